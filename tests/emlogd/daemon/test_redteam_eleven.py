"""The eleventh red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): no lock-out of the autopilot or the operator; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

from tests.emlogd.daemon.harness import PD0_CONFIG, free_port, make_work
from tests.emlogd.daemon.test_lockout import _first_sentence
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon


def test_a_tcp_reader_that_half_closes_is_served(tmp_path: Path) -> None:
    """A reader of the TCP output that ends its sending at once (``shutdown(SHUT_WR)``:
    ``nc -N``, a script whose input is empty) receives the corrected VHW beside a plain
    reader, and the output counts it a client. The daemon took its end of file for a
    close: the reader got nothing, ``client_disconnected`` at once."""
    port = free_port()
    config = PD0_CONFIG.replace(
        "outputs: {pty: out/emlog0}", f'outputs: {{pty: out/emlog0, tcp: "127.0.0.1:{port}"}}'
    )
    work = make_work(tmp_path, config)
    with _pd0_daemon(work) as (d, emlog):
        half = socket.create_connection(("127.0.0.1", port), timeout=5)
        plain = socket.create_connection(("127.0.0.1", port), timeout=5)
        with half, plain:
            half.shutdown(socket.SHUT_WR)
            time.sleep(0.3)  # the daemon reads the end of file
            for k in range(10):
                os.write(emlog, VHW[k % 2])
                time.sleep(0.1)
            assert _first_sentence(half, 3.0) < 3.0
            assert _first_sentence(plain, 3.0) < 3.0
            outputs = d.ask(cmd="status")["outputs"]
            assert isinstance(outputs, dict)
            assert outputs[f"tcp:127.0.0.1:{port}"]["clients"] == 2
        assert d.stop() == 0
