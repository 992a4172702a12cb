"""Integrity pieces: the envelope, the low-speed policy, sensor faults, glitches, error windows."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from calib.models import Params
from emlogd.pipeline.integrity import (
    STUCK_BLOCK_S,
    Envelope,
    JumpFilter,
    PairedWindow,
    UutHealth,
    emitted_speed,
)

ENV = Envelope(max_speed_mps=10.0)


class TestEnvelope:
    """What a calibration may be."""

    def test_a_real_log_fits(self) -> None:
        """The simulator's EM4 logs are inside the default envelope."""
        assert Envelope().check(Params("EM4", 0.03, 0.17, 0.12)) == ""
        assert Envelope().check(Params("EM4", -0.02, -0.11, -0.05)) == ""

    @pytest.mark.parametrize(
        ("params", "why"),
        [
            (Params("EM3", m=-0.6), "scale"),
            (Params("EM3", m=-2.0), "scale"),
            (Params("EM3", b_mps=1e6), "bias"),
            (Params("EM4", a_spm=0.2), "curvature"),
            (Params("EM4", a_spm=-0.06), "monotonic"),
            (Params("EM4", a_spm=-0.03), "saturates"),
        ],
    )
    def test_absurd_calibrations_are_outside(self, params: Params, why: str) -> None:
        """Scale, bias, curvature, monotonicity and saturation limits each say why."""
        assert why in ENV.check(params)

    def test_the_current_is_bounded(self) -> None:
        """A current above max_current_mps is outside."""
        assert "current" in ENV.check(Params("EM3"), (3.0, 2.0))
        assert ENV.check(Params("EM3"), (0.3, -0.2)) == ""

    @given(
        a=st.floats(-0.1, 0.1),
        m=st.floats(-0.5, 0.5),
        b=st.floats(-0.5, 0.5),
        raw=st.floats(0.0, 10.0),
    )
    def test_the_inverse_is_monotonic_and_exact_inside_the_envelope(
        self, a: float, m: float, b: float, raw: float
    ) -> None:
        """For every admitted EM4, correct() inverts forward() and grows with the reading."""
        p = Params("EM4", a, m, b)
        if ENV.check(p):
            return
        u = p.correct(raw)
        assert math.isfinite(u)
        assert p.forward(u) == pytest.approx(raw, abs=1e-9)
        assert p.correct(raw + 0.01) > u


class TestEmittedSpeed:
    """The low-speed and range policy."""

    def test_at_rest_the_bias_does_not_make_sternway(self) -> None:
        """A log at rest with a positive bias emits its own reading, never a negative speed."""
        assert emitted_speed(-0.17, 0.0, 0.25, 10.0) == 0.0
        assert emitted_speed(-0.05, 0.1, 0.25, 10.0) == pytest.approx(0.1)
        assert emitted_speed(-0.2, 0.3, 0.25, 10.0) == 0.0

    def test_sternway_the_log_reads_goes_out_as_read(self) -> None:
        """A log astern reading -1.02 m/s (and the blend disabled: its correction) emits
        what it reads, no further astern than it; it went out at 0 (a simulated log 5
        min astern at 1 m/s: every 5-min window 4 to 10 times raw's error)."""
        assert emitted_speed(-0.9, -1.02, 0.25, 10.0) == pytest.approx(-1.02)
        assert emitted_speed(-0.9, -1.02, 0.0, 10.0) == pytest.approx(-0.9)
        assert emitted_speed(-1.3, -1.02, 0.0, 10.0) == pytest.approx(-1.02)
        assert emitted_speed(-0.2, -0.05, 0.25, 10.0) == pytest.approx(-0.05)

    def test_the_blend_is_continuous(self) -> None:
        """From half the threshold to the threshold the output blends raw into corrected."""
        assert emitted_speed(0.2, 0.25, 0.25, 10.0) == pytest.approx(0.2)
        assert emitted_speed(0.1, 0.1875, 0.25, 10.0) == pytest.approx(0.5 * 0.1 + 0.5 * 0.1875)

    def test_clamped_to_the_range_and_nan_stays_nan(self) -> None:
        """Above the range the output is the range; a non-finite correction is nan."""
        assert emitted_speed(50.0, 20.0, 0.25, 10.0) == 10.0
        assert math.isnan(emitted_speed(math.nan, 2.0, 0.25, 10.0))


