"""The supervisor's own evidence: per-calibration currents, the change detector."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from calib.models import Params
from emlogd.pipeline.evidence import (
    CUSUM_H,
    DRIFT_CONFIRM_S,
    DRIFT_WINDOW_S,
    Course,
    Cusum,
    Drift,
    FitWindow,
    SeaMemory,
    steps,
)


def _cs(deg: float) -> tuple[float, float]:
    return math.cos(math.radians(deg)), math.sin(math.radians(deg))


def test_a_current_is_fitted_away_and_an_offset_is_not_in_a_turn() -> None:
    """Over a full turn, a current leaves no residual; a sensor's offset stays whole."""
    w = FitWindow(2, water=True)
    for k in range(360):
        h = _cs(float(k))
        current_err = -(0.3 * h[0] + 0.1 * h[1])  # p(raw) − ref for a perfect sensor
        w.add(float(k), h, (current_err, current_err + 0.2))
    assert w.rmse(0) == pytest.approx(0.0, abs=0.005)
    assert w.rmse(1) == pytest.approx(0.2, abs=0.005)
    assert w.current(0) == pytest.approx((0.3, 0.1), abs=1e-3)


def test_without_current_states_the_window_fits_the_mean() -> None:
    """Paper frame: the prediction is the window's mean error."""
    w = FitWindow(1, water=False)
    for k in range(50):
        w.add(float(k), None, (0.1 + (0.01 if k % 2 else -0.01),))
    assert w.predict(0, None) == pytest.approx(0.1, abs=1e-3)
    assert w.rmse(0) == pytest.approx(0.01, abs=1e-3)


def test_sea_memory_fits_each_calibrations_own_current() -> None:
    """The same samples give raw and a calibration different currents (their offsets
    differ along the hull); on a full turn each is the sea's."""
    mem = SeaMemory()
    p = Params("EM3", m=0.1, b_mps=0.0)
    for k in range(360):
        u = 2.0
        h = _cs(float(k))
        ref = u + 0.2 * h[0]
        mem.add(float(k), p.forward(u), ref, h)
    b_cal = mem.current(p, 360.0)
    b_raw = mem.current(None, 360.0)
    assert b_cal == pytest.approx((-0.2, 0.0), abs=0.01)
    assert b_raw == pytest.approx((-0.2, 0.0), abs=0.05)  # its offset leaks little


def test_the_cusum_ignores_one_glitch_and_alarms_on_a_step() -> None:
    """One 50σ sample is clipped; a run of 10σ samples alarms within three."""
    c = Cusum()
    assert not c.add(50.0, 1.0, 0.0)
    for _ in range(5):
        c.add(0.0, 0.0, 0.0)
    assert c.hi == 0.0
    alarms = [c.add(10.0, 0.5, 0.1) for _ in range(3)]
    assert alarms == [False, False, True]
    assert c.ss_app > c.ss_raw and c.hi > CUSUM_H


def test_an_alarm_is_judged_on_the_run_of_its_own_side() -> None:
    """A step down after a run of noise on the high side: the evidence is the low side's
    run alone, not raw's offset over the noise before the step."""
    c = Cusum()
    for _ in range(10):  # noise builds the high side slowly; raw is off by 0.4 there
        assert not c.add(2.0, 0.0, 0.4)
    assert c.hi > 0.0
    alarms = [c.add(-10.0, 0.5, 0.3) for _ in range(3)]
    assert alarms == [False, False, True] and c.hi == 0.0
    assert c.ss_app == pytest.approx(3 * 0.25) and c.ss_raw == pytest.approx(3 * 0.09)
    # the whole run, noise included (what an alarm without a jump of the log is judged on)
    assert c.run_app == pytest.approx(3 * 0.25) and c.run_raw == pytest.approx(1.6 + 0.27)


def test_steps_tell_which_series_jumped() -> None:
    """The vessel accelerating moves both series alike: that is their slope before the
    run. A sensor step moves the reading alone, a current's the reference alone."""
    before = [(float(t), 2.0 + 0.1 * t, 2.0 + 0.1 * t) for t in range(5)]
    sensor = [(5.0, 2.5 - 0.5, 2.5), (6.0, 2.6 - 0.5, 2.6)]
    log, ref = steps(before + sensor, len(before))
    assert log == pytest.approx(-0.5) and ref == pytest.approx(0.0, abs=1e-9)
    sea = [(5.0, 2.5, 2.8), (6.0, 2.6, 2.9)]
    log, ref = steps(before + sea, len(before))
    assert log == pytest.approx(0.0, abs=1e-9) and ref == pytest.approx(0.3)
    assert steps(before, len(before)) == (0.0, 0.0)


