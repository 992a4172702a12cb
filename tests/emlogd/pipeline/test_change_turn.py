"""The change detector in a turn and across a silence: a healthy log is neither held nor
withdrawn."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import UutCalibration
from tests.profiles import by_profile

TRUE = Params("EM3", m=-0.11, b_mps=-0.05)
CURRENT = (0.2, 0.15)
"""The tidal trial's current (north, east), m/s."""

T_TURN = 60.0
"""A straight leg at heading 0 until then, s, then a steady turn."""


def _turn(seed: int, rate_dps: float, seconds: float = 240.0) -> tuple[list[float], int]:
    """A healthy 10-Hz log (0.05 m/s of noise) calibrated exactly, against a DVL
    (0.01 m/s) in the tidal trial's current; the vessel turns at ``rate_dps`` from
    :data:`T_TURN` and, 90 s into the turn, slows from 1.93 to 1.66 m/s (the hull's
    5-s response). Returns the fallbacks' times and the readings emitted raw while the
    calibration was held."""
    rng = np.random.default_rng(seed)
    falls: list[float] = []
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True, learn=False)
    heading = [0.0]
    cal = UutCalibration(
        s,
        Calibration("log", Estimate(TRUE, {"m": 0.01, "b": 0.01}), 0.0),
        lambda t: heading[0],
        lambda t, k, d: falls.append(t) if k == "fallback" else None,
    )
    u, held = 1.93, 0
    for i in range(1, round((T_TURN + seconds) * 10.0)):
        t = i / 10.0
        u += 0.1 / 5.1 * ((1.66 if t >= T_TURN + 90.0 else 1.93) - u)
        heading[0] = max(t - T_TURN, 0.0) * rate_dps % 360.0
        psi = math.radians(heading[0])
        along = CURRENT[0] * math.cos(psi) + CURRENT[1] * math.sin(psi)
        cal.add_reference(t, u + along + float(rng.normal(0.0, 0.01)), True)
        cal.add_reading(t, TRUE.forward(u) + float(rng.normal(0.0, 0.05)))
        cal.drain(t)
        held += cal.sup.held
    assert cal.applied == TRUE or falls  # applied on the straight leg
    return falls, held


@pytest.mark.fuzz
@pytest.mark.parametrize("rate_dps", [3.0, 6.0])
def test_a_speed_step_in_a_turn_in_a_current_holds_and_withdraws_nothing(
    rate_dps: float,
) -> None:
    """In a turn the current's share along the hull changes by up to 0.013 m/s a second
    (3°/s in 0.25 m/s), and the detector's alarms there are the sea's: each empties its
    window. A baseline of a second of a 10-Hz log is no baseline (its current is the
    offset of that moment, its spread too small): the detector alarmed again within
    seconds, and an alarm of such a cascade held or withdrew the healthy calibration
    (without the span: seeds 0, 1 and 9 of 12 at 3°/s, 0, 1, 3 and 6 at 6°/s). The
    window must span ``CUSUM_MIN_SPAN_S`` first. The quick profile runs the first 4
    seeds (2 and 3 of those alarms), the long one (``-m fuzz``) all 12."""
    for seed in range(by_profile(4, 12)):
        falls, held = _turn(seed, rate_dps)
        assert (seed, falls, held) == (seed, [], 0)


def test_a_current_that_moved_across_a_silence_withdraws_nothing() -> None:
    """Five minutes without samples (captures apart, a reference lost) in which the
    current along the hull fell from 0.2 m/s to zero, on a straight leg: the first
    samples after the silence are an innovation of 0.2 m/s against the baseline before
    it, toward raw's error (the log reads low), and at one heading a current cannot be
    told from an offset. The detector starts afresh after ``CUSUM_MAX_GAP_S`` of
    silence: the healthy calibration is neither held nor withdrawn."""
    rng = np.random.default_rng(1)
    falls: list[float] = []
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True, learn=False)
    cal = UutCalibration(
        s,
        Calibration("log", Estimate(TRUE, {"m": 0.01, "b": 0.01}), 0.0),
        lambda t: 0.0,
        lambda t, k, d: falls.append(t) if k == "fallback" else None,
    )
    held = 0
    for i in range(1, 3000):
        t = i / 10.0 if i <= 1200 else i / 10.0 + 300.0
        along = 0.2 if i <= 1200 else 0.0
        cal.add_reference(t, 1.93 + along + float(rng.normal(0.0, 0.01)), True)
        cal.add_reading(t, TRUE.forward(1.93) + float(rng.normal(0.0, 0.05)))
        cal.drain(t)
        held += cal.sup.held and t > 120.0
    assert cal.applied == TRUE
    assert (falls, held) == ([], 0)
