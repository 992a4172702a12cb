"""The supervisor of one UUT: what is applied to its readings, and why.

The learner (:mod:`emlogd.pipeline.learner`) only *offers* candidates; the supervisor
alone decides what reaches the autopilot. It sees the reading, the reference at the
reading's time, the heading and the learner's offer (through :class:`CandidateSource`)
— never the learner's current or its covariance. It keeps the *applied* calibration
(None: the raw reading passes through), the *previous* one, the *last good* one and a
candidate under validation.

**Its own evidence** (:class:`~emlogd.pipeline.evidence.SeaMemory`): in the water frame every calibration it
judges gets its own current, fitted by least squares on the heading's (cos, sin) from
its own errors over the last :data:`~emlogd.pipeline.evidence.CURRENT_HALF_LIFE_S`; a calibration is scored by
what that current cannot explain, and raw is scored in the sea as the applied
calibration sees it (its own current would take its offset on every straight leg). A
current therefore cannot make a bad calibration look good. Without current states the
reference is the judge as it is.

Rules (the constants are this module's and :mod:`~emlogd.pipeline.revalidation`'s):

- **Emitting** (:meth:`Supervisor.correct`) uses only the applied calibration, never
  waits for the reference, and is silent while the log has a fault
  (:class:`~emlogd.pipeline.integrity.UutHealth`). A reading whose reference is
  already in (a log that lags the reference) is judged before it is emitted; one whose
  innovation is beyond :data:`~emlogd.pipeline.evidence.HOLD_SIGMAS` holds the calibration: raw goes out until
  the change detector has decided.
- **Validation**: an offer different enough from the applied calibration
  (``persist_min_change_sigma`` / ``persist_min_change_abs``) becomes a candidate,
  frozen and scored over the next ``validation_s`` (at least
  :data:`VALIDATION_MIN_SAMPLES`); it is applied only if raw is worse than it by the
  margin the re-check withdraws on (:func:`worse` the other way round: a gain within
  it is no evidence) and it is within :data:`CANDIDATE_FACTOR` /
  :data:`CANDIDATE_MARGIN_MPS` of the applied one. In the water frame raw must be
  worse than it both after a current of each one's own and in one sea for both
  (:func:`~emlogd.pipeline.revalidation.common_current`: a current fitted with a free
  correction of the reading, which neither can fit to its own offset; scored only at
  headings along which the memory determines it,
  :meth:`~emlogd.pipeline.revalidation.CommonSea.along`).
- **Refuted by the memory** (:meth:`Supervisor._refuted`): a new candidate is refused,
  and at its verdict the applied calibration withdrawn for cause, when the sea memory
  tells raw from it whatever the current and raw is the better one
  (:class:`~emlogd.pipeline.separation.Separation`, ``w`` below ½ by
  :data:`~emlogd.pipeline.separation.SEPARATION_SIGMAS`). On two headings either side
  of a current, a current of its own, and the common sea, can each take a wrong offset;
  the changes of speed and the turns, which no current makes, cannot.
- **Re-check**: the applied calibration is scored against raw over a forgetting
  window of ``recheck_s`` (:class:`~emlogd.pipeline.integrity.PairedWindow`); once worse than raw (:data:`WORSE_FACTOR`,
  :data:`WORSE_MARGIN_MPS`) it falls back to the previous one if that beats raw,
  else to raw pass-through.
- **Change detection** (:class:`~emlogd.pipeline.detector.ChangeDetector`, whose
  docstring gives its rules): a CUSUM on the applied calibration's innovations alarms
  within a few samples of a step of the sensor or the sea, and judges the alarm
  (:class:`~emlogd.pipeline.detector.Alarm`). Worse than raw, the calibration is
  withdrawn and the learner learns the parameters again; when the log's mean shifted
  (the sensor changed, the sea is as it was) the withdrawn calibration re-validates,
  raw and it alike, in the current the detector had before the jump. Else the sea
  changed; when the reference jumped the learner's current re-opens (raw passing
  through or not), so that the jump goes into the current, not into the parameters.
- **Drift** (:class:`~emlogd.pipeline.evidence.Drift`): a log that drifts against a
  steady reference on a straight leg for :data:`~emlogd.pipeline.evidence.DRIFT_CONFIRM_S`
  withdraws the applied calibration, and nothing is applied while it drifts.
- **Withdrawn for cause** (re-check, drift, change detection): it stays the *last good*
  one (persisted, not a reset) and is the next candidate from :data:`RESTORE_VALIDATION_S`
  on: withdrawn when the log jumped, re-applied when not worse than raw in the sea before
  the jump; else when raw is worse by the margin in both seas, or on what no current
  explains (refused only so: :func:`~emlogd.pipeline.revalidation.judge_withdrawn`).
  Refused, it is no new candidate either until the learner's offer differs from it as
  much as an offer must differ from an applied one (``persist_min_change_sigma`` /
  ``persist_min_change_abs``), or until the headings since have spread
  :data:`RESTORE_MIN_HEADING_SPREAD`: on one heading the offset is not determined (the
  current takes it) and the offer stays where the withdrawal found it while the log's
  offset drifts; after a turn the offer is evidence the refusal did not weigh.
- **Restored** (state file, warm start): validated before it is applied (over
  :data:`RESTORE_VALIDATION_S`, not worse than raw; in a turn after currents fitted to
  the window; on a straight leg it keeps the verdict that made it unless, in the sea it
  was saved in and against raw, the current its errors imply is one the sea cannot
  have and raw's a likelier, :data:`RESTORE_SEA_SIGMAS`; refused so, judged again every
  :data:`RESTORE_RETRY_S`), raw passing through meanwhile; saved with its sea
  and raw worse than it there over its first :data:`RESTORE_EARLY_SAMPLES`, or on a
  straight leg kept by that leg's verdict on them already, it is applied then and
  validated in place (withdrawn when that fails); when no reference
  has been heard :data:`RESTORE_WAIT_S` after the first reading, applied *unverified*
  (said in the status) and validated in place once a reference arrives.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from calib.models import HeadingCS, Layout, Params
from emlogd.pipeline.cadence import VALIDATION_MIN_SAMPLES as VALIDATION_MIN_SAMPLES
from emlogd.pipeline.counters import Counters, Score
from emlogd.pipeline.detector import ChangeDetector
from emlogd.pipeline.evidence import Drift, SeaMemory
from emlogd.pipeline.integrity import PairedWindow, UutHealth, emitted_speed, output_std
from emlogd.pipeline.revalidation import (
    COMMON_SEA_DEGREE,
    UNDETERMINED_SEA,
    beats_raw,
    common_current,
    judge_early,
    judge_restored,
    judge_saved_sea,
    judge_withdrawn,
    worse,
)
from emlogd.pipeline.revalidation import RESTORE_EARLY_SAMPLES as RESTORE_EARLY_SAMPLES
from emlogd.pipeline.revalidation import RESTORE_MIN_HEADING_SPREAD as RESTORE_MIN_HEADING_SPREAD
from emlogd.pipeline.revalidation import RESTORE_RETRY_S as RESTORE_RETRY_S
from emlogd.pipeline.revalidation import RESTORE_SEA_MAX_AGE_S as RESTORE_SEA_MAX_AGE_S
from emlogd.pipeline.revalidation import RESTORE_SEA_SIGMAS as RESTORE_SEA_SIGMAS
from emlogd.pipeline.revalidation import RESTORE_VALIDATION_S as RESTORE_VALIDATION_S
from emlogd.pipeline.revalidation import RESTORE_WAIT_S as RESTORE_WAIT_S
from emlogd.pipeline.revalidation import WORSE_FACTOR as WORSE_FACTOR
from emlogd.pipeline.revalidation import WORSE_MARGIN_MPS as WORSE_MARGIN_MPS
from emlogd.pipeline.revalidation import Candidate as Candidate
from emlogd.pipeline.revalidation import CandidateKind as CandidateKind
from emlogd.pipeline.revalidation import CandidateSource as CandidateSource
from emlogd.pipeline.separation import Separation

if TYPE_CHECKING:
    from emlogd.pipeline.settings import UutSettings

CANDIDATE_FACTOR = 1.02
CANDIDATE_MARGIN_MPS = 0.002
"""A candidate replaces the applied calibration when it beats raw and its RMSE is within
the applied one's × 1.02 + 2 mm/s."""

