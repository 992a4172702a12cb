"""The calibration of one unit under test (UUT): align, learn, supervise, correct.

One :class:`UutCalibration` per EMlog, fed by :class:`emlogd.pipeline.core.Pipeline`
with the UUT's readings, its reference (already reduced to a speed along the hull)
and its heading. Nothing here reads a clock or does I/O; times are receive times.

**Emitting** (:meth:`UutCalibration.correct`) uses only the *applied* calibration:
the last one that beat the raw reading on data it had not learnt from, else the raw
reading itself (pass-through). It never waits for the reference, so the autopilot's
latency is the decoder's.

**Learning** (:meth:`UutCalibration.learn`) pairs each reading with the reference and
the heading at ``t − lag`` (:mod:`emlogd.pipeline.align`); a reading waits in a short
queue until its reference has arrived. Per sample:

1. the lag: configured, restored with the calibration, or estimated once over
   ``lag_window_s`` (:mod:`calib.lag`, with the current modelled when there is one);
2. the reference's state: valid, lost, stale, too slow, or none yet;
3. the UUT's health (:class:`~emlogd.pipeline.integrity.UutHealth`): a stuck or dead
   log is neither learnt from nor corrected — its output goes silent;
4. which unknowns the recent data determine (:class:`calib.excitation.ExcitationWindow`):
   only those learn; the others are held at their prior (the applied calibration,
   else nominal). With current states the current always learns — as a nuisance
   absorbing bias and along-hull current together when they cannot be told apart;
5. the filter step (:class:`calib.kalman.KfCalibrator`) with an NIS gate: a gated
   sample teaches nothing; a run of gated readings re-opens the parameters (the
   sensor changed), a run of gated references re-acquires the speed;
6. supervision: an estimate whose learnt unknowns are all under ``max_param_std``,
   inside the envelope, and different enough from the applied calibration becomes
   a *candidate*, frozen and scored against the reference over the next
   ``validation_s``; it is applied only if it beats both the raw reading and the
   applied calibration there. The applied calibration is re-checked on a window of
   ``recheck_s``: once worse than raw it falls back to the previous good one if that
   beats raw, else to raw pass-through, and says so.

Errors are scored in the water frame when the UUT has current states: a calibration's
corrected speed plus the estimated current projected on the hull, against the
reference over the ground.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from calib.errors import CalibrationError
from calib.excitation import ExcitationWindow, Identifiability
from calib.kalman import Innovation, KfCalibrator
from calib.lag import MAX_LAG_STD_RELAXED_S, MAX_LAG_STD_S, accept, estimate_lag
from calib.lsq import BLOCK_MAX_GAP_S, MIN_HEADING_COHERENCE
from calib.models import CURRENT, FloatArray, Layout, Params, check_model, zero_params
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.integrity import Envelope, PairedWindow, UutHealth, emitted_speed

if TYPE_CHECKING:
    from emlogd.pipeline.settings import UutSettings

RefState = Literal["valid", "lost", "stale", "slow", "none"]
CalState = Literal["learning", "frozen", "uncalibrated", "fault"]

EVAL_EVERY = 10
"""Identifiability is re-judged every this many samples with a valid reference."""

LEARN_STD_FACTOR = 5.0
"""Online, an unknown may learn while the window's own information gives it a standard
deviation up to this many times its ``max_std``: the filter's covariance weighs weak
information, and only a structural degeneracy (constant speed, too few heading
sectors, a singular window) must stop it. Whether the result is good enough to apply
is judged on the filter's covariance (``max_param_std``) and the validation window."""

NUISANCE_REOPEN = 20
"""Samples the current has learnt while every scale was held after which a scale
becoming determined re-opens the current (what it learnt was conditional on the held
scale)."""

_TRACK_CURRENT = frozenset({CURRENT})
"""What learns while the operator has switched learning off (water frame only)."""

LAG_WINDOW_GROWTH = 4.0
"""A refused lag estimate lets the window grow up to this many times ``lag_window_s``."""

LAG_MAX_RATE_HZ = 20.0
"""Reference samples per second the lag window is sized for (a 10 Hz DVL twice over)."""

VALIDATION_MIN_SAMPLES = 20
"""A candidate needs at least this many scored samples in its validation window."""

RECHECK_MIN_SAMPLES = 60.0
"""The applied calibration is judged once its re-check window holds this many."""

