"""One UUT's supervision: validation, fallback, faults, relearning — never worse than raw."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import UutCalibration

TRUE = Params("EM3", m=0.15, b_mps=0.1)


def _speed(t: float) -> float:
    return 1.6 + 0.5 * math.sin(2 * math.pi * t / 60.0) + 0.2 * math.sin(2 * math.pi * t / 23.0)


class Rig:
    """A UutCalibration fed by hand: reference at 10 Hz, reading at 1 Hz, no latency."""

    def __init__(
        self, prior: Calibration | None = None, heading: float | None = None, **kw: object
    ) -> None:
        self.events: list[tuple[float, str, Mapping[str, object]]] = []
        s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, **kw)  # type: ignore[arg-type]
        self.cal = UutCalibration(
            s, prior, lambda t: heading, lambda t, k, d: self.events.append((t, k, d))
        )
        self.t = 0.0

    def run(
        self, seconds: float, raw: object = None, ref: object = None, *, judged_first: bool = False
    ) -> list[float | None]:
        """Advance; ``raw(t, v)`` and ``ref(t, v)`` may replace the true reading/reference.

        ``judged_first``: each reading is learnt from and judged before it is corrected
        (as the pipeline does when its reference is in), else corrected first."""
        outs: list[float | None] = []
        for _ in range(int(seconds * 10)):
            self.t += 0.1
            v = _speed(self.t)
            r = ref(self.t, v) if callable(ref) else v
            self.cal.add_reference(self.t, r, True)
            if round(self.t * 10) % 10 == 0:
                reading = raw(self.t, v) if callable(raw) else TRUE.forward(v)
                if not judged_first:
                    outs.append(self.cal.correct(reading))
                self.cal.add_reading(self.t, reading)
                self.cal.drain(self.t)
                if judged_first:
                    outs.append(self.cal.correct(reading))
        return outs

    def kinds(self) -> list[str]:
        return [k for _, k, _ in self.events]


def _applied(rig: Rig) -> Params | None:
    """The applied calibration now (a call: what a run changes is not narrowed away)."""
    return rig.cal.applied


class TestValidation:
    """A calibration is applied only after beating raw on data it did not learn from."""

    def test_a_good_estimate_is_validated_then_applied(self) -> None:
        """The first good estimate is frozen, scored over validation_s, then applied."""
        rig = Rig()
        rig.run(300)
        assert "calibrated" in rig.kinds()
        (t_cal,) = [t for t, k, _ in rig.events if k == "calibrated"]
        proposals = rig.cal.counters.candidates_applied
        assert proposals >= 1
        assert rig.cal.applied is not None and rig.cal.applied.m == pytest.approx(0.15, abs=0.02)
        assert t_cal >= rig.cal.s.validation_s

    def test_a_candidate_worse_than_raw_is_rejected(self) -> None:
        """A candidate that loses to raw in its validation window is not applied."""
        rig = Rig()
        rig.run(20)
        while rig.cal.candidate is None and rig.t < 200.0:
            rig.run(1)
        cand = rig.cal.candidate
        assert cand is not None
        # replace the frozen candidate by one that is plainly wrong
        rig.cal.candidate = type(cand)(Params("EM3", m=-0.3, b_mps=0.4), cand.t0)
        rig.run(rig.cal.s.validation_s + 10.0)
        assert "candidate_rejected" in rig.kinds()
        assert rig.cal.applied is None or rig.cal.applied.m > 0.0


class TestRecheck:
    """The applied calibration is re-checked and dropped once worse than raw."""

    def test_fallback_to_raw_when_the_sensor_changes(self) -> None:
        """After a sensor swap the old calibration loses to raw: fall back, and say so."""
        prior = Calibration("log", Estimate(TRUE, {"m": 0.01, "b": 0.01}), 0.0)
        rig = Rig(prior, recheck_s=60.0, learn=False)
        rig.run(40)
        assert _applied(rig) == TRUE  # the restored calibration re-validated
        outs = rig.run(120, raw=lambda t, v: v)  # the new log reads the truth itself
        assert "fallback" in rig.kinds()
        assert rig.cal.applied is None and rig.cal.state == "uncalibrated"
        assert "fell back to raw" in rig.cal.reason
        late = [o for o in outs[-20:] if o is not None]
        assert late and all(o == pytest.approx(_speed(100.0), abs=1.0) for o in late)

    def test_a_withdrawn_calibration_is_kept_as_the_last_good_one(self) -> None:
        """Withdrawn for cause, a calibration is persisted (not a reset) and is the next
        candidate; the snapshot of a UUT that never had one is a reset."""
        prior = Calibration("log", Estimate(TRUE, {"m": 0.01, "b": 0.01}), 0.0)
        rig = Rig(prior, learn=False)
        rig.run(40)
        rig.run(10, raw=lambda t, v: v)
        assert rig.cal.applied is None
        snap = rig.cal.snapshot()
        assert not snap.reset and snap.params == TRUE
        cand = rig.cal.candidate
        assert cand is not None and cand.params == TRUE and cand.kind == "revalidate"
        assert Rig().cal.snapshot().reset


class TestWaterFrame:
    """The current as a nuisance on a straight line."""

    def test_on_a_straight_line_the_current_takes_the_offset(self) -> None:
        """Heading fixed, 0.3 m/s along the hull: b held at 0, the scale still right."""
        rig = Rig(heading=0.0, current=True)
        rig.run(600, ref=lambda t, v: v + 0.3)
        ident = rig.cal.ident
        assert ident is not None and {"b", "current"} <= set(ident.unidentifiable)
        assert rig.cal.kf.params.b_mps == 0.0
        assert rig.cal.kf.params.m == pytest.approx(0.15, abs=0.02)
        assert not rig.cal.ident_current()


class TestFaults:
    """Sensor faults and glitches."""

    def test_a_dead_log_goes_silent_and_teaches_nothing(self) -> None:
        """A log reading zero while the reference moves: output silent, no learning, named."""
        rig = Rig()
        rig.run(200)
        before = rig.cal.kf.params
        outs = rig.run(60, raw=lambda t, v: 0.0)
        assert rig.cal.state == "fault" and "zero" in rig.cal.reason
        assert outs[-1] is None
        assert rig.cal.kf.params.m == pytest.approx(before.m, abs=0.005)
        assert rig.cal.kf.params.b_mps == pytest.approx(before.b_mps, abs=0.005)
        assert rig.cal.counters.uut_fault > 0

    def test_a_stuck_log_is_detected(self) -> None:
        """A constant reading for stuck_s while the reference moves is a stuck log."""
        rig = Rig(stuck_s=30.0)
        rig.run(100)
        rig.run(40, raw=lambda t, v: 2.2)
        assert rig.cal.health.fault == "uut_stuck" and rig.cal.correct(2.2) is None

    def test_a_run_of_gated_readings_relearns(self) -> None:
        """Readings that stop fitting (a new sensor) re-open the parameters and are learnt."""
        rig = Rig(relearn_gates=10)
        rig.run(300)
        rig.run(300, raw=lambda t, v: 1.4 * v - 0.1)
        assert "relearn" in rig.kinds()
        assert rig.cal.kf.params.m == pytest.approx(0.4, abs=0.05)

    def test_low_speed_output_never_goes_negative(self) -> None:
        """At rest with a positive bias the corrected speed is never negative."""
        prior = Calibration("log", Estimate(Params("EM3", b_mps=0.17), {"b": 0.01}), 0.0)
        rig = Rig(prior)
        assert rig.cal.correct(0.0) == 0.0
        assert rig.cal.correct(0.05) == pytest.approx(0.05)


class TestBlockMeans:
    """Learning from block means of a noisy reference (GNSS)."""

    def test_blocks_close_after_the_window(self) -> None:
        """A block closes after window_s with the means; its heading is the mean vector's."""
        from emlogd.pipeline.uut import BlockMeans

        b = BlockMeans(10.0)
        learn = frozenset({"m", "b"})
        out = None
        for k in range(11):
            ang = math.radians(80.0 if k % 2 else 100.0)
            out = b.add(float(k), 2.0 + k, 1.0, (math.cos(ang), math.sin(ang)), learn)
            if k < 10:
                assert out is None
        assert out is not None
        raw, ref, cs, unknowns = out
        assert raw == pytest.approx(7.0) and ref == 1.0 and unknowns == learn
        assert cs is not None and math.degrees(math.atan2(cs[1], cs[0])) == pytest.approx(
            90.0, abs=1.0
        )
        assert b.n == 0

    def test_turns_gaps_and_changed_unknowns_drop_the_block(self) -> None:
        """A U-turn inside the block, a 6-s gap or a new set of unknowns starts again."""
        from emlogd.pipeline.uut import BlockMeans

        learn = frozenset({"m", "b"})
        b = BlockMeans(10.0)
        for k in range(11):  # turning through 180° in 10 s
            ang = math.radians(18.0 * k)
            assert b.add(float(k), 1.0, 1.0, (math.cos(ang), math.sin(ang)), learn) is None
        b = BlockMeans(10.0)
        b.add(0.0, 1.0, 1.0, None, learn)
        b.add(6.5, 1.0, 1.0, None, learn)  # gap: the block restarts at 6.5
        assert b.t0 == 6.5 and b.n == 1
        b.add(7.0, 1.0, 1.0, None, frozenset({"b"}))
        assert b.t0 == 7.0 and b.n == 1

    def test_noisy_gnss_reference_gives_the_sensors_scale(self) -> None:
        """A reference with 0.3 m/s of noise: the scale is learnt from block means within
        0.03 over two hours of speed changes, where sample-by-sample learning with the
        same filter is pulled further (average_s: 0). The supervisor's change detector
        may withdraw the applied calibration on this reference's noise, re-opening the
        parameters to the prior; the block means learn the scale back each time, so it
        does not drift."""
        rng = np.random.default_rng(3)

        def run(average_s: float | None) -> float:
            s = UutSettings(
                port="log", reference_port="gps", reference_field="gnss", lag_s=0.0,
                average_s=average_s,
            )  # fmt: skip
            cal = UutCalibration(s, None, lambda t: None, lambda t, k, d: None)
            noise = np.random.default_rng(5).normal(0.0, 0.3, 7200)
            for k in range(7200):
                t = float(k)
                v = 2.5 + 1.2 * math.sin(2 * math.pi * t / 400.0)
                cal.add_reference(t, v + float(noise[k]), True)
                cal.add_reading(t, TRUE.forward(v) + float(rng.normal(0.0, 0.03)))
                cal.drain(t)
            return cal.kf.params.m

        m_blocks = run(None)
        assert m_blocks == pytest.approx(TRUE.m, abs=0.03)
        assert abs(run(0.0) - TRUE.m) > abs(m_blocks - TRUE.m)


