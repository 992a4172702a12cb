"""The lag in use checked against the data: a reference whose clock is off is told, and
the UUT learns nothing from it and applies nothing (emlogd.pipeline.lagcheck)."""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.lag import LagEstimate
from calib.models import Params
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.lagcheck import (
    LAG_CHECK_AUTO_MIN_OFFSET_S,
    LAG_CHECK_MIN_GAIN,
    LAG_CHECK_MIN_SAMPLES,
    LAG_CHECK_TOLERANCE_S,
    LagCheck,
    verdict,
)
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import UutCalibration

_KNOTS = np.random.default_rng(7).uniform(1.0, 4.0, 400)
"""A speed that wanders between 1 and 4 m/s, a new value every 10 s (never periodic)."""

TRUE = Params("EM3", m=0.15, b_mps=0.1)


def _speed(t: float) -> float:
    return float(np.interp(t, 10.0 * np.arange(_KNOTS.size), _KNOTS))


OUTAGE_EVERY_S = 200.0
"""With outages, the reference is lost for the last 40 s of every this many seconds."""


def _feed(
    check: LagCheck,
    seconds: float,
    shift_s: float,
    lag_s: float,
    steady: bool,
    outages: bool = False,
) -> None:
    """The reference at 2 Hz stamped ``shift_s`` late (with ``outages``, 40 s lost every
    200 s), the readings at 1 Hz."""
    for k in range(int(seconds * 2)):
        t = 200.0 + 0.5 * k
        v = 2.0 if steady else _speed(t - shift_s)
        if not (outages and t % OUTAGE_EVERY_S >= OUTAGE_EVERY_S - 40.0):
            check.reference(t, v + 0.01 * np.sin(7.0 * t), lambda t: None)
        if k % 2 == 0:
            check.reading(t, 2.0 if steady else _speed(t), lag_s)


@pytest.mark.parametrize("shift_s", [120.0, -120.0])
def test_a_reference_two_minutes_off_contradicts_the_lag(shift_s: float) -> None:
    """Stamped 120 s late (a lag of −120 s) or early (+120 s, beyond the lag search's
    0..30 s): the check finds it and says so."""
    check = LagCheck(with_heading=False)
    _feed(check, 1000.0, shift_s, 0.5, steady=False)
    assert check.contradicted
    found = re.search(r"best lag ([+-][0-9.]+) s", check.why)
    assert found is not None and float(found.group(1)) == pytest.approx(-shift_s, abs=2.0)
    assert "configured 0.5 s" in check.why


@pytest.mark.parametrize("shift_s", [120.0, -120.0])
def test_a_reference_with_outages_two_minutes_off_contradicts(shift_s: float) -> None:
    """The reference lost for 40 s every 200 s: no reading overlaps it at every lag of
    ±180 s, and each lag scored on its own overlap still finds the offset."""
    check = LagCheck(with_heading=False)
    _feed(check, 1000.0, shift_s, 0.5, steady=False, outages=True)
    found = re.search(r"best lag ([+-][0-9.]+) s", check.why)
    assert found is not None and float(found.group(1)) == pytest.approx(-shift_s, abs=2.0)


@pytest.mark.parametrize(("lag_s", "outages"), [(0.0, False), (3.0, False), (0.0, True)])
def test_a_reference_in_time_agrees(lag_s: float, outages: bool) -> None:
    """In time, with the lag in use right or a few seconds off, with outages or without:
    never contradicted."""
    check = LagCheck(with_heading=False)
    _feed(check, 1500.0, 0.0, lag_s, steady=False, outages=outages)
    assert check.checks >= 3
    assert not check.contradicted


def test_a_steady_speed_cannot_contradict() -> None:
    """At a steady speed no correlation means anything: 120 s off goes unjudged."""
    check = LagCheck(with_heading=False)
    _feed(check, 1000.0, 120.0, 0.5, steady=True)
    assert check.checks >= 1
    assert not check.contradicted


def _est(lag: float, peak: float, at: float, n: int = 300) -> LagEstimate:
    return LagEstimate(lag, peak, 0.5, n, False, 1.0, at)


