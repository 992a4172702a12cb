"""The supervisor of one UUT: what is applied to its readings, and why.

The learner (:mod:`emlogd.pipeline.learner`) only *offers* candidates; the supervisor
alone decides what reaches the autopilot. It sees the reading, the reference at the
reading's time, the heading and the learner's offer — through :class:`CandidateSource`,
never the learner's state — and keeps three calibrations: the *applied* one (None:
the raw reading passes through), the *previous* good one, and the candidate under
validation.

- **Emitting** (:meth:`Supervisor.correct`) uses only the applied calibration, never
  waits for the reference, and is silent while the log has a fault
  (:class:`~emlogd.pipeline.integrity.UutHealth`).
- **Validation**: an offer different enough from the applied calibration
  (``persist_min_change_sigma`` / ``persist_min_change_abs``) becomes a candidate,
  frozen and scored over the next ``validation_s`` (at least
  :data:`VALIDATION_MIN_SAMPLES`); it is applied only if it beats both the raw reading
  and the applied calibration there.
- **Re-check**: the applied calibration is scored against raw over a forgetting window
  of ``recheck_s`` (:class:`~emlogd.pipeline.integrity.PairedWindow`); once worse than
  raw (:data:`WORSE_FACTOR`, :data:`WORSE_MARGIN_MPS`) it falls back to the previous
  good one if that beats raw, else to raw pass-through, and says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from calib.models import Layout, Params
from emlogd.pipeline.counters import Counters, Score
from emlogd.pipeline.integrity import PairedWindow, UutHealth, emitted_speed

if TYPE_CHECKING:
    from emlogd.pipeline.learner import Offer
    from emlogd.pipeline.settings import UutSettings

VALIDATION_MIN_SAMPLES = 20
"""A candidate needs at least this many scored samples in its validation window."""

RECHECK_MIN_SAMPLES = 60.0
"""The applied calibration is judged once its re-check window holds this many."""

WORSE_FACTOR = 1.05
WORSE_MARGIN_MPS = 0.005
"""The applied calibration is worse than raw when its RMSE exceeds raw's × 1.05 + 5 mm/s."""

CANDIDATE_FACTOR = 1.02
CANDIDATE_MARGIN_MPS = 0.002
"""A candidate replaces the applied calibration when it beats raw and its RMSE is within
the applied one's × 1.02 + 2 mm/s."""


class CandidateSource(Protocol):
    """What the supervisor may ask of the learner: an offer, and its uncertainty now."""

    def offer(self) -> Offer | None:
        """The learner's estimate as a candidate, or None when it has none to offer."""

    @property
    def param_std(self) -> Mapping[str, float]:
        """The standard deviation of each parameter now."""


@dataclass
class _Candidate:
    params: Params
    t0: float
    raw: float = 0.0
    cand: float = 0.0
    applied: float = 0.0
    n: int = 0


