"""A VBW's athwart speed is judged like its speed along the hull: a transverse speed
jumping by tens of knots between two readings is neither emitted nor learnt."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest

from drivers.framing import split_nmea
from drivers.nmea0183 import encode_vbw
from drivers.rdi_ascii import encode_pd6
from emlogd.config import parse_config
from emlogd.pipeline.core import Pipeline
from emlogd.settings import fusion_from_config, pipeline_from_config

CONFIG = """\
ports:
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog2, reference: dvl, lag: 0.2, current: true, uut_source: VBW, axes: 2}
"""

T0 = datetime(2026, 1, 1, tzinfo=UTC).timestamp()

N = 600
"""Readings at 2 Hz (5 min)."""


def _run(trans: list[float]) -> tuple[list[float], dict[str, object]]:
    """The athwart speeds of the VBW the pipeline sends for readings whose athwart
    speeds are ``trans``, and its counters."""
    cfg = parse_config(CONFIG)
    p = Pipeline(*pipeline_from_config(cfg), fusion=fusion_from_config(cfg))
    out: list[float] = []
    for k, tr in enumerate(trans):
        t = T0 + k * 0.5
        v = 2.5 + 0.5 * math.sin(k / 50.0)
        emits = p.feed(t, "emlog2", (encode_vbw(v, tr) + "\r\n").encode()).emits
        lines = encode_pd6(
            timestamp=datetime.fromtimestamp(t, UTC),
            heading_deg=float(k % 360),
            bottom_ship_mps=(0.1, v, 0.0),
            range_m=30.0,
        )
        emits += p.feed(t + 0.1, "dvl", "".join(x + "\r\n" for x in lines).encode()).emits
        emits += p.tick(t + 0.2).emits
        for e in emits:
            if e.port == "emlog2" and e.sentence[3:6] == "VBW":
                out.append(float(split_nmea(e.sentence.encode()).decode().split(",")[2]))
    counters = p.status()["uuts"]["emlog2"]["counters"]  # type: ignore[index]
    assert isinstance(counters, dict)
    return out, counters


@pytest.mark.parametrize("spike", [20.0, -40.0])
def test_athwart_spikes_of_tens_of_knots_are_not_emitted(spike: float) -> None:
    """A drift of 0.2 m/s to starboard, one reading in ten with an athwart speed of
    ``spike`` m/s (its speed along the hull plausible): none of the spikes goes out,
    each counted ``implausible_accel``. Only the speed along the hull was judged: all
    60 went out, 39 or 78 kn sideways, to the autopilot and to the two-axis learner."""
    out, counters = _run([spike if k % 10 == 5 else 0.2 for k in range(N)])
    assert len(out) == N - N // 10
    assert max(abs(x) for x in out) < 1.0
    assert counters["implausible_accel"] == N // 10


def test_an_athwart_speed_alternating_by_tens_of_knots_keeps_its_first_level() -> None:
    """± 20 m/s from one reading to the next: the level first accepted (+20) is the one
    kept, the other half refused; which of two alternating levels is true the log alone
    cannot tell (as for the speed along the hull)."""
    out, counters = _run([20.0 * (-1) ** k for k in range(N)])
    assert len(out) == N // 2 and all(x > 0 for x in out)
    assert counters["implausible_accel"] == N // 2


def test_a_steady_athwart_speed_goes_out() -> None:
    """A drift of 0.2 m/s to starboard with ±0.05 m/s of ripple: every VBW goes out."""
    out, counters = _run([0.2 + 0.05 * math.sin(k) for k in range(N)])
    assert len(out) == N
    assert counters["implausible_accel"] == 0
