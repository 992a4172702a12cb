"""The supervisor's change detector: a CUSUM on the applied calibration's innovations.

:class:`ChangeDetector` watches what is emitted (the applied calibration, raw while it
passes through) for a step of the sensor or of the sea, and judges each alarm; the
supervisor (:mod:`emlogd.pipeline.supervisor`) acts on the judgement (:class:`Alarm`).

- **The innovation**: the error against the reference less what the detector's own
  current (fitted over :data:`CUSUM_HALF_LIFE_S` on the heading,
  :class:`~emlogd.pipeline.evidence.FitWindow`) predicts, over the window's spread
  widened by the current's uncertainty at the heading. A two-sided CUSUM
  (:class:`~emlogd.pipeline.evidence.Cusum`) on it alarms within a few samples of a step
  of the sensor or the sea. The baseline is judged on once it holds
  :data:`CUSUM_MIN_SAMPLES` (fewer at a slow cadence,
  :class:`~emlogd.pipeline.cadence.Cadence`) and spans
  :data:`~emlogd.pipeline.evidence.CUSUM_MIN_SPAN_S`; it learns only while the CUSUM
  stands at zero (a run's samples go to :attr:`ChangeDetector.run`). After the scored
  readings fell silent for more than :data:`~emlogd.pipeline.evidence.CUSUM_MAX_GAP_S`
  it starts afresh: its baseline is another sea's.
- **Holding**: an innovation beyond :data:`~emlogd.pipeline.evidence.HOLD_SIGMAS` where
  the log jumped and the reference did not (:class:`~emlogd.pipeline.evidence.Course`)
  holds the calibration (:attr:`ChangeDetector.held`): raw goes out until the run ends
  or its alarm is decided.
- **The judgement of an alarm**: the calibration's errors and raw's over the alarm's
  run, against the current as it stood. When the mean of the log's error shifted in the
  run beyond its standard error and the reference's mean did not
  (:class:`~emlogd.pipeline.evidence.Shift`; one noisy sample is no shift), the sensor
  shifted and the sea is as it was: the alarm is judged on the run of the side that
  alarmed alone, and the detector's current before the jump is handed on (the withdrawn
  calibration re-validates in it). Worse than raw, the calibration is to be withdrawn
  (:attr:`Alarm.withdraw`), unless the reference jumped and the log did not
  (:func:`~emlogd.pipeline.evidence.sea_jumped`: a tack, a tidal front; which of raw and
  the calibration fits the jumped sea is no evidence about the sensor). Otherwise the sea
  changed and the baseline starts again, from the alarm's run where an empty one takes
  longer than :data:`~emlogd.pipeline.cadence.CUSUM_MIN_FILL_S` to fill (at 0.2 Hz it
  absorbs a step within); with nothing applied, raw's alarm is the sea's alike.
  :attr:`Alarm.sea_jumped`: the reference jumped
  (:data:`~emlogd.pipeline.evidence.SEA_STEP_SIGMAS`), the learner's current re-opens.

This module must not import the supervisor, the learner or anything with I/O.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from calib.models import HeadingCS
from emlogd.pipeline.cadence import CUSUM_MIN_FILL_S, Cadence
from emlogd.pipeline.evidence import (
    CUSUM_MAX_GAP_S,
    CUSUM_MIN_SPAN_S,
    HOLD_SIGMAS,
    Course,
    Cusum,
    FitWindow,
    sea_jumped,
)

CUSUM_HALF_LIFE_S = 60.0
"""The change detector's own window, s: short, so that its current follows the sea's
(a current that turns over minutes would otherwise leave a bias in the innovations)."""

CUSUM_MIN_SAMPLES = 10.0
"""The CUSUM runs once its window holds this many (forgotten) samples of the applied
calibration (its own current and spread known; fewer at a slow cadence, :class:`Cadence`)
and spans :data:`~emlogd.pipeline.evidence.CUSUM_MIN_SPAN_S`. A run's samples stay out of
the window: a change is not absorbed by the baseline it is judged against."""

CUSUM_SIGMA_FLOOR_MPS = 0.02
"""The innovation's standard deviation is at least this, m/s (a window of quantised
readings at one speed has almost no spread)."""


class Alarm(NamedTuple):
    """The detector's judgement of one alarm (:meth:`ChangeDetector.step`)."""

    withdraw: bool
    """The applied calibration fits the alarm's run worse than raw, and the sea did not
    jump alone: it is to be withdrawn (the detector is then as it was at the alarm, for
    the owner to reset). Otherwise the detector has started again already."""
    sea_jumped: bool
    """The reference jumped (:func:`~emlogd.pipeline.evidence.sea_jumped`): the learner's
    current re-opens. False when the calibration is withdrawn."""
    detail: dict[str, object]
    """What the verdict rests on (the innovation, σ, both runs' squared errors, the
    shift), for the log line of a withdrawal; empty otherwise."""
    current_before: tuple[float, float] | None
    """The log jumped (its mean shifted) in the water frame: the detector's β before the
    jump (``error ≈ β·(cos ψ, sin ψ)``), the sea the withdrawn calibration re-validates
    in; None otherwise."""


