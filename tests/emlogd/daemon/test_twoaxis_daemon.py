"""End to end, ``axes: 2``: the real daemon (subprocess) on ptys restores a two-axis log's
figures from its state file, validates them against the DVL, and then sends VBW with
the athwart speed in the hull frame, read by pynmea2.

The capture is served 20 times faster than real time, so the configured lag and
validation window are the simulator's divided by that speed; the figures are the
state file's (learning them takes half an hour of figure-8, which the replay tests
cover: ``tests/emlogd/offline/test_replay_twoaxis.py``)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pynmea2
import pytest

from calib.estimate import Estimate
from calib.models import Params
from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.records import KNOT_MPS, Rejected
from emlogd.daemon.statefile import StateStore
from emlogd.launch import fake_sensors
from emlogd.offline.simulate import SimulationResult
from emlogd.pipeline.calibration import Calibration
from tests.emlogd.daemon.harness import OUTPUTS, SPEED, Daemon, wait
from tests.synth import TWO_AXIS_FIGURES as FIGURES

CONFIG = f"""\
ports:
  - {{name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut, baud: 38400}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}}
calibration:
  - {{uut: emlog2, reference: dvl, lag: {0.46 / SPEED:.4f}, current: true, learn: false,
     uut_source: VBW, axes: 2, validation_s: 4, talker: VM, max_rate_hz: 10000,
     max_reading_accel_mps2: {SPEED**2:g}}}
{OUTPUTS}"""


@pytest.fixture(scope="module")
def figure8(misaligned_trial: SimulationResult) -> Path:
    """A fifth of the figure-8 with emlog2 turned 3° to starboard (noise 0.01 m/s: the
    session's ``misaligned_trial``)."""
    return misaligned_trial.files[1]


@pytest.fixture
def served(work: Path, figure8: Path) -> Iterator[Path]:
    """The state file with the figures (no one-axis calibration), the figure-8 served."""
    none = Calibration("emlog2", Estimate(Params("EM3"), {}), None, reset=True, two_axis=FIGURES)
    StateStore(work / "state" / "state.yaml").save({"emlog2": none})
    with fake_sensors(figure8, work / "links", ("emlog2", "dvl"), speed=SPEED):
        yield figure8


def _raw_vbw(capture: Path) -> list[tuple[float, float]]:
    """The log's VBW water pairs in the capture, in order, m/s."""
    dec = make_decoder("nmea0183", "emlog2", errors="skip")
    out = []
    for _, port, data, _ in CaptureReader(capture, errors="skip").received():
        if port != "emlog2":
            continue
        for rec in dec.feed(data):
            if isinstance(rec, Rejected):
                continue
            for sp in dec.speed_records(rec):
                if sp.source == "VBW" and sp.transverse_mps is not None:
                    assert sp.longitudinal_mps is not None
                    out.append((sp.longitudinal_mps, sp.transverse_mps))
    return out


def _sensor_pair(u: float, w: float) -> tuple[float, float]:
    """The raw pair a hull-frame VBW was corrected from, by the figures (the forward
    reading passed through, no one-axis calibration): ``w_s = w·cos α − u·sin α``,
    forward ``(u + w_s·sin α)/cos²α``, athwart ``(1 + m_t)·w_s + b_t``."""
    a = math.radians(FIGURES["misalign_deg"])
    ws = w * math.cos(a) - u * math.sin(a)
    fwd = (u + ws * math.sin(a)) / math.cos(a) ** 2
    return fwd, (1.0 + FIGURES["m_t"]) * ws + FIGURES["b_t_mps"]


def _near(p: tuple[float, float], q: tuple[float, float]) -> bool:
    """Two VBW pairs equal within the rounding of the knot's second decimal of both
    sentences (0.0026 m/s each)."""
    return abs(p[0] - q[0]) <= 0.006 and abs(p[1] - q[1]) <= 0.006


def _run(pairs: list[tuple[float, float]], raw: list[tuple[float, float]], i: int, gap: int) -> int:
    """How many of ``pairs`` are, in order from ``raw[i]``, raw readings (each among the
    ``gap`` after the last matched: readings dropped as backlog between)."""
    hits = 0
    for p in pairs:
        for j in range(i, min(i + gap, len(raw))):
            if _near(raw[j], p):
                hits, i = hits + 1, j + 1
                break
    return hits


def _matched(pairs: list[tuple[float, float]], raw: list[tuple[float, float]]) -> int:
    """How many of ``pairs`` are, in order, raw readings: from the first raw reading where
    their first five follow each other."""
    for i in range(len(raw)):
        if pairs and _near(raw[i], pairs[0]) and _run(pairs[:5], raw, i, 40) == 5:
            return _run(pairs, raw, i, 400)
    return 0


LEEWAY_TOL_DEG = 0.25
"""How far a leeway angle may lie from the one of the VBW it was taken from, degrees:
its 0.1° field plus the VBW's two-decimal knots (0.0026 m/s each) at 1 m/s or more."""


def _leeway(pair: tuple[float, float]) -> float:
    """The leeway angle of a hull-frame pair, degrees (+ starboard)."""
    return math.degrees(math.atan2(pair[1], pair[0]))


def _ground_pair_valid(msg: pynmea2.NMEASentence) -> bool:
    """A VBW's ground pair: both numbers with ``A``, or both empty with ``V``."""
    if msg.data_validity_grnd_spd == "V":
        return msg.lon_grnd_spd is None and msg.trans_grnd_spd is None
    return msg.data_validity_grnd_spd == "A" and None not in (msg.lon_grnd_spd, msg.trans_grnd_spd)


def _status_after(text: list[str], first: int) -> int:
    """How many ``$PEMLT`` sentences from ``text[first]`` on carry the figures (α, its
    σ, m_t, b_t) and the leeway angle of the last corrected VBW sent before them."""
    last: tuple[float, float] | None = None
    checked = 0
    for s in text[first:]:
        if "VBW" in s[:6]:
            msg = pynmea2.parse(s, check=True)
            last = (float(msg.lon_water_spd) * KNOT_MPS, float(msg.trans_water_spd) * KNOT_MPS)
        elif s.startswith("$PEMLT,emlog2,"):
            f = pynmea2.parse(s, check=True).data
            assert f[2:7] == ["A", "+3.00", "1.0e-01", "-0.0800", "+0.040"] and f[8] in ("", "R")
            if last is not None and last[0] >= 1.0:
                assert abs(float(f[7]) - _leeway(last)) <= LEEWAY_TOL_DEG, (s, last)
                checked += 1
    return checked


def test_vbw_carries_the_corrected_athwart_speed_once_validated(work: Path, served: Path) -> None:
    """The restored figures validate and are applied ($PEMLT ``A``, the status
    ``applied``); from then on every VBW (checksum and fields valid for pynmea2, its
    ground pair with its validity) is the raw reading turned into the hull frame by
    them, its athwart speed without the misalignment's phantom leeway; before, the VBW
    passed through as read. The status sentence and the JSON carry α ± σ and the
    leeway angle of the corrected VBW, and the JSON why the forward speed is the
    one-axis calibration's."""
    d = Daemon(work, pty=True)
    try:

        def applied() -> bool:
            d.pump(0.2)
            return any(line.startswith(b"$PEMLT,emlog2,A,") for line in d.lines)

        wait(applied, "the restored two-axis figures applied", timeout_s=20.0)
        d.pump(2.0)
        two = d.uut("emlog2")["two_axis"]
        d.pump(0.5)
        assert isinstance(two, dict) and two["state"] == "applied"
        assert two["applied"] == pytest.approx(FIGURES)
        assert two["forward"] == "one_axis" and two["forward_reason"] == (
            "the one-axis calibration's: the two-axis fit did not determine the forward "
            "scale and offset"
        )  # the state file's figures carry no longitudinal parameters
    finally:
        d.stop()
    text = [line.decode("ascii") for line in d.lines]
    first = next(i for i, s in enumerate(text) if s.startswith("$PEMLT,emlog2,A,"))
    before: list[tuple[float, float]] = []
    after: list[tuple[float, float]] = []
    for i, s in enumerate(text):
        if "VBW" not in s[:6]:
            continue
        msg = pynmea2.parse(s, check=True)
        assert msg.data_validity_water_spd == "A" and _ground_pair_valid(msg)
        pair = (float(msg.lon_water_spd) * KNOT_MPS, float(msg.trans_water_spd) * KNOT_MPS)
        (after if i > first else before).append(pair)
    assert _status_after(text, first) >= 3
    lee = two["leeway_deg"]  # the JSON's: a corrected VBW's, sent about when it was read
    assert isinstance(lee, float)
    assert min(abs(lee - _leeway(p)) for p in after if p[0] >= 1.0) <= LEEWAY_TOL_DEG
    raw = _raw_vbw(served)
    assert len(after) >= 50 and _matched(before, raw) >= 0.9 * len(before)
    assert _matched([_sensor_pair(*p) for p in after], raw) >= 0.9 * len(after)
    assert _matched(after, raw) < 0.1 * len(after)  # not the raw pairs: corrected
