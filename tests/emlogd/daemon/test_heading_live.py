"""Two compasses 180° apart fed to the live daemon: its status and log say so.

The real ``emlogd run`` reads an EMlog, another log as its reference and two compasses
(HDT) on ptys; the second compass reads 180° off the first and nothing else tells which
is right (no GNSS): within the comparison's window (:mod:`emlogd.pipeline.headingsources`,
a verdict after half of its 120 s) the UUT's heading is suspect — the status's
``heading_suspect`` and ``reason`` name the two sources and their difference, ``emlogd
status`` prints it — and the log holds one ``heading_sources_disagree`` event. A ``soak``
test: about 70 s of wall clock.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from emlogd.pipeline.headingcheck import WINDOW_S
from tests.emlogd.daemon.harness import OUTPUTS, Daemon, make_work, raw_pty
from tests.nmea_encoders import encode_hdt

CONFIG = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}}
  - {{name: ref, url: links/ref, protocol: nmea0183, role: reference}}
  - {{name: compass1, url: links/compass1, protocol: nmea0183, role: aux}}
  - {{name: compass2, url: links/compass2, protocol: nmea0183, role: aux}}
calibration:
  - {{uut: emlog1, reference: ref, reference_field: speed, lag: 0}}
{OUTPUTS}"""
"""An EMlog against another log, two compasses beside."""

RATE_HZ = 5.0
"""How often each sensor sends."""

VHW = b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n"


@pytest.mark.soak
def test_two_compasses_180_apart_make_the_live_heading_suspect(tmp_path: Path) -> None:
    work = make_work(tmp_path, CONFIG)
    fds = {
        name: raw_pty(work / "links" / name) for name in ("emlog1", "ref", "compass1", "compass2")
    }
    d = Daemon(work)
    try:
        t0 = time.monotonic()
        why, poll = "", 0.0
        while time.monotonic() - t0 < WINDOW_S:
            k = time.monotonic() - t0
            h = (30.0 + 0.5 * k) % 360.0  # a slow turn
            os.write(fds["emlog1"], VHW)
            os.write(fds["ref"], VHW)
            os.write(fds["compass1"], f"{encode_hdt(h)}\r\n".encode())
            os.write(fds["compass2"], f"{encode_hdt((h + 180.0) % 360.0)}\r\n".encode())
            time.sleep(1.0 / RATE_HZ)
            if k >= poll:  # every 5 s
                poll += 5.0
                why = str(d.uut("emlog1")["heading_suspect"])
                if why:
                    break
        assert "compass1.HDT and compass2.HDT 180° apart" in why, why
        assert time.monotonic() - t0 < 0.5 * WINDOW_S + 15.0
        u = d.uut("emlog1")
        assert u["reason"] == why
        sources = u["heading"]["sources"]  # type: ignore[index]
        assert sources["unresolved"] == ["compass1.HDT/compass2.HDT"]
        assert d.events("heading_sources_disagree") == 1
        assert d.events("heading_suspect") == 1
        assert d.stop() == 0
    finally:
        d.kill()
        for fd in fds.values():
            os.close(fd)