def test_the_rule() -> None:
    """Agrees within the tolerance; contradicts only a clearly better lag on enough
    samples with a correlation that means something; else cannot tell."""
    tol, gain = LAG_CHECK_TOLERANCE_S, LAG_CHECK_MIN_GAIN
    assert verdict(_est(3.3 + 0.9 * tol, 0.95, 0.2), 3.3) == ""
    assert verdict(_est(120.0, 0.95, 0.95 - 1.1 * gain), 3.3)
    assert verdict(_est(120.0, 0.95, 0.95 - 0.9 * gain), 3.3) is None  # a flat curve
    assert verdict(_est(120.0, 0.5, 0.0), 3.3) is None  # no correlation worth the name
    assert verdict(_est(120.0, 0.95, 0.2, LAG_CHECK_MIN_SAMPLES - 1), 3.3) is None
    bound = LagEstimate(180.0, 0.95, 0.5, 300, True, float("inf"), 0.2)
    assert verdict(bound, 3.3) is None  # beyond the range: where, unknown


def test_the_lag_found_is_contradicted_by_a_clock_minutes_off_that_repeats() -> None:
    """``lag: auto``: the first check that finds the reference 120 s off cannot tell yet;
    the next that finds it again contradicts the lag in use."""
    check = LagCheck(with_heading=False, auto=True)
    _feed(check, 700.0, 120.0, 0.5, steady=False, outages=True)
    assert check.checks == 1 and check.why == ""
    _feed(check, 1000.0, 120.0, 0.5, steady=False, outages=True)
    assert "best lag -1" in check.why and "in use 0.5 s" in check.why


def test_the_lag_found_is_not_contradicted_by_a_false_peak_or_seconds() -> None:
    """``lag: auto``: a best lag minutes off once, then elsewhere (a false peak), or
    seconds off however often (the lag search's business), never contradicts; the same
    offset twice in a row does, and a check that agrees starts the count again."""

    def run(bests: list[float]) -> list[bool]:
        check = LagCheck(with_heading=False, auto=True)
        out = []
        for best in bests:
            why = verdict(_est(best, 0.95, 0.2), 0.5, "in use")
            out.append(bool(check._confirmed(why, best, 0.5)))
        return out

    seconds = 0.5 + 0.9 * LAG_CHECK_AUTO_MIN_OFFSET_S
    assert not any(run([136.0, -114.0, 136.0, 0.5, -114.0]))
    assert not any(run([seconds] * 5))
    assert run([-119.0, -117.0]) == [False, True]
    assert run([-119.0, 0.5, -119.0]) == [False, False, False]


def test_the_uut_withdraws_to_raw_and_learns_nothing() -> None:
    """A UUT whose restored calibration is applied, then a reference 120 s late: the
    calibration is withdrawn, raw passes, nothing is learnt, and the status says why."""
    events: list[tuple[float, str, Mapping[str, object]]] = []
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.5)
    prior = Calibration("log", Estimate(TRUE, {"m": 0.01, "b": 0.01}), 0.5)
    cal = UutCalibration(s, prior, lambda t: None, lambda t, k, d: events.append((t, k, d)))
    learnt: list[int] = []
    applied_in_time = False
    for k in range(13000):
        t = 200.0 + 0.1 * k
        late = t >= 300.0
        cal.add_reference(t, _speed(t - 120.0 if late else t), True)
        if k % 10 == 0:
            cal.add_reading(t, TRUE.forward(_speed(t)))
            cal.drain(t)
            learnt.append(cal.n_learnt)
            applied_in_time |= not late and cal.applied is not None
    assert applied_in_time  # in time, the restored calibration was applied
    assert any(k == "lag_check" for _, k, _ in events)
    assert any(k == "fallback" for _, k, _ in events)
    assert cal.applied is None
    assert cal.correct(2.0) == 2.0
    assert "the reference's time does not match the log's" in cal.reason
    assert learnt[-1] == learnt[-200]  # the last 200 s taught nothing


def test_the_lag_found_is_checked_too() -> None:
    """``lag: auto``: the UUT checks the lag in use, by the rule for a lag found."""
    s = UutSettings(port="log", reference_port="dvl")
    cal = UutCalibration(s, None, lambda t: None, lambda t, k, d: None)
    assert s.lag_s is None
    assert cal.lagcheck is not None and cal.lagcheck.auto
