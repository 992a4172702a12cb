"""One UUT's supervision: validation, fallback, faults, relearning — never worse than raw."""

from __future__ import annotations

import math
from collections.abc import Mapping

import pytest

from calib.models import Params
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import UutSettings
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

    def run(self, seconds: float, raw: object = None, ref: object = None) -> list[float | None]:
        """Advance; ``raw(t, v)`` and ``ref(t, v)`` may replace the true reading/reference."""
        outs: list[float | None] = []
        for _ in range(int(seconds * 10)):
            self.t += 0.1
            v = _speed(self.t)
            r = ref(self.t, v) if callable(ref) else v
            self.cal.add_reference(self.t, r, True)
            if round(self.t * 10) % 10 == 0:
                reading = raw(self.t, v) if callable(raw) else TRUE.forward(v)
                outs.append(self.cal.correct(reading))
                self.cal.add_reading(self.t, reading)
                self.cal.drain(self.t)
        return outs

    def kinds(self) -> list[str]:
        return [k for _, k, _ in self.events]


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
        prior = Calibration("log", TRUE, {"m": 0.01, "b": 0.01}, 0.0)
        rig = Rig(prior, recheck_s=60.0, learn=False)
        outs = rig.run(120, raw=lambda t, v: v)  # the new log reads the truth itself
        assert "fallback" in rig.kinds()
        assert rig.cal.applied is None and rig.cal.state == "uncalibrated"
        assert "fell back to raw" in rig.cal.reason
        late = [o for o in outs[-20:] if o is not None]
        assert late and all(o == pytest.approx(_speed(100.0), abs=1.0) for o in late)

    def test_fallback_to_the_previous_calibration(self) -> None:
        """A newer calibration gone bad gives way to the previous good one when that beats raw."""
        prior = Calibration("log", TRUE, {"m": 0.01, "b": 0.01}, 0.0)
        rig = Rig(prior, recheck_s=60.0, learn=False)
        rig.cal.previous = TRUE
        rig.cal.applied = Params("EM3", m=-0.3, b_mps=0.1)
        rig.run(150)
        assert "fallback" in rig.kinds()
        assert rig.cal.applied == TRUE
        assert "previous calibration" in rig.cal.reason


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
        prior = Calibration("log", Params("EM3", b_mps=0.17), {"b": 0.01}, 0.0)
        rig = Rig(prior)
        assert rig.cal.correct(0.0) == 0.0
        assert rig.cal.correct(0.05) == pytest.approx(0.05)