def _noisy_run(offset: Callable[[int], float]) -> Course:
    """A 10-Hz log with 0.03 m/s of noise on a vessel accelerating 0.02 m/s², the
    reference smooth: 5 s before a CUSUM run, then 3 s of run with ``offset(i)`` added
    to the corrected reading's i-th sample of the run."""
    rng = np.random.default_rng(7)
    c = Course(60.0)
    for i in range(-50, 30):
        t = 1.7e9 + 0.1 * i
        ref = 2.0 + 0.02 * 0.1 * i
        c.add(t, ref + rng.normal(0.0, 0.03) + (offset(i) if i >= 0 else 0.0), ref, i < 0)
    return c


def test_a_spike_of_the_log_is_no_jump_and_a_shift_of_its_mean_is() -> None:
    """One sample 0.25 m/s (8σ) off at the start of the run is noise: the mean of the
    reading's error moved by a fraction of that, within its standard error, and the
    log did not jump. A step of the sensor by the same 0.25 shifts the mean at once,
    tens of standard errors, with the reference's mean steady: the log jumped. (One
    sample's change reads both as the same jump.)"""
    spike = _noisy_run(lambda i: 0.25 if i == 0 else 0.0)
    step = _noisy_run(lambda i: 0.25)
    for c in (spike, step):
        log, ref = c.steps()
        assert c.log_jumped(log, ref) and abs(log) == pytest.approx(0.25, abs=0.1)
    s = spike.shift()
    assert not s.log_jumped and abs(s.log_mps - s.reference_mps) < 4.0 * s.se_mps
    s = step.shift()
    assert s.log_jumped and s.log_mps == pytest.approx(0.25, abs=0.03)
    assert abs(s.reference_mps) < 0.01 and s.log_mps > 10.0 * s.se_mps


def test_a_step_of_a_log_read_every_5_s_shifts_its_mean() -> None:
    """A log read every 5 s (0.2 Hz), 0.02 m/s of noise, steps by −0.23 m/s two readings
    before the alarm (a 15 % gain step at 1.8 m/s), the reference steady: each side of
    the split holds two readings (3 s held one, and no step of a slow log was the
    sensor's)."""
    rng = np.random.default_rng(1)
    c = Course(60.0)
    for i in range(-4, 6):
        t = 1.7e9 + 5.0 * i
        c.add(t, 1.8 + rng.normal(0.0, 0.02) - (0.23 if i >= 4 else 0.0), 1.8, i < 0)
    s = c.shift()
    assert s.log_jumped and s.log_mps == pytest.approx(-0.23, abs=0.05)
    assert abs(s.reference_mps) < 1e-9


def test_a_change_of_speed_the_log_follows_is_no_jump() -> None:
    """The vessel speeds up 0.3 m/s over 2 s, the log following the reference 0.5 s
    late: the mean of its error shifts while it lags, but the reference's mean steps
    as much as the reading's, and the log did not jump."""

    def v(t: float) -> float:
        return 2.0 + 0.3 * min(max(t / 2.0, 0.0), 1.0)

    c = Course(60.0)
    for i in range(-50, 40):
        t = 0.1 * i
        c.add(t, v(t - 0.5) + (0.01 if i % 2 else -0.01), v(t), i < 0)
    s = c.shift()
    assert abs(s.log_mps - s.reference_mps) > 4.0 * s.se_mps  # the lag's transient
    assert not s.log_jumped and s.reference_mps == pytest.approx(s.log_mps, abs=0.1)


def _drift(
    raw: Callable[[float], float],
    ref: Callable[[float], float],
    seconds: float = 200.0,
    heading: Callable[[float], float] = lambda t: 30.0,
) -> Drift:
    """A :class:`Drift` fed at 1 Hz with a little alternating noise on the reading."""
    d = Drift()
    for k in range(int(seconds)):
        t = float(k)
        d.add(t, raw(t) + (0.01 if k % 2 else -0.01), ref(t), _cs(heading(t)))
    return d