WORSE_FACTOR = 1.05
WORSE_MARGIN_MPS = 0.005
"""The applied calibration is worse than raw when its RMSE exceeds raw's × 1.05 + 5 mm/s."""


class Recorder(Protocol):
    """What the offline commands collect from a UUT: its inputs, exactly as learning sees them."""

    def reference(
        self, t: float, v_mps: float | None, valid: bool, heading_deg: float | None
    ) -> None:
        """One reference sample along the hull and the UUT's heading at its time."""

    def reading(self, t: float, raw_mps: float) -> None:
        """One reading of the learnt sentence (fresh, in range)."""


AVERAGE_S: dict[str, float] = {"gnss": 20.0}
"""Learning from block means of this length by reference field, s (others: every
sample). GNSS speed projected on the hull has about 0.3 m/s of noise correlated over
seconds (the receiver's filter, the heading's swing); taken sample by sample it would
make the filter far more certain of the current than the data allow, and a plain least
squares would shrink the scale (errors in the regressor). 20-s means still follow a
yacht's tacks and a boat's speed steps."""

CURRENT_SIGNIFICANCE = 3.0
"""A current is reported when each component's σ is within ``max_std_current_mps``, or
within a third of the current's speed: a 1 m/s tidal stream known to ±0.1 m/s is a
measurement; 0.1 m/s known to ±0.1 m/s is not."""


class BlockMeans:
    """Consecutive blocks of learnt-from samples, averaged (:data:`AVERAGE_S`); the
    streaming form of :func:`calib.lsq.block_average`, with its rules.

    A block closes after ``window_s`` (samples that cannot be learnt from are left out);
    it is dropped when the set of unknowns learning changes, a gap between its samples
    exceeds 5 s, the heading comes or goes, or the heading turned too much
    inside it (its mean heading vector shorter than :data:`MIN_HEADING_COHERENCE`).
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.clear()

    def clear(self) -> None:
        """Drop the block being collected."""
        self.n = 0
        self.t0 = self.t_last = 0.0
        self.raw = self.ref = self.c = self.s = 0.0
        self.learn: frozenset[str] = frozenset()
        self.with_heading = False

    def add(
        self,
        t: float,
        raw: float,
        ref: float,
        cs: tuple[float, float] | None,
        learn: frozenset[str],
    ) -> tuple[float, float, tuple[float, float] | None, frozenset[str]] | None:
        """Add a sample; the block's (raw, ref, (cos, sin), unknowns) when it closes."""
        if self.n and (
            learn != self.learn
            or t - self.t_last > BLOCK_MAX_GAP_S
            or (cs is not None) != self.with_heading
        ):
            self.clear()
        if not self.n:
            self.t0, self.learn, self.with_heading = t, learn, cs is not None
        self.n += 1
        self.t_last = t
        self.raw += raw
        self.ref += ref
        if cs is not None:
            self.c += cs[0]
            self.s += cs[1]
        if t - self.t0 < self.window_s:
            return None
        n, learn_set = self.n, self.learn
        mean_cs: tuple[float, float] | None = None
        if self.with_heading:
            c, s = self.c / n, self.s / n
            norm = math.hypot(c, s)
            if norm < MIN_HEADING_COHERENCE:
                self.clear()
                return None
            mean_cs = (c / norm, s / norm)
        out = (self.raw / n, self.ref / n, mean_cs, learn_set)
        self.clear()
        return out


@dataclass
class Counters:
    """Why samples were not learnt from (or not emitted), by reason."""

    learnt: int = 0
    out_of_range: int = 0
    backlog: int = 0
    gated_raw: int = 0
    gated_ref: int = 0
    no_heading: int = 0
    uut_fault: int = 0
    relearn: int = 0
    reacquire: int = 0
    envelope: int = 0
    candidates_rejected: int = 0
    candidates_applied: int = 0
    fallbacks: int = 0

    def as_dict(self) -> dict[str, int]:
        """Plain types."""
        return dict(self.__dict__)