class TestUutHealth:
    """Stuck and dead logs."""

    def test_a_stuck_log_while_the_reference_moves(self) -> None:
        """An unchanged reading for stuck_s while the reference moves is a fault; a reading
        that follows the reference again for a block clears it."""
        h = UutHealth(stuck_s=30.0)
        for k in range(40):
            fault = h.update(float(k), 2.0, 1.5 + 0.02 * k)
        assert fault == "uut_stuck"
        for k in range(40, 40 + int(STUCK_BLOCK_S) + 2):
            fault = h.update(float(k), 0.5 + 0.04 * k, 1.5 + 0.02 * k)
        assert fault == ""

    def test_a_noisy_stuck_log_is_stuck_by_its_spread(self) -> None:
        """3.0 ± 0.03 m/s (every reading moves) while the reference climbs 0.8 m/s: stuck;
        the same noise on a reading that follows the reference is not."""
        rng = np.random.default_rng(1)
        stuck, good = UutHealth(stuck_s=60.0), UutHealth(stuck_s=60.0)
        for k in range(80):
            ref = 1.5 + 0.01 * k
            f_stuck = stuck.update(float(k), 3.0 + float(rng.normal(0.0, 0.03)), ref)
            f_good = good.update(float(k), 1.1 * ref + float(rng.normal(0.0, 0.03)), ref)
        assert f_stuck == "uut_stuck" and f_good == ""

    def test_a_log_holding_one_step_of_its_resolution_is_not_stuck(self) -> None:
        """A 0.1-kn log on a steady yacht reads 5.8 and 5.9 kn (its 10-s means span one
        step, 0.051 m/s) while the GNSS speed's 10-s means wander 0.33 m/s with its noise
        (Irene 2014-06-27): a span of one step is no evidence of a stuck log."""
        step = 0.1 * 0.514444
        h = UutHealth(stuck_s=60.0)
        refs = [3.20, 3.16, 3.08, 2.98, 3.31, 3.10, 3.15]
        fault = ""
        for k in range(70):
            raw = 58 * step if (k // 7) % 3 else 59 * step
            fault = h.update(float(k), raw, refs[k // 10], heading_deg=215.0) or fault
        assert h.resolution_mps == pytest.approx(step)
        assert fault == ""

    def test_the_spread_rule_waits_for_a_steady_heading(self) -> None:
        """In a turn the reference moves with the current's projection while the speed
        through the water stays: a steady reading is not stuck there."""
        rng = np.random.default_rng(2)
        turning, steady = UutHealth(stuck_s=60.0), UutHealth(stuck_s=60.0)
        for k in range(80):
            raw, ref = 3.0 + float(rng.normal(0.0, 0.03)), 1.5 + 0.01 * k
            f_turning = turning.update(float(k), raw, ref, heading_deg=3.0 * k)
            f_steady = steady.update(float(k), raw, ref, heading_deg=90.0)
        assert f_turning == "" and f_steady == "uut_stuck"

    def test_a_stalled_wheel(self) -> None:
        """Below half the reference at speed: stalled; at rest or following: not."""
        assert UutHealth.stalled(0.2, 0.6)
        assert not UutHealth.stalled(0.2, 0.3)
        assert not UutHealth.stalled(0.5, 0.6)
        assert not UutHealth.stalled(0.2, None)

    def test_a_reading_at_zero_while_the_reference_moves(self) -> None:
        """A log below its threshold (a dead band) reads 0.00: at any reference speed
        that is learnt (0.3–0.5 m/s too, below the stall rule's speed), and astern, the
        reading is stalled from its first sample; at rest it is not, nor is a slow
        reading above zero."""
        assert UutHealth.stalled(0.0, 0.35)
        assert UutHealth.stalled(0.005, 0.45)
        assert UutHealth.stalled(0.0, -0.4)
        assert not UutHealth.stalled(0.0, 0.02)
        assert not UutHealth.stalled(0.0, None)
        assert not UutHealth.stalled(0.02, 0.35)

    def test_constant_speed_and_reference_is_no_fault(self) -> None:
        """A steady log on a steady reference is not stuck."""
        h = UutHealth(stuck_s=30.0)
        for k in range(100):
            fault = h.update(float(k), 2.0, 1.9)
        assert fault == ""

    def test_zero_while_moving(self) -> None:
        """A reading of zero for zero_s while the reference moves is a dead log."""
        h = UutHealth(zero_s=10.0)
        for k in range(12):
            fault = h.update(float(k), 0.0 if k % 2 else 0.005, 2.0)
        assert fault == "uut_zero"
        h2 = UutHealth(zero_s=10.0)
        for k in range(20):
            fault = h2.update(float(k), 0.0, 0.1)  # the vessel is at rest: no fault
        assert fault == ""

    def test_a_zero_fault_lapses_without_a_reference_showing_motion(self) -> None:
        """Zero at 0.7 m/s for 10 s is a fault, which stands through a short loss of the
        reference; moored (no GNSS speed, the log at zero) it lapses after zero_s."""
        h = UutHealth(zero_s=10.0)
        for k in range(12):
            fault = h.update(float(k), 0.0, 0.7)
        assert fault == "uut_zero"
        assert h.update(15.0, 0.0, None) == "uut_zero"
        assert h.update(22.0, 0.0, None) == ""
        for k in range(23, 40):
            fault = h.update(float(k), 0.0, None)
        assert fault == ""


class TestJumpFilter:
    """Glitches and re-acquisition."""

    def test_a_glitch_is_refused_and_the_old_level_continues(self) -> None:
        """A 2 s spike of +30 m/s is refused; the next normal sample is accepted."""
        f = JumpFilter(max_rate=2.0, margin=0.3, confirm_s=3.0)
        assert f.accept(0.0, 2.0)
        assert not any(f.accept(0.1 * k, 32.0) for k in range(1, 21))
        assert f.accept(2.2, 2.05)
        assert f.rejected == 20

    def test_a_new_level_is_accepted_after_confirmation(self) -> None:
        """A level that persists for confirm_s is accepted (the vessel really is elsewhere)."""
        f = JumpFilter(max_rate=2.0, margin=0.3, confirm_s=3.0)
        f.accept(0.0, 1.0)
        results = [f.accept(10.0 + 0.1 * k, 30.0) for k in range(40)]
        assert not results[0] and results[-1]

    def test_headings_wrap(self) -> None:
        """A heading from 359° to 1° is a 2° change, not 358°."""
        f = JumpFilter(max_rate=30.0, margin=5.0, angular=True)
        assert f.accept(0.0, 359.0) and f.accept(0.1, 1.0)
        assert not f.accept(0.2, 120.0)


class TestPairedWindow:
    """RMS errors of three calibrations over one forgetting window."""

    def test_recent_errors_dominate_and_the_three_share_their_samples(self) -> None:
        """After a half-life the old errors weigh half; the three figures share weights."""
        w = PairedWindow(half_life_s=10.0)
        w.add(0.0, 1.0, 2.0, 0.0)
        w.add(10.0, 0.0, 0.0, 1.0)
        raw, app, prev = w.rmse()
        assert raw == pytest.approx(math.sqrt(0.5 / 1.5))
        assert app == pytest.approx(math.sqrt(2.0 / 1.5))
        assert prev == pytest.approx(math.sqrt(1.0 / 1.5))
        w.reset()
        assert math.isnan(w.rmse()[0]) and w.n_effective == 0.0
