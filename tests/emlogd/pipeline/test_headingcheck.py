"""A heading the course over ground contradicts for minutes is flagged and not used."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator
from typing import SupportsIndex

import numpy as np
import pytest

from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.pipeline.core import Output, Pipeline
from emlogd.pipeline.headingcheck import BAD_FRACTION, WINDOW_S, HeadingCheck
from emlogd.pipeline.settings import PortSettings, UutSettings
from tests.nmea_encoders import encode_hdt

T0 = 1_750_000_000.0


def _run(offset_deg: float, duration_s: float = 600.0) -> tuple[Pipeline, Output]:
    """A log at 2.8 m/s through the water turning slowly (3°/s for a minute, then
    straight, by turns), a 0.3 m/s current to the north-east, GNSS at 1 Hz, and a
    heading sent ``offset_deg`` off the true one."""
    p = Pipeline(
        [PortSettings("log", "nmea0183"), PortSettings("gps", "nmea0183")],
        [UutSettings(port="log", reference_port="gps", reference_field="gnss", heading="gps")],
    )
    rng = np.random.default_rng(11)
    out = Output()
    psi = 0.0
    cn, ce = 0.3 * math.cos(math.pi / 4), 0.3 * math.sin(math.pi / 4)
    for k in range(int(duration_s)):
        t = float(k)
        psi = (psi + (3.0 if (k // 60) % 2 == 0 else 0.0)) % 360.0
        stw = 2.8 + rng.normal(0.0, 0.05)
        vn = stw * math.cos(math.radians(psi)) + cn + rng.normal(0.0, 0.1)
        ve = stw * math.sin(math.radians(psi)) + ce + rng.normal(0.0, 0.1)
        sog = math.hypot(vn, ve)
        cog = math.degrees(math.atan2(ve, vn)) % 360.0
        out.add(p.feed(T0 + t, "log", (encode_vhw(stw) + "\r\n").encode()))
        gps = encode_rmc(None, sog, cog) + "\r\n" + encode_hdt((psi + offset_deg) % 360.0)
        out.add(p.feed(T0 + t + 0.2, "gps", (gps + "\r\n").encode()))
    return p, out


def test_a_heading_180_degrees_wrong_is_flagged_and_not_used() -> None:
    """Within the judging window the heading is flagged in the status and an event; the
    UUT's heading is then not used (none for the water frame)."""
    p, out = _run(180.0)
    st = p.status()["uuts"]["log"]  # type: ignore[index]
    assert "course over ground" in st["heading_suspect"]
    flagged = [e for e in out.events if e.kind == "heading_suspect"]
    assert flagged and flagged[0].t - T0 <= WINDOW_S + 5.0
    assert p._heading_at("log", T0 + 590.0) is None


@pytest.mark.parametrize("offset_deg", [0.0, 5.0])
def test_a_right_heading_is_used(offset_deg: float) -> None:
    """A true heading, or one 5° off (leeway, a compass's error): never flagged."""
    p, out = _run(offset_deg)
    assert p.status()["uuts"]["log"]["heading_suspect"] == ""  # type: ignore[index]
    assert not [e for e in out.events if e.kind == "heading_suspect"]
    assert p._heading_at("log", T0 + 590.0) is not None


def test_the_check_needs_a_speed_and_recovers() -> None:
    """Below 0.5 m/s through the water nothing is judged; a flagged heading that agrees
    again over a window is used again."""
    hc = HeadingCheck(3.0)
    for k in range(200):
        hc.add(float(k), 0.0, 0.3, 0.3, 180.0)
    assert hc.reason() == ""
    for k in range(200, 400):
        hc.add(float(k), 0.0, 2.8, 2.8, 180.0)
    assert "5.6 m/s" in hc.reason()
    for k in range(400, 600):
        hc.add(float(k), 180.0, 2.8, 2.8, 180.0)
    assert hc.reason() == ""


MAX_WINDOW_READS_PER_FIX = 4
"""Window entries a fix may read (its own, the oldest's time, one dropped): a bound
that does not grow with the window (36 000 fixes in the flood below)."""


class _CountingWindow(deque[tuple[float, bool]]):
    """The check's window, counting the entries read from it (indexed, iterated or
    dropped); past ``limit`` reads it fails at once (a pass over the window per fix
    would otherwise run for minutes before the count could be compared)."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.reads = 0
        self.limit = limit

    def _read(self) -> None:
        self.reads += 1
        if self.reads > self.limit:
            raise AssertionError(f"the window was read more than {self.limit} times")

    # typeshed's deque takes SupportsIndex where Sequence's overloads take int or a slice
    def __getitem__(self, i: SupportsIndex, /) -> tuple[float, bool]:  # type: ignore[override]
        self._read()
        return super().__getitem__(i)

    def __iter__(self) -> Iterator[tuple[float, bool]]:
        for item in super().__iter__():
            self._read()
            yield item

    def popleft(self) -> tuple[float, bool]:
        self._read()
        return super().popleft()


def test_a_gnss_flooding_fixes_costs_each_fix_little() -> None:
    """60 000 fixes over 200 s (300 a second, a GNSS port flooding valid RMC): the
    heading right for 60 s, then 180° wrong. The verdict follows (consistent, then
    suspect once 80 % of the window's samples are wrong, at 156 s), and each fix reads
    at most MAX_WINDOW_READS_PER_FIX entries of the window, however long it is. The
    share of bad samples was counted over the whole window at every fix once the window
    held 60 s: each fix cost the window (about 10⁹ steps here, a minute; 15.7 s of CPU
    per second of a GNSS at 2900 fixes a second)."""
    hc = HeadingCheck(1.5)
    n, duration = 60_000, 200.0
    window = _CountingWindow(limit=MAX_WINDOW_READS_PER_FIX * n)
    hc._samples = window
    verdicts = []
    for k in range(n):
        t = duration * k / n
        hc.add(t, 0.0 if t < 60.0 else 180.0, 2.8, 3.0, 0.0)
        verdicts.append(hc.suspect)
    assert len(window) > 30_000  # the window is long: a pass over it per fix shows
    assert window.reads <= MAX_WINDOW_READS_PER_FIX * n  # 2.8 a fix
    first = verdicts.index(True)
    assert duration * first / n == pytest.approx(60.0 + BAD_FRACTION * WINDOW_S, abs=0.1)
    assert all(verdicts[first:])