def test_a_restored_current_is_aged_by_the_time_the_daemon_was_down() -> None:
    """A calibration saved an hour before the first reading: its current's variance grows by
    the random walk over that hour before it is used (it is no longer known to 2 mm/s)."""
    cur_std = (0.002, 0.002)
    prior = Calibration(
        "log",
        Estimate(TRUE, {"m": 0.01, "b": 0.01}, current_mps=(0.1, 0.0), current_std_mps=cur_std),
        0.0,
        current=True,
        covariance=tuple(tuple(r) for r in np.diag([1.0, 1e-4, 1e-4, 4e-6, 4e-6]).tolist()),
        t=-3600.0,
    )
    rig = Rig(prior, heading=90.0, current=True, learn=False)
    std0 = rig.cal.kf.current_std_mps
    assert std0 is not None and std0[0] < 0.01
    rig.run(1.0)
    std1 = rig.cal.kf.current_std_mps
    psd = rig.cal.s.kf.current_psd_m2ps3
    assert std1 is not None and std1[0] >= math.sqrt(psd * 3600.0) * 0.99


def _prior(p: Params = TRUE) -> Calibration:
    return Calibration("log", Estimate(p, {"m": 0.01, "b": 0.01}), 0.0)


def _saved_with_bow_current(p: Params) -> Rig:
    """A rig on a straight leg (heading 0) in the water frame, not learning, restored
    with ``p`` saved with 0.3 m/s of current on the bow."""
    prior = Calibration(
        "log",
        Estimate(p, {"m": 0.01, "b": 0.01}, current_mps=(-0.3, 0.0)),
        0.0,
        current=True,
    )
    return Rig(prior, heading=0.0, current=True, learn=False)


