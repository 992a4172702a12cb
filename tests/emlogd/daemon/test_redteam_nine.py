"""The ninth red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from emlogd.daemon.logsetup import CONTROL_EVENT_BURST
from tests.emlogd.daemon.harness import PD0_CONFIG, Daemon, make_work, raw_pty

FLOOD_S = 2.0
"""How long the control client sends its commands, s."""


def _flood_commands(sock: Path, seconds: float) -> int:
    """Send ``learn`` and ``freeze`` requests over one connection, each after the answer
    to the one before, for ``seconds``; the number answered ``ok``."""
    ok = 0
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5.0)
        s.connect(str(sock))
        f = s.makefile("rwb")
        end = time.monotonic() + seconds
        i = 0
        while time.monotonic() < end:
            cmd = {"cmd": "learn", "on": True} if i % 2 else {"cmd": "freeze"}
            f.write(json.dumps(cmd).encode() + b"\n")
            f.flush()
            ok += bool(json.loads(f.readline())["ok"])
            i += 1
    return ok


def test_a_flood_of_operators_commands_is_a_few_log_lines(tmp_path: Path) -> None:
    """A client of the control socket sending ``freeze`` and ``learn`` as fast as the
    answers come, for 2 s: every request answered, and at most
    ``CONTROL_EVENT_BURST`` lines of each command in the log (the next line after
    the interval counts those left out). Each request was a log line: thousands in
    the run, on the operators' journal."""
    work = make_work(tmp_path, PD0_CONFIG)
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    try:
        d = Daemon(work)
        try:
            answered = _flood_commands(work / "run" / "control.sock", FLOOD_S)
            assert answered > 4 * CONTROL_EVENT_BURST
            assert d.status()["ports"]
            assert 1 <= d.events("control_freeze") <= CONTROL_EVENT_BURST
            assert 1 <= d.events("control_learn") <= CONTROL_EVENT_BURST
            code = d.stop()
        finally:
            d.kill()
    finally:
        for fd in masters:
            os.close(fd)
    assert code == 0
