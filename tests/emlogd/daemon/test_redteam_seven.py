"""The seventh red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import os
import time
from pathlib import Path

from tests.emlogd.daemon.harness import PD0_CONFIG, make_work
from tests.emlogd.daemon.test_redteam_live import VHW, _flood, _pd0_daemon, _vhw_within

ECHO = b"$AAXXX,echo*00\r\n" * 256
"""What the reader of the output pty writes back (an autopilot echoing, a program
holding the pty open for writing): 4 KiB a write."""


def test_a_reader_writing_into_the_output_pty_costs_itself(tmp_path: Path) -> None:
    """A process holding the output pty open writes into it as fast as it takes it,
    while the EMlog sends a VHW every 0.1 s: nine in ten corrected VHW leave within
    50 ms of their reading and a status request is answered within 0.5 s. What a reader
    writes is drained and discarded, a bounded amount at each write: the drain read
    until the pty was empty, which a writer as fast as the daemon's reads never let
    it be (a write held 75 ms in the median, 250 ms at worst)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with _pd0_daemon(work) as (d, emlog):
        echo = os.open(work / "out" / "emlog0", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            until = time.monotonic() + 4.0
            flood = _flood(echo, ECHO, 4.0)
            late: list[bool] = []
            slowest = 0.0
            while time.monotonic() < until:
                sent = time.monotonic()
                os.write(emlog, VHW[len(late) % 2])
                late.append(not _vhw_within(d.fd, 0.05))
                if len(late) % 10 == 0:
                    t0 = time.monotonic()
                    d.status()
                    slowest = max(slowest, time.monotonic() - t0)
                time.sleep(max(sent + 0.1 - time.monotonic(), 0.0))
            flood.wait(10.0)
        finally:
            os.close(echo)
        assert sum(late) <= len(late) // 10, f"{sum(late)} of {len(late)} late"
        assert slowest < 0.5, slowest
        assert d.stop() == 0