def _saved_in_still_water(saved_t: float) -> Rig:
    """A rig on a straight leg (heading 0) in the water frame, not learning, restored
    with TRUE saved at ``saved_t`` with no current (±0.05 m/s)."""
    est = Estimate(
        TRUE, {"m": 0.01, "b": 0.01}, current_mps=(0.0, 0.0), current_std_mps=(0.05, 0.05)
    )
    prior = Calibration("log", est, 0.0, current=True, t=saved_t)
    return Rig(prior, heading=0.0, current=True, learn=False)


def _stern_current_leg(rig: Rig, seconds: float, rng: np.random.Generator) -> list[float | None]:
    """``seconds`` at 2 m/s through the water in 0.24 m/s of current on the stern, the
    log reading ``TRUE.forward(2.0)`` with 0.03 m/s of noise."""
    return rig.run(
        seconds,
        raw=lambda t, v: TRUE.forward(2.0) + float(rng.normal(0.0, 0.03)),
        ref=lambda t, v: 2.0 + 0.24,
    )


class TestChangeDetection:
    """A sensor that changes loses its calibration within seconds; a sea that changes does not."""

    def test_a_gain_step_is_withdrawn_within_seconds(self) -> None:
        """A 35 % gain step: the calibration goes back to raw within 5 s, and learning reopens."""
        rig = Rig(_prior())
        rig.run(60)
        assert rig.cal.applied == TRUE
        t_step = rig.t
        rig.run(20, raw=lambda t, v: 0.65 * TRUE.forward(v))
        falls = [t for t, k, _ in rig.events if k == "fallback"]
        assert falls and falls[0] - t_step <= 5.0
        assert rig.cal.counters.changes == 1
        assert "relearn" in [k for t, k, _ in rig.events if t >= t_step]
        assert rig.cal.applied is None or rig.cal.applied != TRUE

    def test_offline_a_change_withdraws_without_reopening_the_learner(self) -> None:
        """Without ``reopen_on_change`` (offline calibrate: one model over the recording)
        the same step is withdrawn as quickly, and the learner keeps what it knew."""
        rig = Rig(_prior())
        rig.cal.reopen_on_change = False
        rig.run(60)
        std_before = rig.cal.learner.param_std["m"]
        t_step = rig.t
        rig.run(20, raw=lambda t, v: 0.65 * TRUE.forward(v))
        falls = [t for t, k, _ in rig.events if k == "fallback"]
        assert falls and falls[0] - t_step <= 5.0
        assert rig.cal.counters.changes == 1 and rig.cal.counters.relearn == 0
        assert "relearn" not in rig.kinds()
        assert rig.cal.learner.shadow is None
        assert rig.cal.learner.param_std["m"] < 1.5 * std_before  # re-opened: σ 0.3

    def test_a_gain_step_goes_out_raw_from_its_first_reading(self) -> None:
        """A 20 % gain step judged before it is emitted: its first reading is an
        innovation far beyond the noise, which holds the calibration (raw goes out) while
        the CUSUM builds up to its alarm; no reading of the changed log goes out
        corrected for the log before the change."""
        rig = Rig(_prior())
        rig.run(60, judged_first=True)
        assert rig.cal.applied == TRUE

        def dipped(t: float, v: float) -> float:
            return 0.8 * TRUE.forward(v)

        readings = [dipped(t, _speed(t)) for t in rig.t + np.arange(1.0, 6.0)]
        outs = rig.run(5, raw=dipped, judged_first=True)
        assert outs == pytest.approx(readings)
        assert "fallback" in rig.kinds()

    def test_one_glitch_holds_the_calibration_until_its_cusum_run_ends(self) -> None:
        """One reading 20 % low goes out raw, and so do the next few while the CUSUM run
        it opened decays; then the calibration is emitted again, never withdrawn."""
        rig = Rig(_prior())
        rig.run(60, judged_first=True)
        t_glitch = rig.t + 1.0

        def glitch(t: float, v: float) -> float:
            return (0.8 if abs(t - t_glitch) < 0.05 else 1.0) * TRUE.forward(v)

        outs = rig.run(20, raw=glitch, judged_first=True)
        truth = [_speed(t) for t in t_glitch + np.arange(0.0, 20.0)]
        assert outs[0] == pytest.approx(glitch(t_glitch, truth[0]))  # raw
        assert outs[1] == pytest.approx(TRUE.forward(truth[1]))  # still held: raw
        assert outs[10:] == pytest.approx(truth[10:], abs=1e-9)  # corrected again
        assert "fallback" not in rig.kinds() and rig.cal.applied == TRUE

    def test_a_sensor_that_jumped_is_judged_in_the_sea_before_the_jump(self) -> None:
        """A 35 % gain step on a straight leg in the water frame: the log jumped and the
        reference did not, so the withdrawn calibration re-validates in the sea as it was
        (raw and it alike) and stays out while the step lasts (a current fitted after
        the step would take its error, and it would come back within the step)."""
        rig = Rig(_prior(), heading=0.0, current=True, learn=False)
        rig.run(60)
        assert rig.cal.applied == TRUE
        t_step = rig.t
        rig.run(5, raw=lambda t, v: 0.65 * TRUE.forward(v))
        cand = rig.cal.candidate
        assert cand is not None and cand.kind == "revalidate" and cand.sea_fixed
        rig.run(55, raw=lambda t, v: 0.65 * TRUE.forward(v))
        after = [(k, d) for t, k, d in rig.events if t >= t_step]
        (fall,) = [d for k, d in after if k == "fallback"]
        assert abs(float(fall["step_log_mps"])) > 0.3  # type: ignore[arg-type]
        assert abs(float(fall["step_reference_mps"])) < 0.05  # type: ignore[arg-type]
        assert not [d for k, d in after if k == "calibrated"]
        assert ("candidate_rejected", "revalidate") in [(k, d.get("kind")) for k, d in after]
        assert rig.cal.applied is None

    def test_a_current_that_jumps_does_not_withdraw_a_good_calibration(self) -> None:
        """A 0.3 m/s head current at once: the calibration still beats raw, and stays.

        (A jump that raw's own error happens to cancel is not told from a sensor change
        at one heading: that one withdraws to raw, which is safe.)"""
        rig = Rig(_prior(), heading=0.0, current=True)
        rig.run(120)
        assert rig.cal.applied == TRUE
        t_jump = rig.t
        rig.run(60, ref=lambda t, v: v - 0.3)
        assert not [t for t, k, _ in rig.events if k == "fallback" and t >= t_jump]
        assert rig.cal.applied == TRUE

    @pytest.mark.parametrize("prior", [True, False], ids=["applied", "raw"])
    def test_a_current_that_jumps_reopens_the_learners_current(self, prior: bool) -> None:
        """A 0.4 m/s head current at once on a straight leg: the reference jumped and the
        log did not, so the learner's current re-opens (the jump goes into the current,
        not into the bias), with a calibration applied and with raw passing alike."""
        rig = Rig(_prior() if prior else None, heading=0.0, current=True)
        rig.run(180)
        cal = rig.cal
        assert (cal.applied == TRUE) is prior
        before = cal.learner.kf.current_std_mps
        assert before is not None and before[0] < 0.2
        t_jump = rig.t
        rig.run(3, ref=lambda t, v: v - 0.4)
        why = [str(d.get("why")) for t, k, d in rig.events if k == "relearn" and t > t_jump]
        assert why == ["the reference jumped: the current learns again"]
        after = cal.learner.kf.current_std_mps
        assert after is not None and after[0] > 2.0 * before[0]

    def test_a_small_jump_of_the_reference_does_not_reopen_the_current(self) -> None:
        """A 0.1 m/s jump of the reference: the detector alarms, but the jump is within
        ``SEA_STEP_SIGMAS`` of the innovations' spread: the learner's current is left as
        it was."""
        rig = Rig(None, heading=0.0, current=True)
        rig.run(180)
        t_jump = rig.t
        rig.run(60, ref=lambda t, v: v - 0.1)
        why = [str(d.get("why")) for t, k, d in rig.events if k == "relearn" and t > t_jump]
        assert "the reference jumped: the current learns again" not in why

    def test_a_log_that_drifts_on_a_straight_leg_is_withdrawn_and_kept_out(self) -> None:
        """At a steady 1.6 m/s on a straight leg, the gain falls 0.05 % a second (fouling):
        the calibration is withdrawn once the log has drifted, and no calibration is
        applied while it drifts; the same leg without the drift keeps it."""
        steady = Rig(_prior(), heading=0.0, current=True, learn=False)
        steady.run(300, raw=lambda t, v: TRUE.forward(1.6), ref=lambda t, v: 1.6)
        assert steady.cal.applied == TRUE and "fallback" not in steady.kinds()
        rig = Rig(_prior(), heading=0.0, current=True, learn=False)
        rig.run(60, raw=lambda t, v: TRUE.forward(1.6), ref=lambda t, v: 1.6)
        assert rig.cal.applied == TRUE
        t0 = rig.t
        rig.run(
            240,
            raw=lambda t, v: TRUE.forward(1.6) * (1.0 - 0.0005 * (t - t0)),
            ref=lambda t, v: 1.6,
        )
        falls = [(t, d) for t, k, d in rig.events if k == "fallback"]
        assert [d["why"] for _, d in falls] == ["the log drifts against a steady reference"]
        assert falls[0][0] - t0 <= 150.0
        assert not [k for t, k, _ in rig.events if t > falls[0][0] and k == "calibrated"]
        assert rig.cal.applied is None


