"""The tenth red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): the status tells the truth, in the log as in
``emlogd status``; nothing from outside stops the daemon."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import time
from pathlib import Path

import structlog

from emlogd.daemon.logsetup import STATUS_LOG_MAX_ITEMS
from emlogd.daemon.loop import Daemon
from emlogd.daemon.statefile import MAX_STATE_BYTES, max_state_bytes
from tests.emlogd.daemon.harness import make_work, reaped, run_daemon

MANY_UUTS = 60
"""UUTs enough for the periodic status line to pass the log's backlog (about 2 KB each)."""


def _many_uuts_config(n: int) -> str:
    """``n`` EMlogs (their links missing: never connected) against one DVL."""
    ports = [
        f"  - {{name: e{i}, url: links/e{i}, protocol: nmea0183, role: uut}}" for i in range(n)
    ]
    ports.append("  - {name: dvl, url: links/dvl, protocol: pd6, role: reference}")
    cals = [f"  - {{uut: e{i}, reference: dvl, lag: 0.2}}" for i in range(n)]
    return (
        "ports:\n" + "\n".join(ports) + "\ncalibration:\n" + "\n".join(cals) + "\n"
        "outputs: {pty: out/emlog0, speed: fused}\nstate_file: state/state.yaml\n"
        "control_socket: run/control.sock\nlog_format: json\nstatus_log_interval_s: 1\n"
    )


def _status_lines(
    fd: int, proc: subprocess.Popen[bytes], seconds: float
) -> list[dict[str, object]]:
    """The ``status`` events read from ``fd`` (the daemon's stdout) within ``seconds``."""
    buf = b""
    end = time.monotonic() + seconds
    found: list[dict[str, object]] = []
    while time.monotonic() < end and proc.poll() is None and not found:
        if select.select([fd], [], [], 0.1)[0]:
            buf += os.read(fd, 1 << 20)
            *lines, buf = buf.split(b"\n")
            for line in lines:
                event = json.loads(line)
                if event.get("event") == "status":
                    found.append(event)
    return found


def test_the_status_line_of_many_uuts_names_a_few_and_counts_the_rest(tmp_path: Path) -> None:
    """60 UUTs, the daemon's stdout a pipe read all along: the periodic status line names
    the first :data:`STATUS_LOG_MAX_ITEMS` UUTs, ports and sources and counts the rest
    (``left_out``), under journald's 48 KiB line limit. The line held every UUT (about
    2 KB each: 2.2 MB with 1000 UUTs), past the log's 64 KiB backlog into a pipe, and
    was dropped whole every time: no status line in the log at all."""
    work = make_work(tmp_path, _many_uuts_config(MANY_UUTS))
    r, w = os.pipe()
    try:
        with reaped(run_daemon(work, w)) as proc:
            os.close(w)
            w = -1
            found = _status_lines(r, proc, 20.0)
            assert found, "no status line in the log"
            status = found[0]
            assert len(json.dumps(status)) < 48 * 1024
            left = MANY_UUTS - STATUS_LOG_MAX_ITEMS
            assert status["left_out"] == {"ports": left + 1, "uuts": left, "sources": left + 1}
            uuts = status["uuts"]
            assert isinstance(uuts, dict)
            assert list(uuts) == [f"e{i}" for i in range(STATUS_LOG_MAX_ITEMS)]
            proc.send_signal(signal.SIGTERM)
            os.set_blocking(r, False)
            end = time.monotonic() + 10.0
            while proc.poll() is None and time.monotonic() < end:  # drain: let it exit
                if select.select([r], [], [], 0.1)[0]:
                    os.read(r, 1 << 20)
            assert proc.wait(1.0) == 0
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)


def test_the_daemon_reads_a_state_file_as_long_as_its_uuts_make_it(tmp_path: Path) -> None:
    """The daemon's state file is read up to what its config's UUTs take
    (:func:`max_state_bytes`): 60 UUTs, 60 × 16 KiB. One bound for any config refused
    the file it had written for its many UUTs at its next start."""
    work = make_work(tmp_path, _many_uuts_config(MANY_UUTS))
    daemon = Daemon(work / "emlogd.yaml", structlog.get_logger("t"))
    assert daemon._state_store().max_bytes == max_state_bytes(MANY_UUTS) > MAX_STATE_BYTES


def test_a_reload_to_more_uuts_reads_the_state_file_as_far(tmp_path: Path) -> None:
    """A reload from 1 UUT to 60 widens the state file's bound with them (and back):
    the save of 60 UUTs' calibrations must be read whole at the next start."""
    work = make_work(tmp_path, _many_uuts_config(1))
    daemon = Daemon(work / "emlogd.yaml", structlog.get_logger("t"))
    daemon._start()
    try:
        store = daemon._state_store()
        assert store.max_bytes == MAX_STATE_BYTES
        (work / "emlogd.yaml").write_text(_many_uuts_config(MANY_UUTS))
        daemon._reload()
        assert store.max_bytes == max_state_bytes(MANY_UUTS)
        (work / "emlogd.yaml").write_text(_many_uuts_config(2))
        daemon._reload()
        assert store.max_bytes == MAX_STATE_BYTES
    finally:
        daemon._shutdown()
        os.close(daemon._wake_r)
        os.close(daemon._wake_w)