class TestDrift:
    """A log that drifts against a steady reference, told from the sea and the vessel."""

    def test_the_trend_is_the_last_windows_however_long_the_run(self) -> None:
        """Over many windows (the samples' array wraps round), the error's change is the
        least-squares line of the last window's samples, at epoch times too."""
        d, rows = Drift(), []
        for k in range(1000):
            t = 1.7e9 + 1.1 * k
            raw, ref = 1.9 - 0.0005 * k + (0.01 if k % 3 else -0.02), 1.6 + 0.0001 * k
            d.add(t, raw, ref, _cs(30.0))
            rows.append((t, raw - ref))
        last = np.array([r for r in rows if rows[-1][0] - r[0] <= DRIFT_WINDOW_S])
        t = last[:, 0] - last[0, 0]
        slope = np.polyfit(t, last[:, 1], 1)[0]
        assert d.change_mps == pytest.approx(slope * t[-1], rel=1e-9)
        assert d.on

    def test_a_fouling_log_at_steady_speed_drifts(self) -> None:
        """The reading falls 0.06 m/s over two minutes, the reference holds: on."""
        d = _drift(lambda t: 1.9 - 0.0005 * t, lambda t: 1.6)
        assert d.on and d.change_mps == pytest.approx(-0.06, abs=0.005)

    def test_a_current_that_changes_is_no_drift(self) -> None:
        """The reference (the ground speed) rises 0.04 m/s over two minutes (steady
        enough), the reading holds: the error moved no more than the reference: off."""
        d = _drift(lambda t: 1.9, lambda t: 1.6 + 0.00035 * t)
        assert not d.on and d.change_mps == pytest.approx(-0.042, abs=0.005)

    def test_a_vessel_that_speeds_up_is_no_drift(self) -> None:
        """Both rise, the log by its 17 % scale error more: off."""
        assert not _drift(lambda t: 1.17 * (1.6 + 0.002 * t), lambda t: 1.6 + 0.002 * t).on

    def test_a_fouling_log_withdraws_once_its_verdict_has_held(self) -> None:
        """The fouling log's verdict comes on at the first full window and is sustained
        (the calibration withdrawn) :data:`DRIFT_CONFIRM_S` later, not before."""
        d, on, sustained = Drift(), math.inf, math.inf
        for k in range(300):
            t = float(k)
            d.add(t, 1.9 - 0.0005 * t + (0.01 if k % 2 else -0.01), 1.6, _cs(30.0))
            on = min(on, t) if d.on else on
            sustained = min(sustained, t) if d.sustained else sustained
        assert on < 200.0 and sustained == on + DRIFT_CONFIRM_S

    def test_a_verdict_of_a_few_seconds_withdraws_nothing(self) -> None:
        """Raw judged without a calibration (gain 1.17): a surge of ±0.02 m/s over two
        minutes in a current rising 0.72 m/s an hour brings the verdict on for seconds at
        a time (the ground reference holds, the reading moves by its gain): never
        sustained."""
        d, spells = Drift(), 0
        for k in range(600):
            t = float(k)
            stw = 1.6 + 0.02 * math.sin(2.0 * math.pi * t / 120.0)
            was = d.on
            d.add(t, 1.17 * stw + 0.1 + (0.01 if k % 2 else -0.01), stw + 0.0002 * t, _cs(30.0))
            spells += d.on and not was
            assert not d.sustained
        assert spells >= 3

    def test_the_readings_are_judged_through_the_calibration(self) -> None:
        """The same surge and current, a log of gain 1.27 judged through its calibration:
        the corrected reading moves with the reference, so it never comes on (judged raw,
        it does)."""
        p = Params("EM3", m=0.27, b_mps=0.05)
        through, raw = Drift(), Drift()
        ever = [False, False]
        for k in range(600):
            t = float(k)
            stw = 1.6 + 0.02 * math.sin(2.0 * math.pi * t / 120.0)
            reading = p.forward(stw) + (0.01 if k % 2 else -0.01)
            through.add(t, reading, stw + 0.0002 * t, _cs(30.0), p)
            raw.add(t, reading, stw + 0.0002 * t, _cs(30.0))
            ever = [ever[0] or through.on, ever[1] or raw.on]
        assert ever == [False, True]

    def test_no_drift_is_judged_in_a_turn(self) -> None:
        """The same fouling log while the vessel turns: a current would move the
        reference with the heading, so nothing is judged: off."""
        assert not _drift(lambda t: 1.9 - 0.0005 * t, lambda t: 1.6, heading=lambda t: t).on

    def test_the_verdict_holds_while_the_drift_goes_on_and_across_a_gap(self) -> None:
        """Once on, it stays while the error keeps its trend though the vessel speeds up
        (the error then moves less than the reference); after a gap the verdict stands
        until a full window judges again; a log that stopped drifting is then off."""
        d = _drift(lambda t: 1.9 - 0.0005 * t, lambda t: 1.6)
        assert d.on
        for k in range(200, 260):
            t = float(k)
            up = 0.0008 * (t - 200.0)
            d.add(t, 1.9 - 0.0005 * t + up + (0.01 if k % 2 else -0.01), 1.6 + up, _cs(30.0))
        assert d.on
        fresh = Drift()  # the last window alone, judged afresh: off
        for k in range(260 - int(DRIFT_WINDOW_S), 260):
            t = float(k)
            up = 0.0008 * max(t - 200.0, 0.0)
            fresh.add(t, 1.9 - 0.0005 * t + up + (0.01 if k % 2 else -0.01), 1.6 + up, _cs(30.0))
        assert not fresh.on and fresh.change_mps < -0.05
        for k in range(300, 300 + int(DRIFT_WINDOW_S) - 10):
            d.add(float(k), 1.8 + (0.01 if k % 2 else -0.01), 1.6, _cs(30.0))
        assert d.on
        for k in range(300 + int(DRIFT_WINDOW_S) - 10, 300 + int(DRIFT_WINDOW_S) + 5):
            d.add(float(k), 1.8 + (0.01 if k % 2 else -0.01), 1.6, _cs(30.0))
        assert not d.on