class TestRestored:
    """A restored calibration re-earns trust before it is applied."""

    def test_a_good_one_is_applied_after_its_validation_raw_meanwhile(self) -> None:
        """Raw passes through until the restored calibration has validated, then it applies."""
        from emlogd.pipeline.supervisor import RESTORE_VALIDATION_S

        rig = Rig(_prior())
        outs = rig.run(RESTORE_VALIDATION_S - 5.0)
        readings = [TRUE.forward(_speed(float(t))) for t in range(1, len(outs) + 1)]
        assert outs == pytest.approx(readings)
        assert rig.cal.applied is None and "awaiting validation" in rig.cal.reason
        rig.run(20)
        assert rig.cal.applied == TRUE

    def test_a_poisoned_state_inside_the_envelope_is_never_applied(self) -> None:
        """m = -0.5, b = +1.0 (inside the envelope): rejected against the reference."""
        bad = Params("EM3", m=-0.5, b_mps=1.0)
        rig = Rig(_prior(bad), learn=False)
        outs = rig.run(120)
        assert rig.cal.applied != bad
        assert "candidate_rejected" in rig.kinds()
        truth = [_speed(float(t)) for t in range(1, len(outs) + 1)]
        raw = [TRUE.forward(v) for v in truth]
        assert all(o == pytest.approx(r) for o, r in zip(outs, raw, strict=True))

    def test_on_a_straight_leg_it_is_judged_in_the_sea_it_was_saved_in(self) -> None:
        """A log reading 15 % low, restored with the current it was saved with (0.3 m/s
        on the bow), on a straight leg at constant speed in that current: against the
        reference as it is, raw's error happens to offset the current and raw wins; in
        the saved sea the calibration is the better and it is applied. A poisoned one
        (m = -0.5, b = +1) is still refused in the same sea."""
        from emlogd.pipeline.supervisor import RESTORE_VALIDATION_S

        low = Params("EM3", m=-0.15, b_mps=0.1)
        rng = np.random.default_rng(7)

        def rig_for(p: Params) -> Rig:
            rig = _saved_with_bow_current(p)
            rig.run(
                RESTORE_VALIDATION_S + 30.0,
                raw=lambda t, v: low.forward(2.0) + float(rng.normal(0.0, 0.05)),
                ref=lambda t, v: 2.0 - 0.3,
            )
            return rig

        assert _applied(rig_for(low)) == low
        bad = Params("EM3", m=-0.5, b_mps=1.0)
        assert _applied(rig_for(bad)) is None

    def test_with_its_saved_sea_it_is_applied_on_its_first_samples(self) -> None:
        """Restored with the current it was saved with (0.3 m/s on the bow) and in that
        sea: after RESTORE_EARLY_SAMPLES readings raw is worse than it, and it is applied
        then, validated in place afterwards. A poisoned one (m = -0.5, b = +1) in the same
        sea is never applied."""
        from emlogd.pipeline.supervisor import RESTORE_EARLY_SAMPLES, RESTORE_VALIDATION_S

        def rig_for(p: Params) -> tuple[Rig, list[float | None]]:
            rig = _saved_with_bow_current(p)
            outs = rig.run(RESTORE_EARLY_SAMPLES + 1.0, ref=lambda t, v: v - 0.3)
            return rig, outs

        rig, outs = rig_for(TRUE)
        raw = [TRUE.forward(_speed(float(t))) for t in range(1, len(outs) + 1)]
        assert outs[:RESTORE_EARLY_SAMPLES] == pytest.approx(raw[:RESTORE_EARLY_SAMPLES])
        assert outs[-1] == pytest.approx(_speed(float(len(outs))))
        early = [d for _, k, d in rig.events if k == "calibrated"]
        assert _applied(rig) == TRUE and early and early[0]["kind"] == "restored-early"
        rig.run(RESTORE_VALIDATION_S, ref=lambda t, v: v - 0.3)
        assert _applied(rig) == TRUE and "calibration_verified" in rig.kinds()
        bad, outs = rig_for(Params("EM3", m=-0.5, b_mps=1.0))
        bad.run(RESTORE_VALIDATION_S, ref=lambda t, v: v - 0.3)
        assert _applied(bad) is None and "candidate_rejected" in bad.kinds()

    def test_on_a_straight_leg_with_no_saved_sea_it_keeps_its_verdict(self) -> None:
        """No current saved, a straight leg at 3 m/s in 0.4 m/s of current on the stern:
        raw's error (+0.55) happens to offset the current, so against the reference raw
        wins, and a current fitted to the window takes either one's offset. The restored
        calibration implies a current of 0.4 m/s, one the sea can have: applied. A poisoned
        one (m = -0.5, b = +1) implies 1.7 m/s: refused."""
        from emlogd.pipeline.supervisor import RESTORE_VALIDATION_S

        rng = np.random.default_rng(11)

        def rig_for(p: Params) -> Rig:
            rig = Rig(_prior(p), heading=0.0, current=True, learn=False)
            rig.run(
                RESTORE_VALIDATION_S + 30.0,
                raw=lambda t, v: TRUE.forward(3.0) + float(rng.normal(0.0, 0.05)),
                ref=lambda t, v: 3.0 + 0.4,
            )
            return rig

        good = rig_for(TRUE)
        assert _applied(good) == TRUE
        (detail,) = [d for _, k, d in good.events if k == "calibrated"]
        assert detail["implied_current_mps"] == pytest.approx(-0.4, abs=0.03)
        assert _applied(rig_for(Params("EM3", m=-0.5, b_mps=1.0))) is None

    def test_on_a_straight_leg_a_saved_sea_is_trusted_as_its_age_allows(self) -> None:
        """Saved with no current (±0.05 m/s), a straight leg at 2 m/s in 0.24 m/s of
        current on the stern, where raw's error (+0.4) nearly offsets it: in the saved sea
        raw wins. Saved 300 s before, the sea may have moved by 3σ = 0.26 m/s (the saved
        uncertainty and the learner's random walk): applied. Saved just now: refused."""
        from emlogd.pipeline.supervisor import RESTORE_VALIDATION_S

        def applied_after(saved_t: float) -> Params | None:
            rig = _saved_in_still_water(saved_t)
            _stern_current_leg(rig, RESTORE_VALIDATION_S + 30.0, np.random.default_rng(13))
            return _applied(rig)

        assert applied_after(-300.0) == TRUE
        assert applied_after(0.0) is None

    def test_on_a_straight_leg_a_sea_that_moved_applies_it_on_its_first_samples(self) -> None:
        """The leg above (saved 300 s before in still water, 0.24 m/s of current on the
        stern now): in the saved sea raw wins, and the current it implies is one the sea
        can have moved to, which more samples of one heading would not change: applied
        after RESTORE_EARLY_SAMPLES readings, verified at the end of its window. Saved
        just now the same current is beyond the sea's allowance: raw passes through."""
        from emlogd.pipeline.supervisor import RESTORE_EARLY_SAMPLES, RESTORE_VALIDATION_S

        rng = np.random.default_rng(13)
        rig = _saved_in_still_water(-300.0)
        _stern_current_leg(rig, RESTORE_EARLY_SAMPLES + 1.0, rng)
        early = [d for _, k, d in rig.events if k == "calibrated"]
        assert _applied(rig) == TRUE and early and early[0]["kind"] == "restored-early"
        assert early[0]["implied_current_mps"] == pytest.approx(-0.24, abs=0.05)
        _stern_current_leg(rig, RESTORE_VALIDATION_S, rng)
        assert _applied(rig) == TRUE and "calibration_verified" in rig.kinds()
        now = _saved_in_still_water(0.0)
        outs = _stern_current_leg(now, RESTORE_EARLY_SAMPLES + 1.0, rng)
        assert _applied(now) is None and "calibrated" not in now.kinds()
        assert all(o == pytest.approx(TRUE.forward(2.0), abs=0.2) for o in outs)

    def test_refused_on_a_straight_leg_it_is_judged_again_as_the_sea_ages(self) -> None:
        """Saved just now with no current (±0.05 m/s), then a straight leg at 2 m/s in 0.32
        m/s of current on the stern (the sea moved faster than the learner's random walk):
        the current it implies is beyond 3σ of the saved sea and raw's (0.08 m/s) the
        likelier by more than that, and it is refused, raw passing through. It was not
        shown wrong, and every RESTORE_RETRY_S it is judged again, the saved sea aged to
        then: once the sea may have moved by as much it is applied. A poisoned one (m =
        -0.5, b = +1) implies 1.7 m/s and stays refused."""
        from emlogd.pipeline.supervisor import RESTORE_RETRY_S

        rng = np.random.default_rng(17)

        def rig_for(p: Params) -> Rig:
            prior = Calibration(
                "log",
                Estimate(
                    p, {"m": 0.01, "b": 0.01}, current_mps=(0.0, 0.0), current_std_mps=(0.05, 0.05)
                ),
                0.0,
                current=True,
                t=0.0,
            )
            return Rig(prior, heading=0.0, current=True, learn=False)

        def leg(rig: Rig, seconds: float) -> None:
            rig.run(
                seconds,
                raw=lambda t, v: TRUE.forward(2.0) + float(rng.normal(0.0, 0.03)),
                ref=lambda t, v: 2.0 + 0.32,
            )

        good, bad = rig_for(TRUE), rig_for(Params("EM3", m=-0.5, b_mps=1.0))
        leg(good, RESTORE_RETRY_S)
        assert _applied(good) is None and "candidate_rejected" in good.kinds()
        leg(good, 4.0 * RESTORE_RETRY_S)
        assert _applied(good) == TRUE
        assert good.kinds().count("candidate_rejected") >= 2  # refused at least once more first
        leg(bad, 4.0 * RESTORE_RETRY_S)
        assert _applied(bad) is None

    def test_without_a_reference_it_is_applied_unverified(self) -> None:
        """No reference heard RESTORE_WAIT_S after the first reading: applied, and said so."""
        from emlogd.pipeline.supervisor import RESTORE_WAIT_S

        rig = Rig(_prior())
        for i in range(int(RESTORE_WAIT_S) + 5):
            t = float(i + 1)
            rig.cal.add_reading(t, TRUE.forward(_speed(t)))
            rig.cal.drain(t)
        assert rig.cal.applied == TRUE
        assert "unverified" in rig.cal.reason
        assert "calibration_unverified" in rig.kinds()