class Supervisor:
    """What is applied to one UUT's readings (see the module docstring).

    Args:
        s: the UUT's settings.
        layout: the UUT's model layout.
        applied: the restored calibration to apply from the start, or None.
        applied_std: its standard deviations.
        emit: called as ``emit(t, kind, detail)`` for every decision worth a log line.
        counters: the UUT's counters (shared with its learner).
    """

    def __init__(
        self,
        s: UutSettings,
        layout: Layout,
        applied: Params | None,
        applied_std: Mapping[str, float | None],
        emit: Callable[[float, str, Mapping[str, object]], None],
        counters: Counters,
    ) -> None:
        self.s = s
        self.layout = layout
        self._emit = emit
        self.counters = counters
        self.applied: Params | None = applied
        self.applied_std: dict[str, float | None] = dict(applied_std)
        self.previous: Params | None = None
        self.candidate: _Candidate | None = None
        self.recheck = PairedWindow(s.recheck_s)
        self.health = UutHealth(s.stuck_s, s.zero_s)
        self.score = Score()
        self.score_water = Score()
        self.dirty = False
        """The applied calibration changed since it was last handed out for persisting."""
        self.note = ""
        """The last supervision decision worth showing with the state (a fallback)."""

    # -- emitting -------------------------------------------------------------

    def correct(self, raw_mps: float) -> float | None:
        """The speed to send for a reading: applied calibration, or raw; None when silent.

        Silent while the UUT has a fault (a stuck or dead log is not a measurement).
        """
        if self.health.fault:
            return None
        p = self.applied if self.s.apply else None
        corrected = raw_mps if p is None else p.correct(raw_mps)
        out = emitted_speed(corrected, raw_mps, self.s.low_speed_mps, self.s.envelope.max_speed_mps)
        return out if math.isfinite(out) else None

    def output_std(self, speed_mps: float) -> float:
        """The standard deviation of a speed :meth:`correct` gave, m/s.

        The reading's noise through the scale, plus the applied calibration's own σ at
        that speed; raw passed through (no calibration yet) counts with 10 % + 0.1 m/s.
        """
        r_raw = self.s.kf.r_raw_mps2
        p = self.applied if self.s.apply else None
        if p is None:
            return math.sqrt(r_raw + (0.1 * speed_mps) ** 2 + 0.01)
        std = self.applied_std
        u = abs(speed_mps)
        gain = p.a_spm * 2.0 * u + 1.0 + p.m
        var = r_raw / max(gain * gain, 0.25)
        for name, x in (("a", u * u), ("m", u), ("b", 1.0)):
            sd = std.get(name)
            if sd is not None and math.isfinite(sd):
                var += (sd * x) ** 2 / max(gain * gain, 0.25)
        return math.sqrt(var)

    # -- supervision ----------------------------------------------------------

    @staticmethod
    def _error(raw: float, ref: float, proj: float, p: Params | None) -> float:
        corrected = raw if p is None else p.correct(raw)
        return corrected + proj - ref

    def observe(
        self,
        t: float,
        raw: float,
        ref: float,
        proj: float,
        water: bool,
        source: CandidateSource,
    ) -> None:
        """Score one reading with a valid reference; validate, re-check, propose.

        Args:
            t: the reading's time, s.
            raw: the reading, m/s.
            ref: the reference along the hull at the reading's time, m/s.
            proj: the current projected on the hull, m/s (0 without one).
            water: the current is determined (the water-frame status score counts).
            source: the learner, for its offer.
        """
        e_raw = self._error(raw, ref, proj, None)
        e_app = self._error(raw, ref, proj, self.applied)
        out = self.correct(raw)
        if out is not None:
            self.score.add(raw - ref, out - ref)
            if water:
                self.score_water.add(raw + proj - ref, out + proj - ref)
        e_prev = self._error(raw, ref, proj, self.previous) if self.previous is not None else 0.0
        self.recheck.add(t, e_raw, e_app, e_prev)
        cand = self.candidate
        if cand is not None:
            cand.raw += e_raw * e_raw
            cand.applied += e_app * e_app
            e_c = self._error(raw, ref, proj, cand.params)
            cand.cand += e_c * e_c
            cand.n += 1
            if t - cand.t0 >= self.s.validation_s and cand.n >= VALIDATION_MIN_SAMPLES:
                self._decide(t, cand, source)
        else:
            self._propose(t, source)
        self._recheck(t)

    def _propose(self, t: float, source: CandidateSource) -> None:
        """Freeze the learner's offer as a candidate when it is new enough."""
        offer = source.offer()
        if offer is None:
            return
        if self.applied is not None and not self._significant(
            self.applied, offer.params, offer.param_std
        ):
            return
        self.candidate = _Candidate(offer.params, t)

    def _significant(self, old: Params, new: Params, std: Mapping[str, float]) -> bool:
        sigmas, floor = self.s.persist_min_change_sigma, self.s.persist_min_change_abs
        return any(
            abs(y - x) > max(sigmas * std[k], floor)
            for k, x, y in zip(self.layout.params, old.theta, new.theta, strict=True)
        )

    def _decide(self, t: float, cand: _Candidate, source: CandidateSource) -> None:
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
        }
        if r_cand < r_raw and r_cand <= r_app * CANDIDATE_FACTOR + CANDIDATE_MARGIN_MPS:
            if self.applied is None:
                self._emit(t, "calibrated", detail)
            else:
                self._emit(t, "calibration_updated", detail)
            self.previous = self.applied
            self.note = ""
            self.applied = cand.params
            self.applied_std = dict(source.param_std)
            self.recheck.reset()
            self.counters.candidates_applied += 1
            self.dirty = True
        else:
            self.counters.candidates_rejected += 1
            self._emit(t, "candidate_rejected", detail)

    def _recheck(self, t: float) -> None:
        if self.applied is None or self.recheck.n_effective < RECHECK_MIN_SAMPLES:
            return
        r_raw, r_app, r_prev = self.recheck.rmse()
        if not r_app > r_raw * WORSE_FACTOR + WORSE_MARGIN_MPS:
            return
        detail: dict[str, object] = {
            "rmse_applied": round(r_app, 4),
            "rmse_raw": round(r_raw, 4),
            "window_s": self.s.recheck_s,
        }
        prev = self.previous
        if prev is not None and r_prev < r_raw:
            self.applied = prev
            self.note = (
                f"fell back to the previous calibration: the applied one was worse than raw "
                f"over {self.s.recheck_s:g} s ({r_app:.3f} vs {r_raw:.3f} m/s)"
            )
            detail["to"] = "previous"
        else:
            self.applied = None
            self.note = (
                f"fell back to raw: the calibration was worse than raw over "
                f"{self.s.recheck_s:g} s ({r_app:.3f} vs {r_raw:.3f} m/s)"
            )
            detail["to"] = "raw"
        self.previous = None
        self.recheck.reset()
        self.candidate = None
        self.counters.fallbacks += 1
        self.dirty = True
        self._emit(t, "fallback", detail)