@dataclass(slots=True)
class Score:
    """Running sums of squared errors against the reference (replay's RMSE figures)."""

    n: int = 0
    ss_raw: float = 0.0
    ss_cor: float = 0.0

    def add(self, err_raw: float, err_cor: float) -> None:
        """One sample's errors (reading − reference), m/s."""
        self.n += 1
        self.ss_raw += err_raw * err_raw
        self.ss_cor += err_cor * err_cor

    @property
    def rmse_raw(self) -> float | None:
        """RMSE of the raw readings, m/s (None before any sample)."""
        return math.sqrt(self.ss_raw / self.n) if self.n else None

    @property
    def rmse_corrected(self) -> float | None:
        """RMSE of the emitted speeds, m/s."""
        return math.sqrt(self.ss_cor / self.n) if self.n else None


@dataclass
class _Candidate:
    params: Params
    t0: float
    raw: float = 0.0
    cand: float = 0.0
    applied: float = 0.0
    n: int = 0


class LagFinder:
    """Bounded series of the UUT, its reference and heading for the one-off lag estimate.

    The first estimate is made over ``window_s``; one that is not final keeps the data
    and waits for a window half as long again, up to :data:`LAG_WINDOW_GROWTH` times
    the first (a broad correlation peak sharpens with more data); beyond that the older
    half is dropped and the window slides. An estimate within
    :data:`calib.lag.MAX_LAG_STD_S` is final; one within the relaxed
    :data:`calib.lag.MAX_LAG_STD_RELAXED_S` is provisional until the longest window
    (learning starts with it: a lag off by a tenth of a second costs a calibration far
    less than twenty minutes of raw output), and final there.
    """

    def __init__(self, window_s: float, max_lag_s: float, with_heading: bool) -> None:
        self.window_s = window_s
        self.target_s = window_s
        self.max_lag_s = max_lag_s
        self.with_heading = with_heading
        cap = int((LAG_WINDOW_GROWTH * window_s + 2 * max_lag_s) * LAG_MAX_RATE_HZ) + 64
        self.uut = _Series(cap)
        self.ref = _Series(cap)
        self.heading = _Series(cap)

    def ready(self) -> bool:
        """The UUT series spans the current target window."""
        return self.uut.span() >= self.target_s

    def span(self) -> float:
        """Time the UUT series spans, s."""
        return self.uut.span()

    def estimate(self) -> tuple[float | None, float, str, bool]:
        """``(lag, std, why, final)``: an accepted lag, or None and why; the window grows
        unless the estimate is final."""
        try:
            est = estimate_lag(
                self.uut.times(),
                self.uut.values(),
                self.ref.times(),
                self.ref.values(),
                self.max_lag_s,
                step_s=0.1,
                heading=(self.heading.times(), self.heading.values())
                if self.with_heading
                else None,
            )
        except CalibrationError as exc:
            why = str(exc)
        else:
            why = accept(est, max_std_s=MAX_LAG_STD_RELAXED_S)
            if not why:
                what = f"r={est.peak_corr:.2f}, σ {est.std_s:.3f} s"
                if est.std_s <= MAX_LAG_STD_S:
                    return est.lag_s, est.std_s, what, True
                if self.target_s >= LAG_WINDOW_GROWTH * self.window_s:
                    note = "uncertain: the sharpest peak in the longest window"
                    return est.lag_s, est.std_s, f"{what}, {note}", True
                self._grow()
                return est.lag_s, est.std_s, f"{what}, provisional until a sharper peak", False
        self._grow()
        return None, math.inf, why, False

    def _grow(self) -> None:
        if self.target_s < LAG_WINDOW_GROWTH * self.window_s:
            self.target_s = min(1.5 * self.target_s, LAG_WINDOW_GROWTH * self.window_s)
        else:
            for q in (self.uut, self.ref, self.heading):
                q.drop_older_half()