class TestStuckAndStalled:
    """A log that does not follow the reference is not learnt from."""

    def test_a_noisy_stuck_log_is_detected_by_its_spread(self) -> None:
        """3.0 ± 0.03 m/s while the reference swings by a metre per second: stuck."""
        rig = Rig()
        rig.run(100)
        noise = np.random.default_rng(3)
        outs = rig.run(90, raw=lambda t, v: 3.0 + float(noise.normal(0.0, 0.03)))
        assert rig.cal.state == "fault" and "stuck" in rig.cal.reason
        assert outs[-1] is None and rig.cal.counters.uut_fault > 0

    def test_a_stalled_wheel_is_gated_from_its_first_sample(self) -> None:
        """Readings of 0-0.2 m/s while the reference shows 1-2 m/s: none is learnt or validated."""
        rig = Rig()
        rig.run(100)
        before = rig.cal.kf.params
        learnt, scored = rig.cal.counters.learnt, rig.cal.score.n
        wheel = np.random.default_rng(5)
        rig.run(8, raw=lambda t, v: float(wheel.uniform(0.0, 0.2)))
        assert rig.cal.counters.uut_stalled == 8
        assert rig.cal.counters.learnt == learnt and rig.cal.score.n == scored
        assert rig.cal.kf.params.m == pytest.approx(before.m, abs=1e-9)
