"""The calibration of one unit under test (UUT): align, learn, supervise, correct.

One :class:`UutCalibration` per EMlog, fed by :class:`emlogd.pipeline.core.Pipeline`
with the UUT's readings, its reference (already reduced to a speed along the hull)
and its heading. Nothing here reads a clock or does I/O; times are receive times.

It joins two parts with a narrow boundary:

- the **learner** (:class:`emlogd.pipeline.learner.Learner`): the lag, alignment,
  identifiability, the filter and block means — what the readings teach;
- the **supervisor** (:class:`emlogd.pipeline.supervisor.Supervisor`): what is
  applied — validation, re-check, change detection, fallback, the applied, previous
  and last good calibrations, the log's health. It sees readings, references,
  headings and the learner's offer.

**Emitting** (:meth:`UutCalibration.correct`) uses only the *applied* calibration:
the last one that beat the raw reading on data it had not learnt from, else the raw
reading itself (pass-through). It never waits for the reference, so the autopilot's
latency is the decoder's. **Learning** (:meth:`UutCalibration.learn`): a reading waits
in a short queue until its reference has arrived, then is aligned, checked for the
log's health, learnt from, and scored by the supervisor.

The supervisor's verdicts rest on its own evidence (each calibration's own current,
fitted from its own errors), never on the learner's current; the learner's current
only feeds the status's water-frame score and the VDR sentence.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Literal, Protocol

from calib.estimate import Estimate
from calib.excitation import Identifiability
from calib.kalman import Innovation, KfCalibrator
from calib.models import CURRENT, Layout, Params, check_model, zero_params
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.counters import Counters, Score
from emlogd.pipeline.integrity import PairedWindow, UutHealth
from emlogd.pipeline.lagcheck import LagCheck
from emlogd.pipeline.learner import AVERAGE_S, Aligned, BlockMeans, LagFinder, Learner, RefState
from emlogd.pipeline.supervisor import Candidate, Supervisor
from emlogd.pipeline.twoaxis_sup import Guard

if TYPE_CHECKING:
    from emlogd.pipeline.settings import UutSettings

__all__ = [
    "AVERAGE_S",
    "BlockMeans",
    "CalState",
    "Counters",
    "Recorder",
    "Score",
    "UutCalibration",
]

CalState = Literal["learning", "frozen", "uncalibrated", "fault"]


class Recorder(Protocol):
    """What the offline commands collect from a UUT: its inputs, exactly as learning sees them."""

    def reference(
        self, t: float, v_mps: float | None, valid: bool, heading_deg: float | None
    ) -> None:
        """One reference sample along the hull and the UUT's heading at its time."""

    def reading(self, t: float, raw_mps: float) -> None:
        """One reading of the learnt sentence (fresh, in range)."""