class _Series:
    """Two bounded deques of floats (times and values): lean fixed memory."""

    __slots__ = ("t", "v")

    def __init__(self, cap: int) -> None:
        self.t: deque[float] = deque(maxlen=cap)
        self.v: deque[float] = deque(maxlen=cap)

    def append(self, item: tuple[float, float]) -> None:
        self.t.append(item[0])
        self.v.append(item[1])

    def span(self) -> float:
        return self.t[-1] - self.t[0] if self.t else 0.0

    def times(self) -> FloatArray:
        return np.fromiter(self.t, dtype=np.float64, count=len(self.t))

    def values(self) -> FloatArray:
        return np.fromiter(self.v, dtype=np.float64, count=len(self.v))

    def drop_older_half(self) -> None:
        for _ in range(len(self.t) // 2):
            self.t.popleft()
            self.v.popleft()

    def __len__(self) -> int:
        return len(self.t)


class UutCalibration:
    """The online calibration of one UUT (see the module docstring).

    Args:
        s: the UUT's settings (:class:`emlogd.pipeline.settings.UutSettings`).
        prior: a checked calibration to start from (warm start), or None.
        heading_at: returns the UUT's heading in degrees (true) at a time, or None.
        event: called as ``event(t, kind, detail)`` for every state change worth a log line.
    """

    def __init__(
        self,
        s: UutSettings,
        prior: Calibration | None,
        heading_at: Callable[[float], float | None],
        event: Callable[[float, str, Mapping[str, object]], None],
    ) -> None:
        self.s = s
        self.layout = Layout(check_model(s.model), s.current)
        self.heading_at = heading_at
        self._event = event
        usable = prior if prior is not None and not prior.reset else None
        if usable is not None and usable.params.model != s.model:
            usable = None
        self.applied: Params | None = usable.params if usable is not None else None
        self.applied_std: dict[str, float | None] = dict(usable.param_std) if usable else {}
        self.previous: Params | None = None
        self.kf = self._new_filter(usable)
        self.lag_s: float | None = s.lag_s
        if self.lag_s is None and usable is not None and usable.lag_s is not None:
            self.lag_s = usable.lag_s
        self.lag_std_s = math.inf
        self.lag_finder = (
            LagFinder(s.lag_window_s, s.max_lag_s, s.current) if self.lag_s is None else None
        )
        self.ref = SampleRing(int((s.max_lag_s + 5.0) * 50) + 64)
        self.pending: deque[tuple[float, float]] = deque(maxlen=int((s.max_lag_s + 5.0) * 20) + 16)
        self.window = ExcitationWindow(
            self.layout, max(s.excitation_half_life_samples, 1.0), s.rule
        )
        self.ident: Identifiability | None = None
        self.learn_set: frozenset[str] = frozenset()
        self.learnt_ever: set[str] = set()
        self.nuisance_samples = 0
        self.current_reportable = False
        self.health = UutHealth(s.stuck_s, s.zero_s)
        self.learn_on = s.learn
        self.state: CalState = "frozen" if self.applied is not None else "uncalibrated"
        self.reason = (
            "" if self.applied is not None else "no calibration yet: raw readings pass through"
        )
        self.ref_state: RefState = "none"
        self.t_prev: float | None = None
        self.t_restored = usable.t if usable is not None and usable.current else None
        """When the restored calibration's current was last known (aged at the first reading)."""
        self.t_ref_last = -math.inf
        self.n_learnt = usable.n_samples if usable is not None else 0
        self.n_since_eval = 0
        self.nis: deque[float] = deque(maxlen=300)
        self.nis_sum = 0.0
        self.gated_run_raw = 0
        self.gated_run_ref = 0
        self.candidate: _Candidate | None = None
        self.recheck = PairedWindow(s.recheck_s)
        self.counters = Counters()
        self.score = Score()
        self.score_water = Score()
        self.freezes = 0
        self._was_learning = False
        self.t_persist = -math.inf
        self.persisted: Params | None = self.applied
        self.dirty = False
        """The applied calibration changed since it was last handed out for persisting."""
        self.note = ""
        """The last supervision decision worth showing with the state (a fallback)."""
        self.recorder: Recorder | None = None
        """Offline use: receives every reference sample and reading as learning sees them."""
        self.record_only = False
        """With a recorder: only record the readings, learn nothing (reading captures)."""
        self.tracer: Callable[[dict[str, object]], None] | None = None
        """Offline use (``calibrate --trace``): receives one row per learnt-from reading."""
        average = s.average_s if s.average_s is not None else AVERAGE_S.get(s.reference_field, 0.0)
        self.block = BlockMeans(average) if average > 0.0 else None
        """Learning from block means (a noisy reference), or None: from every sample."""
        env = s.envelope
        self._wide = Envelope(
            2.0 * env.max_abs_m,
            2.0 * env.max_abs_b_mps,
            2.0 * env.max_abs_a_spm,
            2.0 * env.max_current_mps,
            env.max_speed_mps,
        )
        """Twice the envelope: an estimate beyond it restarts the filter (:meth:`_envelope`)."""
        self._param_names = frozenset(self.layout.params)

    # -- construction -------------------------------------------------------

    def _new_filter(self, prior: Calibration | None) -> KfCalibrator:
        s = self.s
        params0 = prior.params if prior is not None else None
        cur0 = prior.current_mps if prior is not None and prior.current else None
        cov0 = None
        if prior is not None and prior.covariance and prior.layout == self.layout:
            cov0 = np.array(prior.covariance, dtype=np.float64)
        elif prior is not None:
            n = self.layout.n
            diag = np.full(n, s.kf.p0)
            for i, name in enumerate(self.layout.params):
                sd = prior.param_std.get(name)
                if sd is not None and math.isfinite(sd) and sd > 0.0:
                    diag[1 + i] = max(sd * sd, 1e-12)
            if self.layout.current:
                diag[-2:] = s.kf.current_p0_m2ps2
            cov0 = np.diag(diag)
        kf = KfCalibrator(
            s.model, s.kf, current=s.current, params0=params0, current0_mps=cur0, P0=cov0
        )
        # the vessel's speed now is unknown (a saved covariance holds the variance the
        # speed had when saved): the first measurement sets it, and no reading is
        # gated against a speed of zero
        kf.reacquire_speed()
        return kf

    def _emit(self, t: float, kind: str, detail: Mapping[str, object]) -> None:
        self._event(t, kind, detail)

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
            s = std.get(name)
            if s is not None and math.isfinite(s):
                var += (s * x) ** 2 / max(gain * gain, 0.25)
        return math.sqrt(var)

    def in_range(self, raw_mps: float) -> bool:
        """A reading the sensor can give: finite, within ``[0, max_speed]`` (sternway aside)."""
        return math.isfinite(raw_mps) and -1.0 <= raw_mps <= self.s.envelope.max_speed_mps

    # -- inputs -------------------------------------------------------------

    def add_reference(self, t: float, v_mps: float | None, valid: bool) -> None:
        """One reference sample along the hull (already filtered for glitches)."""
        if not self.ref.add(t, v_mps, valid):
            return
        self.t_ref_last = t
        if self.recorder is not None:
            self.recorder.reference(t, v_mps, valid, self.heading_at(t))
        lf = self.lag_finder
        if lf is not None and valid and v_mps is not None and math.isfinite(v_mps):
            lf.ref.append((t, v_mps))
            if lf.with_heading:
                h = self.heading_at(t)
                if h is not None:
                    lf.heading.append((t, h))

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
        while self.pending:
            t, raw = self.pending[0]
            lag = self.lag_s
            if lag is not None and not final:
                target = t - lag
                waiting = not self.ref.covers(target)
                if waiting and now - target <= self.ref.max_gap_s + 1.0:
                    return
            self.pending.popleft()
            self.learn(t, raw)

    # -- learning -----------------------------------------------------------

    def learn(self, t: float, raw: float) -> None:
        """Align, supervise and update the filter with one reading."""
        s = self.s
        dt = 0.0 if self.t_prev is None else max(t - self.t_prev, 0.0)
        self.t_prev = t
        if self.t_restored is not None:
            self.kf.age_current(t - self.t_restored)
            self.t_restored = None
        self._lag_step(t, raw)
        lag = self.lag_s
        ref = self.ref.at(t - lag) if lag is not None else None
        heading = self.heading_at(t - lag) if lag is not None else None
        ref_state = self._ref_state(t, ref)
        if ref_state != self.ref_state:
            self._emit(t, "reference", {"from": self.ref_state, "to": ref_state})
            self.ref_state = ref_state
        fault = self.health.update(t, raw, ref if ref_state == "valid" else None)
        valid = ref_state == "valid" and ref is not None
        cs: tuple[float, float] | None = None
        if heading is not None:
            psi = math.radians(heading)
            cs = (math.cos(psi), math.sin(psi))
        if valid and self.layout.current and cs is None:
            self.counters.no_heading += 1
            valid = False
        current = self.kf.current_mps
        proj = 0.0 if current is None or cs is None else current[0] * cs[0] + current[1] * cs[1]
        if valid and ref is not None:
            self.window.add(ref - proj, raw, heading)
            self.n_since_eval += 1
            if self.n_since_eval >= EVAL_EVERY or self.ident is None:
                self._judge(t)
        learn_set: frozenset[str] | bool = False
        if valid and not fault and lag is not None and self.learn_set:
            if self.learn_on:
                learn_set = self.learn_set
            elif self.layout.current:
                # Learning off freezes the sensor's parameters, not the sea: the current
                # keeps following a valid reference, so the output is still checked
                # against the reference in the water frame.
                learn_set = _TRACK_CURRENT
        if fault:
            self.counters.uut_fault += 1
        block = self.block
        res = self.kf.update(
            raw,
            ref if valid else None,
            dt,
            heading_cs=cs,
            learn=False if block is not None else learn_set,
            max_nis=s.gate_nis,
        )
        self._gates(t, res.raw_gated, res.ref_gated, valid)
        learnt = res.learnt and learn_set is not False
        if block is not None:
            # Block means: each sample moves the speed state only; the unknowns learn
            # from the means of a block (a noisy reference's errors are correlated
            # over seconds, so single samples would overstate what is known).
            closed = None
            usable = not (res.raw_gated or res.ref_gated) and res.raw is not None
            if usable and isinstance(learn_set, frozenset) and ref is not None:
                closed = block.add(t, raw, ref, cs, learn_set)
            learnt = False
            if closed is not None:
                b_raw, b_ref, b_cs, b_learn = closed
                # the speed state followed the last sample; the block's mean speed is
                # another quantity: the mean reference sets it afresh
                self.kf.reacquire_speed()
                res = self.kf.update(
                    b_raw,
                    b_ref,
                    0.0,
                    heading_cs=b_cs,
                    learn=b_learn,
                    max_nis=s.gate_nis,
                )
                learnt = res.learnt
                learn_set = b_learn
        if not self.learn_on:
            learnt = False  # at most the current followed the reference
        if learnt and res.raw is not None:
            self.n_learnt += 1
            self.counters.learnt += 1
            if isinstance(learn_set, frozenset):
                self.learnt_ever |= learn_set
                if CURRENT in learn_set and not {"a", "m"} & learn_set:
                    self.nuisance_samples += 1
            if len(self.nis) == self.nis.maxlen:
                self.nis_sum -= self.nis[0]
            self.nis.append(res.raw.nis)
            self.nis_sum += res.raw.nis
            self._envelope(t)
        if valid and ref is not None and not fault:
            self._score(t, raw, ref, cs)
        self._set_state(
            t, bool(learnt) or (self.learn_on and block is not None and block.n > 0), fault
        )
        if self.tracer is not None:
            self.tracer(
                self._trace_row(t, raw, ref if valid else None, heading, res.raw, learn_set)
            )

    def _lag_step(self, t: float, raw: float) -> None:
        lf = self.lag_finder
        if lf is None:
            return
        lf.uut.append((t, raw))
        if not lf.ready():
            return
        lag, std, why, final = lf.estimate()
        if lag is None:
            self._emit(t, "lag_retry", {"why": why})
            return
        if self.lag_s is None or final or std < self.lag_std_s:
            # the first, a sharper one from a longer window, or the final one
            self._emit(t, "lag_estimated", {"lag_s": round(lag, 3), "why": why})
            self.lag_s, self.lag_std_s = lag, std
        if final:
            self.lag_finder = None

    def _ref_state(self, t: float, ref: float | None) -> RefState:
        if self.lag_s is None and self.t_ref_last == -math.inf:
            return "none"
        if t - self.t_ref_last > self.s.ref_stale_s:
            return "stale"
        if ref is None:
            return "lost" if self.lag_s is not None else "none"
        if abs(ref) < self.s.min_ref_speed_mps:
            return "slow"
        return "valid"

    def _judge(self, t: float) -> None:
        self.n_since_eval = 0
        kf = self.s.kf
        sigma2 = kf.r_raw_mps2 + kf.r_ref_mps2
        ident = self.window.evaluate(sigma2, std_factor=LEARN_STD_FACTOR)
        before = self.ident.determined if self.ident is not None else None
        self.ident = ident
        if self.layout.current:
            strict = self.window.evaluate(sigma2)
            self.current_reportable = CURRENT in strict.determined
        learn = set(ident.determined)
        if self.layout.current:
            learn.add(CURRENT)
            gained = {"a", "m"} & (learn - self.learn_set)
            if gained and self.nuisance_samples >= NUISANCE_REOPEN:
                # The current took the offset of a scale held at its prior: that offset
                # was the scale's. Let the current learn again beside the scale.
                self.kf.reopen([CURRENT])
                self.nuisance_samples = 0
                self._emit(
                    t,
                    "relearn",
                    {
                        "why": f"{', '.join(sorted(gained))} now determined: the current learns again"
                    },
                )
        elif "b" in self.layout.params and "b" not in learn:
            # Without current states nothing takes the offset the held bias leaves: a
            # scale learnt then would absorb it. The scale learns with the bias only.
            learn -= {"a", "m"}
        self.learn_set = frozenset(learn)
        if before != ident.determined:
            self._emit(
                t,
                "identifiability",
                {"determined": list(ident.determined), "why": ident.reason},
            )

    def _gates(self, t: float, raw_gated: bool, ref_gated: bool, valid: bool) -> None:
        s = self.s
        if ref_gated:
            self.counters.gated_ref += 1
            self.gated_run_ref += 1
            if self.gated_run_ref >= s.relearn_gates:
                # The speed state lost the reference (after a long outage, or a real
                # jump the state could not follow): re-acquire it from the reference.
                self.kf.reacquire_speed()
                self.counters.reacquire += 1
                self.gated_run_ref = 0
                self._emit(t, "reacquire", {"why": "reference gated repeatedly"})
        elif valid:
            self.gated_run_ref = 0
        if raw_gated:
            self.counters.gated_raw += 1
            self.gated_run_raw += 1
            if self.gated_run_raw >= s.relearn_gates:
                # The readings no longer fit the calibration while the log is healthy:
                # the sensor changed. Learn its parameters again from the data.
                self.kf.reopen(self.layout.params)
                self.counters.relearn += 1
                self.gated_run_raw = 0
                self._emit(t, "relearn", {"why": "readings gated repeatedly"})
        else:
            self.gated_run_raw = 0

    def _envelope(self, t: float) -> None:
        """Restart the parameters when the estimate has run far outside the envelope.

        A learning transient may leave the envelope (nothing outside it is applied or
        persisted); an estimate at twice the limits, or one that cannot be inverted,
        is a filter captured by something the model does not explain.
        """
        why = self._wide.check(self.kf.params, self.kf.current_mps)
        if not why:
            return
        self.counters.envelope += 1
        base = self.applied if self.applied is not None else zero_params(self.s.model)
        self.kf.restart(base)
        self._emit(t, "envelope", {"why": why, "restart_from": base.as_dict()})

    # -- supervision ----------------------------------------------------------

    def _errors(self, raw: float, ref: float, proj: float, p: Params | None) -> float:
        corrected = raw if p is None else p.correct(raw)
        return corrected + proj - ref

    def _score(self, t: float, raw: float, ref: float, cs: tuple[float, float] | None) -> None:
        # Validation and re-check compare speeds through the water: the reference minus
        # the filter's current, whenever it estimates one (against the ground speed a
        # correct calibration would lose to a raw reading whose error happens to offset
        # the current). The status's water-frame score waits for a determined current.
        current = self.kf.current_mps if self.layout.current else None
        proj = 0.0 if current is None or cs is None else current[0] * cs[0] + current[1] * cs[1]
        e_raw = self._errors(raw, ref, proj, None)
        e_app = self._errors(raw, ref, proj, self.applied)
        out = self.correct(raw)
        if out is not None:
            self.score.add(raw - ref, out - ref)
            if current is not None and self.ident_current():
                self.score_water.add(raw + proj - ref, out + proj - ref)
        e_prev = self._errors(raw, ref, proj, self.previous) if self.previous is not None else 0.0
        self.recheck.add(t, e_raw, e_app, e_prev)
        cand = self.candidate
        if cand is not None:
            cand.raw += e_raw * e_raw
            cand.applied += e_app * e_app
            e_c = self._errors(raw, ref, proj, cand.params)
            cand.cand += e_c * e_c
            cand.n += 1
            if t - cand.t0 >= self.s.validation_s and cand.n >= VALIDATION_MIN_SAMPLES:
                self._decide(t, cand)
        else:
            self._propose(t)
        self._recheck(t)

    def ident_current(self) -> bool:
        """The current is determined: reported in the status, the VDR and a calibration.

        The recent window must determine it by the strict rule (``max_std_current_mps``
        itself, not the looser bound that lets the filter learn) and the filter's own
        standard deviation of each component must be within that bound, or within a
        third of the current's speed (:data:`CURRENT_SIGNIFICANCE`).
        """
        if not (self.layout.current and self.current_reportable):
            return False
        std, cur = self.kf.current_std_mps, self.kf.current_mps
        if std is None or cur is None:
            return False
        limit = max(self.s.rule.max_std_current_mps, math.hypot(*cur) / CURRENT_SIGNIFICANCE)
        return max(std) <= limit

    def _propose(self, t: float) -> None:
        """Freeze the estimate as a candidate when it is good and new enough."""
        if not self.learnt_ever & self._param_names or self.lag_s is None:
            return
        std = self.kf.param_std
        for name in self.layout.params:
            if name in self.learnt_ever and std[name] > self.s.max_param_std.get(name, math.inf):
                return
        est = self.kf.params
        if self.s.envelope.check(est, self.kf.current_mps):
            return
        if self.applied is not None and not self._significant(self.applied, est, std):
            return
        self.candidate = _Candidate(est, t)

    def _significant(self, old: Params, new: Params, std: Mapping[str, float]) -> bool:
        sigmas, floor = self.s.persist_min_change_sigma, self.s.persist_min_change_abs
        return any(
            abs(y - x) > max(sigmas * std[k], floor)
            for k, x, y in zip(self.layout.params, old.theta, new.theta, strict=True)
        )

    def _decide(self, t: float, cand: _Candidate) -> None:
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
        if r_cand < r_raw and r_cand <= r_app * 1.02 + 0.002:
            if self.applied is None:
                self._emit(t, "calibrated", detail)
            else:
                self._emit(t, "calibration_updated", detail)
            self.previous = self.applied
            self.note = ""
            self.applied = cand.params
            self.applied_std = dict(self.kf.param_std)
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

    def _set_state(self, t: float, learnt: bool, fault: str) -> None:
        if fault:
            new: CalState = "fault"
            self.reason = {
                "uut_stuck": f"speed log stuck for {self.s.stuck_s:g} s while the reference moves",
                "uut_zero": f"speed log reads zero for {self.s.zero_s:g} s while the reference moves",
            }.get(fault, fault)
        elif learnt:
            new = "learning"
            undetermined = self.ident.unidentifiable if self.ident is not None else ()
            self.reason = (
                "learning; " + self.ident.reason
                if self.ident is not None and undetermined
                else "learning"
            )
        else:
            new = "frozen" if self.applied is not None else "uncalibrated"
            self.reason = self._why_not_learning()
        if self.note:
            self.reason = f"{self.reason}; {self.note}"
        if new != self.state:
            self._emit(t, "state", {"from": self.state, "to": new, "why": self.reason})
            if self.state == "learning" and new == "frozen":
                self.freezes += 1
            self.state = new

    def _why_not_learning(self) -> str:
        s = self.s
        lf = self.lag_finder
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
        if self.ident is not None and not self.learn_set - {CURRENT}:
            return self.ident.reason or "nothing determinable"
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

    def nis_mean(self) -> float | None:
        """Running NIS mean over the last 300 learnt samples."""
        return self.nis_sum / len(self.nis) if self.nis else None

    def take_snapshot(self, t: float) -> Calibration | None:
        """The applied calibration to persist, when it changed (and persisting is due)."""
        if not self.dirty or t - self.t_persist < self.s.persist_interval_s:
            return None
        self.dirty = False
        self.t_persist = t
        return self.snapshot(t)

    def snapshot(self, t: float | None = None) -> Calibration:
        """The applied calibration as a record (``reset`` when there is none)."""
        cur = self.kf.current_mps if self.ident_current() else None
        cur_std = self.kf.current_std_mps if cur is not None else None
        return Calibration(
            uut=self.s.port,
            params=self.applied if self.applied is not None else zero_params(self.s.model),
            param_std=dict(self.applied_std) if self.applied is not None else {},
            lag_s=self.lag_s,
            current=self.layout.current,
            current_mps=cur,
            current_std_mps=cur_std,
            covariance=tuple(tuple(row) for row in self.kf.covariance())
            if self.applied is not None
            else (),
            method="online",
            t=t if t is not None else (self.t_prev or 0.0),
            n_samples=self.n_learnt,
            reference={"port": self.s.reference_port, "field": self.s.reference_field},
            unidentifiable=self.ident.unidentifiable if self.ident is not None else (),
            nis_mean=self.nis_mean(),
            reset=self.applied is None,
        )