CURRENT_REFRESH_S = 20.0
"""Each calibration's current is fitted again this often, s (and when one is made; on
every sample for this long after a silence, :meth:`SeaMemory.renew`)."""


class Supervisor:
    """What is applied to one UUT's readings (see the module docstring).

    Args:
        s: the UUT's settings.
        layout: the UUT's model layout.
        restored: the restored calibration (re-earns trust before it is applied), or None.
        restored_std: its standard deviations.
        emit: called as ``emit(t, kind, detail)`` for every decision worth a log line.
        counters: the UUT's counters (shared with its learner).
        restored_sea: the restored calibration's saved current and its time, if any.
        restored_sea_std: that current's standard deviations, if any.
    """

    def __init__(
        self,
        s: UutSettings,
        layout: Layout,
        restored: Params | None,
        restored_std: Mapping[str, float | None],
        emit: Callable[[float, str, Mapping[str, object]], None],
        counters: Counters,
        restored_sea: tuple[float, float, float] | None = None,
        restored_sea_std: tuple[float, float] | None = None,
    ) -> None:
        self.s = s
        self.restored_sea = restored_sea
        """The restored calibration's saved current (north, east, m/s) and when it was
        saved (s), or None: the sea it re-validates in (:data:`RESTORE_SEA_MAX_AGE_S`)."""
        self.restored_sea_std = restored_sea_std
        """That current's saved standard deviations (north, east, m/s), if any."""
        self.layout = layout
        self._emit = emit
        self.counters = counters
        self.water = layout.current
        self.applied: Params | None = None
        self.applied_std: dict[str, float | None] = {}
        self.previous: Params | None = None
        self.last_good: Params | None = restored
        """The calibration last applied for good reason: kept (and persisted) when it is
        withdrawn for cause, until another is applied."""
        self.last_good_std: dict[str, float | None] = dict(restored_std)
        self.candidate: Candidate | None = (
            Candidate(restored, math.nan, "restored", dict(restored_std))
            if restored is not None
            else None
        )
        self.unverified = False
        """The applied calibration is a restored one no reference has confirmed yet."""
        self.refused: Params | None = None
        """A calibration withdrawn for cause whose re-validation refused it, until another
        is applied or the headings since turn (:meth:`_turned_since_refusal`): an offer
        within its σ of it is not a new candidate."""
        self.since_refused = [0.0, 0.0, 0.0]
        """The readings since the refusal and their headings' summed (cos, sin)."""
        self.retry: tuple[Candidate, float] | None = None
        """A restored calibration refused on a straight leg, and when
        (:data:`RESTORE_RETRY_S`)."""
        self.t_first: float | None = None
        self.heard_reference = False
        self.recheck = PairedWindow(s.recheck_s)
        self.memory = SeaMemory()
        self._beta: dict[str, tuple[float, float]] = {}
        self._common = UNDETERMINED_SEA
        self._t_beta = -math.inf
        self.change = ChangeDetector(self.water)
        """The change detector (its cadence is the scored readings')."""
        self.drift = Drift()
        self.sea_changed = False
        """The reference jumped: the learner's current re-opens (taken by the owner)."""
        self.reopen = False
        """Change detected: the learner should learn the parameters again (taken by the owner)."""
        self.health = UutHealth(s.stuck_s, s.zero_s)
        self.score = Score()
        self.score_water = Score()
        self.dirty = False
        """The applied calibration changed since it was last handed out for persisting."""
        self.note = (
            "restored calibration awaiting validation: raw readings pass through"
            if restored is not None
            else ""
        )
        """The last supervision decision worth showing with the state (a fallback)."""

    @property
    def held(self) -> bool:
        """Raw passes through until the change detector's run decides
        (:attr:`~emlogd.pipeline.detector.ChangeDetector.held`)."""
        return self.change.held

    @property
    def kept(self) -> Params | None:
        """What a snapshot persists: the applied calibration, else the last good one."""
        return self.applied if self.applied is not None else self.last_good

    @property
    def kept_std(self) -> dict[str, float | None]:
        """Its standard deviations."""
        return self.applied_std if self.applied is not None else self.last_good_std

    # -- emitting -------------------------------------------------------------

    def correct(self, raw_mps: float) -> float | None:
        """The speed to send for a reading: applied calibration, or raw; None when silent.

        Silent while the UUT has a fault (a stuck or dead log is not a measurement);
        raw while the applied calibration is held (:data:`~emlogd.pipeline.evidence.HOLD_SIGMAS`).
        """
        if self.health.fault:
            return None
        p = self.applied if self.s.apply and not self.held else None
        corrected = raw_mps if p is None else p.correct(raw_mps)
        out = emitted_speed(corrected, raw_mps, self.s.low_speed_mps, self.s.envelope.max_speed_mps)
        return out if math.isfinite(out) else None

    def output_std(self, speed_mps: float) -> float:
        """The standard deviation of a speed :meth:`correct` gave, m/s (:func:`output_std`)."""
        p = self.applied if self.s.apply else None
        return output_std(p, self.applied_std, self.s.kf.r_raw_mps2, speed_mps)

    # -- supervision ----------------------------------------------------------

    def reading(self, t: float, reference_heard: bool) -> None:
        """Every reading learnt from: a restored calibration waits for a reference.

        Args:
            t: the reading's time, s.
            reference_heard: the reference is reporting (valid or not, slow or lost).
        """
        if self.t_first is None:
            self.t_first = t
            sea = self.restored_sea
            if sea is not None and not 0.0 <= t - sea[2] <= RESTORE_SEA_MAX_AGE_S:
                self.restored_sea = None
        if reference_heard:
            self.heard_reference = True
            return
        cand = self.candidate
        if (
            cand is not None
            and cand.kind == "restored"
            and not self.heard_reference
            and t - self.t_first >= RESTORE_WAIT_S
        ):
            self.candidate = Candidate(cand.params, math.nan, "verify", cand.std)
            self._apply(t, cand.params, cand.std or {})
            self.unverified = True
            self.note = "restored calibration unverified: no reference"
            self._emit(t, "calibration_unverified", {"params": cand.params.as_dict()})

    @staticmethod
    def _error(raw: float, ref: float, p: Params | None) -> float:
        corrected = raw if p is None else p.correct(raw)
        return corrected - ref

    def observe(
        self,
        t: float,
        raw: float,
        ref: float,
        cs: HeadingCS,
        source: CandidateSource,
        *,
        proj: float = 0.0,
        water: bool = False,
    ) -> None:
        """Score one reading with a valid reference; detect, validate, re-check, propose.

        Args:
            t: the reading's time, s.
            raw: the reading, m/s.
            ref: the reference along the hull at the reading's time, m/s.
            cs: the heading's (cos, sin) at that time, or None.
            source: the learner, for its offer.
            proj: the learner's current on the hull, m/s: the status's water-frame score
                only (never a verdict).
            water: the learner's current is determined (that score counts).
        """
        d_raw = self._error(raw, ref, None)
        d_app = self._error(raw, ref, self.applied)
        self._score_output(raw, ref, proj, water)
        self.drift.add(t, raw, ref, cs if self.water else None, self.applied)
        if self.drift.sustained and self.applied is not None:
            why = {"params": self.applied.as_dict(), "drift_mps": round(self.drift.change_mps, 4)}
            self.withdraw(t, "the log drifts against a steady reference", why)
            self.reopen = True
            d_app = d_raw
        elif self._detect(t, cs, d_app, d_raw, ref):
            d_app = d_raw
        hc = self._heading_regressor(t, cs)
        # raw is judged in the sea as the applied calibration sees it (else its own
        # current would take its offset on every straight leg and raw would look right)
        sea = "applied" if self.applied is not None else "raw"
        e_raw = self._residual(d_raw, sea, hc)
        e_app = self._residual(d_app, sea, hc)
        e_prev = 0.0
        if self.previous is not None:
            e_prev = self._residual(self._error(raw, ref, self.previous), "previous", hc)
        self.recheck.add(t, e_raw, e_app, e_prev)
        cand = self.candidate
        if cand is not None:
            self._validate(t, cand, raw, ref, cs, hc, (d_raw, e_raw, e_app))
            if self._validated(t, cand):
                self._decide(t, cand, source)
        else:
            self._propose(t, source)
        if self.water and cs is not None:
            self.memory.add(t, raw, ref, cs)
        if self.refused is not None and cs is not None and self._turned_since_refusal(cs):
            self.refused = None
        self._recheck(t)

    def _score_output(self, raw: float, ref: float, proj: float, water: bool) -> None:
        """The status's scores of what was emitted (against the reference, and in the
        learner's water frame while its current is determined): never a verdict."""
        out = self.correct(raw)
        if out is None:
            return
        self.score.add(raw - ref, out - ref, ref)
        if water:
            self.score_water.add(raw + proj - ref, out + proj - ref)

    def _heading_regressor(self, t: float, cs: HeadingCS) -> tuple[float, float]:
        """The heading's (cos, sin) the currents act through (zero without current
        states); each calibration's current is fitted again when due (:meth:`SeaMemory.renew`)."""
        if not (self.water and cs is not None):
            return 0.0, 0.0
        if self.memory.renew(t, CURRENT_REFRESH_S) or t - self._t_beta >= CURRENT_REFRESH_S:
            self._refit(t)
        return cs

    def _validate(
        self,
        t: float,
        cand: Candidate,
        raw: float,
        ref: float,
        cs: HeadingCS,
        hc: tuple[float, float],
        errors: tuple[float, float, float],
    ) -> None:
        """Score the candidate under validation, raw and the applied one on one reading.

        ``errors`` are raw's error against the reference, and raw's and the applied
        calibration's residuals after their current.
        """
        d_raw, e_raw, e_app = errors
        if cand.n == 0:
            cand.t0 = t
        if cand.beta is None and self.water:
            cand.beta = self.memory.current(cand.params, t)
        beta = cand.beta or (0.0, 0.0)
        d_c = self._error(raw, ref, cand.params)
        e_c = d_c - (beta[0] * hc[0] + beta[1] * hc[1])
        cand.separate(t, d_raw, ref, cs)
        common = self._common if self._beta else None  # fitted with the others
        if cand.kind in ("new", "revalidate") and not cand.sea_fixed and common is not None:
            cand.score_common(d_raw, d_c, common.along(hc))  # one sea neither was fitted to
        if cand.sea_fixed:
            e_raw = d_raw - (beta[0] * hc[0] + beta[1] * hc[1])  # raw in that sea too
        sea = self.restored_sea
        if cand.kind == "restored" and cs is not None and sea is not None:
            c_h = sea[0] * cs[0] + sea[1] * cs[1]
            cand.sea_raw += (d_raw + c_h) ** 2
            cand.sea_cand += (d_c + c_h) ** 2
            cand.n_sea += 1
        if cand.kind == "restored" and self.water and cs is not None:
            if cand.samples is None:
                cand.samples = []
            cand.samples.append((d_raw, d_c, cs[0], cs[1]))
        cand.raw += e_raw * e_raw
        cand.applied += e_app * e_app
        cand.cand += e_c * e_c
        cand.n += 1
        if cand.kind == "restored" and cand.n == RESTORE_EARLY_SAMPLES:
            self._early(t, cand)

    def _early(self, t: float, cand: Candidate) -> None:
        """Apply a restored calibration on its first samples (:func:`judge_early`)."""
        detail: dict[str, object] = {"params": cand.params.as_dict()}
        sea, sea_std = self.restored_sea, self.restored_sea_std
        if self.applied is not None or not judge_early(cand, detail, self.s.kf, sea, sea_std):
            return
        cand.early = True
        self._apply(t, cand.params, cand.std or {})
        self.note = "restored calibration applied on its first samples: validating"
        self._emit(t, "calibrated", detail | {"samples": cand.n, "kind": "restored-early"})

    def _validated(self, t: float, cand: Candidate) -> bool:
        """The candidate's validation window is complete (``validation_s``, or
        :data:`RESTORE_VALIDATION_S` for one validated before)."""
        v = self.s.validation_s
        span = v if cand.kind == "new" else min(RESTORE_VALIDATION_S, v)
        done = t - cand.t0 >= span and cand.n >= self.change.cadence.validation_count()
        final = t - cand.t0 >= v  # a withdrawn one: until told from raw
        return done and (cand.separation is None or judge_withdrawn(cand, {}, final) is not None)

    def _refit(self, t: float) -> None:
        """Each calibration's own current from the memory (:data:`~emlogd.pipeline.evidence.CURRENT_HALF_LIFE_S`)."""
        mem = self.memory
        self._beta = {"raw": mem.current(None, t)}
        self._common = common_current(mem, t, COMMON_SEA_DEGREE)
        if self.applied is not None:
            self._beta["applied"] = mem.current(self.applied, t)
        if self.previous is not None:
            self._beta["previous"] = mem.current(self.previous, t)
        cand = self.candidate
        if cand is not None and cand.n and not cand.sea_fixed:
            cand.beta = mem.current(cand.params, t)
        self._t_beta = t

    def _residual(self, d: float, slot: str, hc: tuple[float, float]) -> float:
        b = self._beta.get(slot)
        return d if b is None else d - (b[0] * hc[0] + b[1] * hc[1])

    def _detect(self, t: float, cs: HeadingCS, e_app: float, e_raw: float, ref: float) -> bool:
        """Change detection on what is emitted (raw while it passes through,
        :class:`~emlogd.pipeline.detector.ChangeDetector`); True when the calibration was
        withdrawn. An alarm that withdraws nothing is the sea's: :attr:`sea_changed` when
        the reference jumped."""
        alarm = self.change.step(t, cs, e_app, e_raw, ref, self.applied is not None)
        if alarm is None:
            return False
        if not alarm.withdraw:
            if self.applied is not None:
                self._t_beta = -math.inf  # the sea changed: the currents are fitted anew
            self.sea_changed = alarm.sea_jumped
            return False
        assert self.applied is not None
        detail: dict[str, object] = {"params": self.applied.as_dict()} | alarm.detail
        beta = alarm.current_before
        self.withdraw(
            t, "the readings changed and the calibration fits them worse than raw", detail
        )
        if self.candidate is not None and beta is not None:
            # the log jumped and the reference did not: the sensor changed and the sea
            # is as it was, so the calibration re-validates in that sea (raw and it
            # alike), and comes back once the sensor does
            self.candidate.in_sea_before(beta)
        elif self.candidate is not None:  # the same sensor: the speeds and turns before it
            self.candidate.recall(self.memory, t)
        self.memory = SeaMemory()  # what it held was the sensor before the change
        self._beta = {}
        self.reopen = True
        self.counters.changes += 1
        return True

    def withdraw(self, t: float, why: str, detail: dict[str, object]) -> None:
        """To raw for cause: the applied calibration stays the last good one and is the
        next candidate (re-applied once it validates again)."""
        p = self.applied
        assert p is not None
        std = dict(self.applied_std)
        self.applied = None
        self.applied_std = {}
        self.unverified = False
        self.previous = None
        self.recheck.reset()
        self._reset_detector()
        self.candidate = Candidate.withdrawn(p, std, self.water)
        self.note = f"fell back to raw: {why}"
        self.counters.fallbacks += 1
        self.dirty = True
        self._emit(t, "fallback", detail | {"to": "raw", "why": why})

    def _propose(self, t: float, source: CandidateSource) -> None:
        """Freeze the learner's offer as a candidate when it is new enough."""
        offer = source.offer()
        if offer is None:
            if self.retry is not None and self.applied is None:
                old, t_refused = self.retry
                if t - t_refused >= RESTORE_RETRY_S:
                    self.retry = None
                    self.candidate = Candidate(old.params, math.nan, "restored", old.std)
            return
        base = self.applied if self.applied is not None else self.refused
        if base is not None and not self._significant(base, offer.params, offer.param_std):
            return
        self.candidate = Candidate(offer.params, t)

    def _turned_since_refusal(self, cs: tuple[float, float]) -> bool:
        """The headings since the refusal spread :data:`RESTORE_MIN_HEADING_SPREAD` over
        at least :data:`VALIDATION_MIN_SAMPLES` readings: the offset and a current are told
        apart again, and what the learner offers then is evidence the refusal did not
        weigh. On one heading the offset is not determined (the current takes it) and
        the learner's offer stays where the withdrawal found it."""
        n = self.since_refused
        n[0] += 1.0
        n[1] += cs[0]
        n[2] += cs[1]
        spread = 1.0 - math.hypot(n[1], n[2]) / n[0]
        return n[0] >= VALIDATION_MIN_SAMPLES and spread >= RESTORE_MIN_HEADING_SPREAD

    def _significant(self, old: Params, new: Params, std: Mapping[str, float]) -> bool:
        sigmas, floor = self.s.persist_min_change_sigma, self.s.persist_min_change_abs
        return any(
            abs(y - x) > max(sigmas * std[k], floor)
            for k, x, y in zip(self.layout.params, old.theta, new.theta, strict=True)
        )

    def _decide(self, t: float, cand: Candidate, source: CandidateSource) -> None:
        self.candidate = None
        n = cand.n
        r_raw, r_cand = math.sqrt(cand.raw / n), math.sqrt(cand.cand / n)
        r_app = math.sqrt(cand.applied / n) if self.applied is not None else r_raw
        detail = {
            "params": cand.params.as_dict(),
            "rmse_raw": round(r_raw, 4),
            "rmse_candidate": round(r_cand, 4),
            "rmse_applied": round(r_app, 4),
            "samples": n,
            "kind": cand.kind,
        }
        if cand.kind == "new":
            good = self._judge_new(t, cand, detail, r_raw, r_cand, r_app)
        elif cand.kind == "restored" and cand.samples is not None and len(cand.samples) == n:
            good = judge_restored(
                cand,
                detail,
                self.s.kf,
                self.restored_sea,
                self.restored_sea_std,
                cand.t0,
            )
            # refused by the sea's allowance, short of the whole (RESTORE_RETRY_S)
            allowance = detail.get("current_allowance_mps")
            cap = math.sqrt(self.s.kf.current_p0_m2ps2)
            if not good and isinstance(allowance, float) and allowance < cap:
                self.retry = (cand, t)
        elif cand.kind == "restored" and cand.n_sea == n:
            good = judge_saved_sea(cand, detail)
        elif cand.kind == "revalidate" and not cand.sea_fixed:
            good = judge_withdrawn(cand, detail) is True
        else:
            # restored, or withdrawn when the log jumped (judged in the sea before the
            # jump): it need only not be worse than raw
            good = not worse(r_cand, r_raw)
        if self.drift.on:  # a drifting log: whatever fitted it a moment ago will not
            good, detail["drifting"] = False, True
        if cand.kind == "verify" or cand.early:
            if good:
                self.unverified = False
                self.note = ""
                self._emit(t, "calibration_verified", detail)
            else:
                self.applied = None
                self.applied_std = {}
                self.unverified = False
                self.recheck.reset()
                self._reset_detector()
                self.note = "fell back to raw: the restored calibration failed its validation"
                self.counters.candidates_rejected += 1
                self.counters.fallbacks += 1
                self.dirty = True
                self._emit(t, "candidate_rejected", detail)
            return
        if good:
            self._emit(t, "calibrated" if self.applied is None else "calibration_updated", detail)
            self.previous = self.applied
            self.note = ""
            std = cand.std if cand.std is not None else dict(source.param_std)
            self._apply(t, cand.params, std)
            self.counters.candidates_applied += 1
        else:
            if cand.kind == "restored":
                self.note = "the restored calibration failed its validation: raw passes through"
            if cand.kind == "revalidate":
                self.refused = cand.params
                self.since_refused = [0.0, 0.0, 0.0]
            self.counters.candidates_rejected += 1
            self._emit(t, "candidate_rejected", detail)

    def _refuted(self, t: float, p: Params, detail: dict[str, object]) -> bool:
        """The sea memory tells raw from ``p`` whatever the current, and raw is the
        better one (:meth:`~emlogd.pipeline.separation.Separation.verdict` False; in the
        water frame only). A current of each one's own, and the common sea's, can take
        an offset where the headings do not tell a current from it (two headings either
        side of the current's direction); what no current can make, the changes of
        speed and the turns, decides here."""
        if not self.water:
            return False
        sep = Separation()
        sep.add_memory(self.memory, p, t)
        return sep.verdict(detail) is False

    def _judge_new(
        self,
        t: float,
        cand: Candidate,
        detail: dict[str, object],
        r_raw: float,
        r_cand: float,
        r_app: float,
    ) -> bool:
        """A new candidate's verdict: it beats raw (:func:`beats_raw`), is within
        :data:`CANDIDATE_FACTOR` of the applied calibration and is not refuted
        (:meth:`_refuted`). First the applied calibration faces the same memory: refuted,
        it is withdrawn for cause and the candidate, judged on that memory, goes with it."""
        applied = self.applied
        gone: dict[str, object] = {}
        if applied is not None and self._refuted(t, applied, gone):
            self.withdraw(t, "the sea memory tells raw from it, and raw is the better one", gone)
            return False
        return (
            beats_raw(cand, r_raw, r_cand, detail)
            and r_cand <= r_app * CANDIDATE_FACTOR + CANDIDATE_MARGIN_MPS
            and not self._refuted(t, cand.params, detail)
        )

    def _apply(self, t: float, p: Params, std: Mapping[str, float | None]) -> None:
        self.retry = None
        self.refused = None
        self.applied = p
        self.applied_std = dict(std)
        self.last_good = p
        self.last_good_std = dict(std)
        self.recheck.reset()
        self._reset_detector()
        self.dirty = True

    def _reset_detector(self) -> None:
        """The applied calibration changed: the currents are fitted anew and the change
        detector starts again."""
        self._t_beta = -math.inf
        self.change.reset()

    def _recheck(self, t: float) -> None:
        w = self.recheck
        if self.applied is None or w.n_effective < self.change.cadence.recheck_weight(
            w.half_life_s
        ):
            return
        r_raw, r_app, r_prev = w.rmse()
        if not worse(r_app, r_raw):
            return
        detail: dict[str, object] = {
            "rmse_applied": round(r_app, 4),
            "rmse_raw": round(r_raw, 4),
            "window_s": self.s.recheck_s,
        }
        prev = self.previous
        if prev is not None and r_prev < r_raw:
            self.applied = prev
            self.previous = None
            self.recheck.reset()
            self._reset_detector()
            self.candidate = None
            self.note = (
                f"fell back to the previous calibration: the applied one was worse than raw "
                f"over {self.s.recheck_s:g} s ({r_app:.3f} vs {r_raw:.3f} m/s)"
            )
            self.counters.fallbacks += 1
            self.dirty = True
            self._emit(t, "fallback", detail | {"to": "previous"})
            return
        self.withdraw(
            t,
            f"the calibration was worse than raw over {self.s.recheck_s:g} s "
            f"({r_app:.3f} vs {r_raw:.3f} m/s)",
            detail,
        )