class UutCalibration:
    """The online calibration of one UUT (see the module docstring).

    Args:
        s: the UUT's settings (:class:`emlogd.pipeline.settings.UutSettings`).
        prior: a checked calibration to start from (warm start), or None.
        heading_at: returns the UUT's heading in degrees (true) at a time, or None.
        event: called as ``event(t, kind, detail)`` for every state change worth a log line.
        matched_noise: the learner's filter scaled to the innovations' covariance
            (:class:`emlogd.pipeline.learner.Learner`; offline ``calibrate``).
        reopen_on_change: a change the supervisor's detector saw re-opens the learner's
            parameters (:meth:`Learner.reopen_for_change`: what is offered next rests on
            readings after the change). False (offline ``calibrate``, one model over the
            recordings as least squares fits it): the supervisor still withdraws, the
            learner keeps what every reading taught.
        check_lag: a configured lag is checked against the data
            (:mod:`emlogd.pipeline.lagcheck`). False (offline ``calibrate``): its lag is
            the lag report's.
    """

    def __init__(
        self,
        s: UutSettings,
        prior: Calibration | None,
        heading_at: Callable[[float], float | None],
        event: Callable[[float, str, Mapping[str, object]], None],
        *,
        matched_noise: bool = False,
        reopen_on_change: bool = True,
        check_lag: bool = True,
    ) -> None:
        self.s = s
        self.reopen_on_change = reopen_on_change
        self.layout = Layout(check_model(s.model), s.current)
        self.heading_at = heading_at
        self._event = event
        usable = prior if prior is not None and not prior.reset else None
        if usable is not None and usable.params.model != s.model:
            usable = None
        self.counters = Counters()
        self.learner = Learner(
            s, self.layout, usable, self._emit, self.counters, matched_noise=matched_noise
        )
        self.sup = Supervisor(
            s,
            self.layout,
            usable.params if usable is not None else None,
            usable.param_std if usable is not None else {},
            self._emit,
            self.counters,
            restored_sea=(
                (*usable.current_mps, usable.t)
                if usable is not None and usable.current and usable.current_mps is not None
                else None
            ),
            restored_sea_std=usable.current_std_mps if usable is not None else None,
        )
        self.lagcheck = LagCheck(s.current, auto=s.lag_s is None) if check_lag else None
        """The lag in use checked against the data (:mod:`emlogd.pipeline.lagcheck`; with
        ``lag: auto`` only for a reference minutes off)."""
        self.lag_beyond = ""
        """With the lag checked: why the lag search says the log lags beyond ``max_lag_s``
        (:attr:`LagFinder.beyond`; nothing learnt or applied), or empty."""
        self.pending: deque[tuple[float, float]] = deque(maxlen=int((s.max_lag_s + 5.0) * 20) + 16)
        self.state: CalState = "uncalibrated"
        self.reason = (
            "restored calibration awaiting validation: raw readings pass through"
            if usable is not None
            else "no calibration yet: raw readings pass through"
        )
        self.freezes = 0
        self.t_persist = -math.inf
        self.recorder: Recorder | None = None
        """Offline use: receives every reference sample and reading as learning sees them."""
        self.record_only = False
        """With a recorder: only record the readings, learn nothing (reading captures)."""
        self.tracer: Callable[[dict[str, object]], None] | None = None
        """Offline use (``calibrate --trace``): receives one row per learnt-from reading."""

    def _emit(self, t: float, kind: str, detail: Mapping[str, object]) -> None:
        self._event(t, kind, detail)

    def _heading(self, t: float) -> float | None:
        return self.heading_at(t)

    # -- the learner's and supervisor's state, as the pipeline and tests read it --

    @property
    def kf(self) -> KfCalibrator:
        """The learner's filter."""
        return self.learner.kf

    @property
    def lag_s(self) -> float | None:
        """The lag in use, s (None while it is estimated)."""
        return self.learner.lag_s

    @lag_s.setter
    def lag_s(self, v: float | None) -> None:
        self.learner.lag_s = v

    @property
    def lag_finder(self) -> LagFinder | None:
        """The lag estimator while the lag is not final."""
        return self.learner.lag_finder

    @lag_finder.setter
    def lag_finder(self, v: LagFinder | None) -> None:
        self.learner.lag_finder = v

    @property
    def ref(self) -> SampleRing:
        """The reference samples along the hull."""
        return self.learner.ref

    @ref.setter
    def ref(self, v: SampleRing) -> None:
        self.learner.ref = v

    @property
    def ident(self) -> Identifiability | None:
        """The latest identifiability verdict."""
        return self.learner.ident

    @property
    def ref_state(self) -> RefState:
        """The reference's state at the latest reading."""
        return self.learner.ref_state

    @property
    def n_learnt(self) -> int:
        """Samples learnt from (restored calibration's included)."""
        return self.learner.n_learnt

    @property
    def nis(self) -> deque[float]:
        """The NIS of the last 300 learnt samples."""
        return self.learner.nis

    @property
    def t_prev(self) -> float | None:
        """The latest reading learnt from, s."""
        return self.learner.t_prev

    @property
    def learn_on(self) -> bool:
        """The operator's learning switch."""
        return self.learner.learn_on

    @learn_on.setter
    def learn_on(self, on: bool) -> None:
        self.learner.learn_on = on

    @property
    def applied(self) -> Params | None:
        """The applied calibration (None: raw passes through)."""
        return self.sup.applied

    @applied.setter
    def applied(self, p: Params | None) -> None:
        self.sup.applied = p

    @property
    def guard(self) -> Guard:
        """What a two-axis forward speed answers to of this supervisor."""
        sup = self.sup
        in_use = sup.applied if sup.s.apply and not sup.held else None
        return Guard(sup.counters.fallbacks, sup.held or bool(sup.health.fault), in_use)

    @property
    def applied_std(self) -> dict[str, float | None]:
        """The applied calibration's standard deviations."""
        return self.sup.applied_std

    @property
    def previous(self) -> Params | None:
        """The previous good calibration (a fallback's target), or None."""
        return self.sup.previous

    @previous.setter
    def previous(self, p: Params | None) -> None:
        self.sup.previous = p

    @property
    def candidate(self) -> Candidate | None:
        """The candidate under validation, or None."""
        return self.sup.candidate

    @candidate.setter
    def candidate(self, c: Candidate | None) -> None:
        self.sup.candidate = c

    @property
    def recheck(self) -> PairedWindow:
        """The applied calibration's re-check window."""
        return self.sup.recheck

    @property
    def health(self) -> UutHealth:
        """The log's own faults."""
        return self.sup.health

    @property
    def score(self) -> Score:
        """Emitted and raw errors against the reference."""
        return self.sup.score

    @property
    def score_water(self) -> Score:
        """The same in the water frame, while the current is determined."""
        return self.sup.score_water

    @property
    def dirty(self) -> bool:
        """The applied calibration changed since it was last handed out for persisting."""
        return self.sup.dirty

    @dirty.setter
    def dirty(self, d: bool) -> None:
        self.sup.dirty = d

    @property
    def note(self) -> str:
        """The last supervision decision worth showing with the state."""
        return self.sup.note

    # -- emitting -------------------------------------------------------------

    def correct(self, raw_mps: float) -> float | None:
        """The speed to send for a reading (:meth:`Supervisor.correct`); None when silent."""
        return self.sup.correct(raw_mps)

    def output_std(self, speed_mps: float) -> float:
        """The standard deviation of a speed :meth:`correct` gave, m/s."""
        return self.sup.output_std(speed_mps)

    def in_range(self, raw_mps: float) -> bool:
        """A reading the sensor can give: finite, within ``[0, max_speed]`` (sternway aside)."""
        return math.isfinite(raw_mps) and -1.0 <= raw_mps <= self.s.envelope.max_speed_mps

    # -- inputs -------------------------------------------------------------

    def add_reference(self, t: float, v_mps: float | None, valid: bool) -> None:
        """One reference sample along the hull (already filtered for glitches)."""
        if not self.learner.add_reference(t, v_mps, valid, self._heading):
            return
        if self.lagcheck is not None and valid and v_mps is not None:
            self.lagcheck.reference(t, v_mps, self._heading)
        if self.recorder is not None:
            self.recorder.reference(t, v_mps, valid, self.heading_at(t))

    def add_reading(self, t: float, raw_mps: float) -> None:
        """Queue one reading of the learnt sentence for learning (see :meth:`drain`)."""
        if self.recorder is not None:
            self.recorder.reading(t, raw_mps)
            if self.record_only:
                return
        self.pending.append((t, raw_mps))

    def drain(self, now: float, *, final: bool = False) -> None:
        """Learn from every queued reading whose reference has arrived (or never will).

        Args:
            now: the pipeline's latest record time, s.
            final: end of input: learn from everything queued.
        """
        ring = self.learner.ref
        while self.pending:
            t, raw = self.pending[0]
            lag = self.learner.lag_s
            if lag is not None and not final:
                target = t - lag
                waiting = not ring.covers(target)
                if waiting and now - target <= ring.gap_s + 1.0:
                    return
            self.pending.popleft()
            self.learn(t, raw)

    # -- one reading ----------------------------------------------------------

    def learn(self, t: float, raw: float) -> None:
        """Align, check the log's health, learn, supervise: one reading."""
        lr, sup = self.learner, self.sup
        lc = self.lagcheck
        if lc is not None and lc.reading(t, raw, lr.lag_s):
            self._lag_verdict(t, lc.why)
        beyond = lr.lag_finder.beyond if lr.lag_finder is not None and lc is not None else ""
        if beyond != self.lag_beyond:  # the lag search's own word on the fallback lag
            self.lag_beyond = beyond
            self._lag_verdict(t, beyond)
        a = lr.align(t, raw, self._heading)
        sup.reading(t, a.ref_state not in ("none", "stale"))
        ref_ok = a.ref if a.ref_state == "valid" else None
        fault = sup.health.update(t, raw, ref_ok, a.heading)
        gate = fault
        if fault:
            self.counters.uut_fault += 1
        elif sup.health.stalled(raw, ref_ok):
            self.counters.uut_stalled += 1
            gate = "uut_stalled"
        if (lc is not None and lc.contradicted) or beyond:
            gate = gate or "lag_contradicted"
        step = lr.step(a, gate, sup.applied)
        if step.valid and a.ref is not None and not gate:
            self._supervise(a)
        self._set_state(t, step.learnt or step.collecting, fault)
        if self.tracer is not None:
            ref = a.ref if step.valid else None
            self.tracer(self._trace_row(t, raw, ref, a.heading, step.innovation, step.learn_set))

    def _lag_verdict(self, t: float, why: str) -> None:
        """The data contradict the lag in use (nothing learnt or applied from pairs of
        different moments: the calibration to raw), or agree again (what was learnt
        before re-opens)."""
        sup = self.sup
        self._emit(t, "lag_check", {"lag_s": self.learner.lag_s, "why": why or "agrees"})
        if not why:
            self.learner.reopen_for_change()
            return
        sup.candidate = None
        if sup.applied is not None:
            sup.withdraw(t, why, {})

    def _supervise(self, a: Aligned) -> None:
        """The supervisor's verdicts on one reading; a change it saw re-opens the learner."""
        assert a.ref is not None
        lr, sup = self.learner, self.sup
        current = lr.kf.current_mps if self.layout.current else None
        cs = a.cs
        proj = 0.0 if current is None or cs is None else current[0] * cs[0] + current[1] * cs[1]
        water = current is not None and lr.ident_current()
        sup.observe(a.t, a.raw, a.ref, cs, lr, proj=proj, water=water)
        if sup.sea_changed:
            sup.sea_changed = False
            if lr.reopen_current():
                self._emit(
                    a.t, "relearn", {"why": "the reference jumped: the current learns again"}
                )
        if sup.reopen:
            sup.reopen = False
            if not self.reopen_on_change:
                return
            lr.reopen_for_change()
            self.counters.relearn += 1
            self._emit(a.t, "relearn", {"why": "the supervisor saw the readings change"})

    def ident_current(self) -> bool:
        """The current is determined (:meth:`Learner.ident_current`)."""
        return self.learner.ident_current()

    # -- state ----------------------------------------------------------------

    def _set_state(self, t: float, learnt: bool, fault: str) -> None:
        if fault:
            new: CalState = "fault"
            self.reason = {
                "uut_stuck": f"speed log stuck for {self.s.stuck_s:g} s while the reference moves",
                "uut_zero": f"speed log reads zero for {self.s.zero_s:g} s while the reference moves",
            }.get(fault, fault)
        elif learnt:
            new = "learning"
            undetermined = (
                self.learner.ident.unidentifiable if self.learner.ident is not None else ()
            )
            self.reason = (
                "learning; " + self.learner.ident.reason
                if self.learner.ident is not None and undetermined
                else "learning"
            )
        else:
            new = "frozen" if self.applied is not None else "uncalibrated"
            self.reason = self._why_not_learning()
        why = self.lag_beyond or (self.lagcheck.why if self.lagcheck is not None else "")
        if why:
            self.reason = f"raw passes through, nothing learnt: {why}"
        elif self.note:
            self.reason = f"{self.reason}; {self.note}"
        if self.learner.lag_note:
            self.reason = f"{self.reason}; {self.learner.lag_note}"
        if new != self.state:
            self._emit(t, "state", {"from": self.state, "to": new, "why": self.reason})
            if self.state == "learning" and new == "frozen":
                self.freezes += 1
            self.state = new

    def _why_not_learning(self) -> str:
        s = self.s
        lf = self.learner.lag_finder
        if lf is not None and self.lag_s is None:
            return f"estimating the lag, {lf.span():.0f} of {lf.target_s:.0f} s"
        if not self.learn_on:
            return "learning switched off"
        if self.ref_state != "valid":
            return {
                "lost": "reference lost",
                "stale": "reference silent",
                "slow": f"reference below {s.min_ref_speed_mps:g} m/s",
                "none": "no reference yet",
            }.get(self.ref_state, "reference not valid")
        if self.learner.ident is not None and not self.learner.learn_set - {CURRENT}:
            return self.learner.ident.reason or "nothing determinable"
        return "no heading for the current" if self.layout.current else "waiting"

    def _trace_row(
        self,
        t: float,
        raw: float,
        ref: float | None,
        heading: float | None,
        inn: Innovation | None,
        learn_set: frozenset[str] | bool,
    ) -> dict[str, object]:
        kf = self.kf
        est = kf.params.as_dict()
        std = kf.param_std
        cur = kf.current_mps
        cur_std = kf.current_std_mps
        row: dict[str, object] = {
            "t": t,
            "raw_mps": raw,
            "ref_mps": ref,
            "heading_deg": heading,
            "emitted_mps": self.correct(raw),
            "corrected_mps": kf.corrected(raw),
        }
        for name in ("a", "m", "b"):
            row[name] = est.get(name)
            row[f"std_{name}"] = std.get(name)
        row["current_north_mps"] = None if cur is None else cur[0]
        row["current_east_mps"] = None if cur is None else cur[1]
        row["std_current_north_mps"] = None if cur_std is None else cur_std[0]
        row["std_current_east_mps"] = None if cur_std is None else cur_std[1]
        row["current_determined"] = self.ident_current()
        row["nis"] = None if inn is None else inn.nis
        row["state"] = self.state
        row["learning"] = "+".join(sorted(learn_set)) if isinstance(learn_set, frozenset) else ""
        return row

    # -- read-outs ----------------------------------------------------------

    # -- read-outs ----------------------------------------------------------

    def nis_mean(self) -> float | None:
        """Running NIS mean over the last 300 learnt samples."""
        return self.learner.nis_mean()

    def take_snapshot(self, t: float) -> Calibration | None:
        """The applied calibration to persist, when it changed (and persisting is due)."""
        if not self.sup.dirty or t - self.t_persist < self.s.persist_interval_s:
            return None
        self.sup.dirty = False
        self.t_persist = t
        return self.snapshot(t)

    def snapshot(self, t: float | None = None) -> Calibration:
        """The calibration to persist: the applied one, else the last good one (withdrawn
        for cause, it re-validates after a restart); ``reset`` when there is none."""
        kept = self.sup.kept
        cur = self.kf.current_mps if self.ident_current() else None
        cur_std = self.kf.current_std_mps if cur is not None else None
        return Calibration(
            uut=self.s.port,
            estimate=Estimate(
                kept if kept is not None else zero_params(self.s.model),
                dict(self.sup.kept_std) if kept is not None else {},
                cur,
                cur_std,
            ),
            # a fallback lag is not saved: a restart measures it again
            lag_s=self.lag_s if self.lag_finder is None else None,
            current=self.layout.current,
            covariance=tuple(tuple(row) for row in self.kf.covariance())
            if kept is not None
            else (),
            method="online",
            t=t if t is not None else (self.t_prev or 0.0),
            n_samples=self.n_learnt,
            reference={"port": self.s.reference_port, "field": self.s.reference_field},
            unidentifiable=self.ident.unidentifiable if self.ident is not None else (),
            nis_mean=self.nis_mean(),
            reset=kept is None,
        )
