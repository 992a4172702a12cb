"""The fourteenth red team's findings against the live daemon, each pinned: what its
ports, sockets, outputs, state file and config may do to it from outside.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon."""

from __future__ import annotations

import os
import time
from pathlib import Path

from tests.emlogd.daemon.harness import PD0_CONFIG, make_work
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon


def _port(status: dict[str, object], name: str) -> dict[str, object]:
    """One port's entry of a ``status`` answer."""
    inner = status["status"]
    assert isinstance(inner, dict)
    port = inner["ports"][name]
    assert isinstance(port, dict)
    return port


def test_an_open_port_that_never_sent_a_byte_is_never_heard(tmp_path: Path) -> None:
    """The DVL's pty is open and silent, the EMlog sends: the DVL's ``state`` is ``never
    heard`` (its ``last_rx`` None), the EMlog's ``open``. It showed ``open``, as healthy
    as a port whose data flow, for as long as the daemon ran."""
    work = make_work(tmp_path, PD0_CONFIG)
    with _pd0_daemon(work) as (d, emlog):
        for k in range(5):
            os.write(emlog, VHW[k % 2])
            time.sleep(0.05)
        d.pump(0.5)
        status = d.ask(cmd="status")
        dvl, log = _port(status, "dvl"), _port(status, "emlog1")
        assert dvl["state"] == "never heard" and dvl["last_rx"] is None, dvl
        assert dvl["stale"] is False and dvl["open"] is True, dvl
        assert log["state"] == "open", log
        assert d.stop() == 0
