"""The thirteenth red team's findings, each pinned: the live daemon, and sensors that
lie in ways the twelfth did not try, edited into the simulated trial's captures and
replayed against the truth.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon, nothing
worse than raw reaches the autopilot."""

from __future__ import annotations

import os
import socket
from pathlib import Path

from tests.emlogd.daemon.harness import PD0_CONFIG, make_work
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon


def test_a_watchdog_interval_of_a_digit_int_cannot_read_is_no_watchdog(tmp_path: Path) -> None:
    """``WATCHDOG_USEC=²`` (a unit's ``Environment=`` line, a superscript typed for a
    square): the daemon starts, says ``READY=1``, decodes its EMlog and exits 0, with no
    watchdog. ``str.isdigit`` takes ``²`` for a digit and ``int`` refused it: the start
    ended with ``internal error: ValueError`` (exit 1, a restart loop under systemd)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify:
        notify.bind(str(work / "notify.sock"))
        notify.settimeout(5.0)
        env = {**os.environ, "NOTIFY_SOCKET": str(work / "notify.sock"), "WATCHDOG_USEC": "²"}
        with _pd0_daemon(work, env) as (d, emlog):
            assert notify.recv(4096) == b"READY=1"
            for k in range(5):
                os.write(emlog, VHW[k % 2])
            d.pump(1.0)
            assert any(line.startswith(b"$VWVHW") for line in d.lines)
            assert d.stop() == 0
            notify.setblocking(False)
            said = []
            while True:
                try:
                    said.append(notify.recv(4096))
                except BlockingIOError:
                    break
            assert b"WATCHDOG=1" not in said, said