class ChangeDetector:
    """The CUSUM on one UUT's emitted errors and its judgement of an alarm (module
    docstring).

    Args:
        water: the UUT learns a current (the detector fits one on the heading); else
            it fits a mean error.
    """

    def __init__(self, water: bool) -> None:
        self.water = water
        self.cusum = Cusum()
        self.baseline = FitWindow(1, water, CUSUM_HALF_LIFE_S)
        """The samples the innovations are judged against (learns while quiet)."""
        self.run = FitWindow(1, water, CUSUM_HALF_LIFE_S)
        """The CUSUM run's samples: the baseline after a sea's alarm where an empty one
        takes longer than CUSUM_MIN_FILL_S to fill (at 0.2 Hz it absorbs a step within)."""
        self.course = Course(CUSUM_HALF_LIFE_S)
        self.cadence = Cadence()
        """The scored readings' cadence and the last one's time."""
        self.held = False
        """Raw passes through until the CUSUM run decides (``HOLD_SIGMAS``)."""

    def step(
        self,
        t: float,
        cs: HeadingCS,
        e_app: float,
        e_raw: float,
        ref: float,
        applied: bool,
    ) -> Alarm | None:
        """One scored reading; the alarm's judgement when it raised one, else None.

        Args:
            t: the reading's time, s.
            cs: the heading's (cos, sin), or None.
            e_app: what is emitted's error against the reference, m/s (raw's while it
                passes through).
            e_raw: raw's error against the reference, m/s.
            ref: the reference, m/s.
            applied: a calibration is applied (else raw's alarm: nothing applied changed).
        """
        if t - self.cadence.t > CUSUM_MAX_GAP_S:
            self.reset()  # its baseline is another sea's
        self.cadence.add(t)
        w = self.baseline
        n_min = self.cadence.detector_weight(CUSUM_MIN_SAMPLES, CUSUM_HALF_LIFE_S)
        if w.n < n_min or w.t0 is None or t - w.t0 < CUSUM_MIN_SPAN_S:
            w.add(t, cs, (e_app,))
            return None
        sigma = max(w.rmse(0), CUSUM_SIGMA_FLOOR_MPS) * math.sqrt(1.0 + w.leverage(cs))
        pred = w.predict(0, cs)
        nu = e_app - pred
        cu = self.cusum
        alarm = cu.add(nu / sigma, nu, e_raw - pred)
        quiet = cu.hi == 0.0 and cu.lo == 0.0
        self.course.add(t, e_app + ref, ref, quiet)
        jump = abs(nu) >= HOLD_SIGMAS * sigma and self.course.log_jumped(*self.course.steps())
        self.held = not quiet and (self.held or jump)
        (w if quiet else self.run).add(t, cs, (e_app,))  # the baseline learns while quiet
        if quiet and self.run.n:
            self.run.reset()
        if not alarm:
            return None
        step_log, step_ref = self.course.steps()
        jumped = (shift := self.course.shift()).log_jumped  # the means shifted, not a spike
        sea = sea_jumped(step_log, step_ref, sigma)
        if not applied:
            self.reset(seed=True)  # raw's alarm: nothing applied changed
            return Alarm(False, sea, {}, None)
        # a log that jumped is judged on the run of the side that alarmed (after the
        # step); otherwise on the whole run, noise included
        n_app, n_raw = (cu.ss_app, cu.ss_raw) if jumped else (cu.run_app, cu.run_raw)
        # the reference jumped and the log did not: the sensor (whose parameters these
        # are) is as it was, and which of raw and it fits the jumped sea is no evidence
        if n_app <= n_raw or (sea and not jumped):
            self.reset(seed=True)
            return Alarm(False, sea, {}, None)
        detail: dict[str, object] = {
            "innovation_mps": round(nu, 4),
            "sigma_mps": round(sigma, 4),
            "ss_applied": round(n_app, 4),
            "ss_raw": round(n_raw, 4),
        }
        detail |= shift.detail(step_log, step_ref)
        before = w.beta(0) if self.water and jumped else None
        return Alarm(True, False, detail, before)

    def reset(self, seed: bool = False) -> None:
        """Start again (a calibration applied or withdrawn, a silence, a sea's alarm).

        Args:
            seed: the baseline starts from the alarm's run where ten readings take longer
                than :data:`~emlogd.pipeline.cadence.CUSUM_MIN_FILL_S` at the cadence.
        """
        self.held = False
        self.cusum.reset()
        self.baseline.reset()
        if seed and self.cadence.median_s * CUSUM_MIN_SAMPLES > CUSUM_MIN_FILL_S:
            self.baseline, self.run = self.run, self.baseline
        self.run.reset()
        self.course.reset()
