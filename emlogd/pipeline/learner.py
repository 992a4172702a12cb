"""The learner of one UUT: lag, alignment, identifiability, the filter, block means.

What a UUT's readings teach, and nothing about what is applied (that is
:mod:`emlogd.pipeline.supervisor`'s). :class:`Learner` pairs each reading with the
reference and the heading at ``t − lag`` (:mod:`emlogd.pipeline.align`) and, per sample:

1. the lag: configured, restored with the calibration, or estimated over
   ``lag_window_s`` (:mod:`calib.lag`, with the current modelled when there is one);
   until an estimate is accepted, learning runs on :data:`calib.lag.LAG_FALLBACK_S`
   and :attr:`Learner.lag_note` says so (the status reason shows it);
2. the reference's state: valid, lost, stale, too slow, or none yet;
3. which unknowns the recent data determine (:class:`calib.excitation.ExcitationWindow`):
   only those learn; the others are held at their prior (the applied calibration,
   else nominal). With current states the current always learns — as a nuisance
   absorbing bias and along-hull current together when they cannot be told apart;
4. the filter step (:class:`calib.kalman.KfCalibrator`) with an NIS gate: a gated
   sample teaches nothing; a run of gated readings re-opens the parameters (the
   sensor changed), a run of gated references re-acquires the speed;
5. an estimate far outside the envelope restarts the filter from the prior.

Its only output to the supervisor is an :class:`Offer`: the estimate and its standard
deviations, once every learnt unknown is within ``max_param_std`` (judged on
:attr:`calib.kalman.KfCalibrator.param_std_offer`) and the estimate is
inside the envelope. When the supervisor withdraws a calibration on a change of the
readings, the parameters re-open by the change's size (:meth:`Learner.reopen_for_change`,
:mod:`emlogd.pipeline.changewindow`). Nothing here reads a clock or does I/O; times are
receive times.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np

from calib.excitation import ExcitationWindow, Identifiability
from calib.kalman import Innovation, KfCalibrator, StepResult
from calib.lag import LAG_FALLBACK_S
from calib.models import CURRENT, Layout, Params, zero_params
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.changewindow import ChangeWindow, widen
from emlogd.pipeline.counters import Counters
from emlogd.pipeline.integrity import Envelope
from emlogd.pipeline.learnbuffers import LAG_MAX_RATE_HZ as LAG_MAX_RATE_HZ
from emlogd.pipeline.learnbuffers import LAG_WINDOW_GROWTH as LAG_WINDOW_GROWTH
from emlogd.pipeline.learnbuffers import BlockMeans as BlockMeans
from emlogd.pipeline.learnbuffers import LagFinder as LagFinder
from emlogd.pipeline.staleness import silent

if TYPE_CHECKING:
    from emlogd.pipeline.settings import UutSettings

RefState = Literal["valid", "lost", "stale", "slow", "none"]

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

OFFER_SIGMAS = 2.0
"""An offer's correction at the speed through the water now (``f(v) − v``, the
parameters learnt so far at ``v``) must be this many of its own standard deviations from
zero (the parameters' covariance, scaled like the σ an offer is judged on): a
correction the filter cannot tell from none is no evidence against the raw reading, and
applying it trades the log's own error for the filter's (2σ: a two-sided 95 % test)."""


@dataclass(frozen=True, slots=True)
class Offer:
    """The learner's estimate, offered to the supervisor as a candidate calibration."""

    params: Params
    param_std: Mapping[str, float]


class Aligned(NamedTuple):
    """One reading with the reference and heading at ``t − lag`` (None when unknown).

    Named tuples, this and :class:`Learnt`: one of each is made per reading, in a third
    of a frozen dataclass's time."""

    t: float
    raw: float
    dt: float
    ref: float | None
    heading: float | None
    cs: tuple[float, float] | None
    """The heading's (cos, sin), or None."""
    ref_state: RefState


class Learnt(NamedTuple):
    """What one filter step did with a reading."""

    valid: bool
    """The reference (and heading, with current states) was usable for this reading."""
    learnt: bool
    """The unknowns learnt from this reading (or from the block it closed)."""
    collecting: bool
    """A block of means is being collected (learning, though nothing learnt yet)."""
    learn_set: frozenset[str] | bool
    innovation: Innovation | None


class Learner:
    """The filter of one UUT and everything that decides what it learns (module docstring).

    Args:
        s: the UUT's settings.
        prior: a checked, usable calibration to start the filter from, or None.
        emit: called as ``emit(t, kind, detail)`` for every event worth a log line.
        matched_noise: the filter's noises scaled by the noise scale matched to the
            innovations (``calibrate --method kf``: an honest σ and NIS); False (the
            daemon) by the slowly adapted one, on which what is offered rests (an
            honest σ from the first blocks would offer parameters the data do not yet
            tell apart: :attr:`calib.kalman.KfCalibrator.param_std_offer`).
    """

    def __init__(
        self,
        s: UutSettings,
        layout: Layout,
        prior: Calibration | None,
        emit: Callable[[float, str, Mapping[str, object]], None],
        counters: Counters,
        *,
        matched_noise: bool = False,
    ) -> None:
        self.s = s
        self.matched_noise = matched_noise
        self.layout = layout
        self._emit = emit
        self.counters = counters
        self.kf = self._new_filter(prior)
        self.lag_s: float | None = s.lag_s
        if self.lag_s is None and prior is not None and prior.lag_s is not None:
            self.lag_s = prior.lag_s
        self.lag_std_s = math.inf
        self.lag_note = ""
        """Why the lag in use is the fallback (shown in the status reason), or empty."""
        self.lag_finder = (
            LagFinder(s.lag_window_s, s.max_lag_s, s.current) if self.lag_s is None else None
        )
        self.ref = SampleRing(int((s.max_lag_s + 5.0) * 50) + 64, cadence=True)
        self.window = ExcitationWindow(
            self.layout, max(s.excitation_half_life_samples, 1.0), s.rule
        )
        self.ident: Identifiability | None = None
        self.learn_set: frozenset[str] = frozenset()
        self.learnt_ever: set[str] = set()
        self.nuisance_samples = 0
        self.current_reportable = False
        self.learn_on = s.learn
        self.ref_state: RefState = "none"
        self.t_prev: float | None = None
        self.t_restored = prior.t if prior is not None and prior.current else None
        """When the restored calibration's current was last known (aged at the first reading)."""
        self.t_ref_last = -math.inf
        self.n_learnt = prior.n_samples if prior is not None else 0
        self.n_since_eval = 0
        self.nis: deque[float] = deque(maxlen=300)
        self.nis_sum = 0.0
        self.gated_run_raw = 0
        self.gated_run_ref = 0
        self.change = ChangeWindow()
        """The last raw innovations, what a change of the readings is measured on."""
        self.shadow: KfCalibrator | None = None
        """After a change, learning from block means: the filter with its parameters
        re-opened to their prior at the change, learning from the same blocks (none of
        the knowledge from before it). An offer waits until it determines them again,
        and the learner then goes on from it (:meth:`offer`)."""
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
        cfg = s.kf
        if cfg.matched_noise != self.matched_noise:
            cfg = dataclasses.replace(cfg, matched_noise=self.matched_noise)
        kf = KfCalibrator(
            s.model, cfg, current=s.current, params0=params0, current0_mps=cur0, P0=cov0
        )
        # the vessel's speed now is unknown (a saved covariance holds the variance the
        # speed had when saved): the first measurement sets it, and no reading is
        # gated against a speed of zero
        kf.reacquire_speed()
        return kf

    # -- inputs -------------------------------------------------------------

    def add_reference(
        self,
        t: float,
        v_mps: float | None,
        valid: bool,
        heading_at: Callable[[float], float | None],
    ) -> bool:
        """One reference sample along the hull; False when the ring refused it."""
        if not self.ref.add(t, v_mps, valid):
            return False
        self.t_ref_last = t
        lf = self.lag_finder
        if lf is not None and valid and v_mps is not None and math.isfinite(v_mps):
            lf.ref.append((t, v_mps))
            if lf.with_heading:
                h = heading_at(t)
                if h is not None:
                    lf.heading.append((t, h))
        return True

    # -- one reading ----------------------------------------------------------

    def align(self, t: float, raw: float, heading_at: Callable[[float], float | None]) -> Aligned:
        """Steps 1–2: the lag, then the reference and heading at ``t − lag`` and their state."""
        dt = 0.0 if self.t_prev is None else max(t - self.t_prev, 0.0)
        self.t_prev = t
        if self.t_restored is not None:
            self.kf.age_current(t - self.t_restored)
            self.t_restored = None
        self._lag_step(t, raw)
        lag = self.lag_s
        ref = self.ref.at(t - lag) if lag is not None else None
        heading = heading_at(t - lag) if lag is not None else None
        ref_state = self._ref_state(t, ref)
        if ref_state != self.ref_state:
            self._emit(t, "reference", {"from": self.ref_state, "to": ref_state})
            self.ref_state = ref_state
        cs: tuple[float, float] | None = None
        if heading is not None:
            psi = math.radians(heading)
            cs = (math.cos(psi), math.sin(psi))
        return Aligned(t, raw, dt, ref, heading, cs, ref_state)

    def step(self, a: Aligned, gate: str, prior: Params | None) -> Learnt:
        """Steps 3–5 for one aligned reading.

        Args:
            a: the reading, aligned.
            gate: why the reading must not teach (the log's fault, a stall), or ``""``.
            prior: the applied calibration (the filter restarts from it), or None.
        """
        valid = self._usable(a)
        self._excitation(a, valid)
        if self.shadow is not None:
            self.shadow.predict(a.dt)
        learn_set = self._learn_set(valid, gate)
        block = self.block
        res = self.kf.update(
            a.raw,
            a.ref if valid else None,
            a.dt,
            heading_cs=a.cs,
            learn=False if block is not None else learn_set,
            max_nis=self.s.gate_nis,
            # between blocks a sample is a sample: the noise scale describes block means
            scaled=block is None,
            # sample by sample (a DVL) the configured noises are the tuning: kept
            adapt=False,
        )
        self._gates(a.t, res.raw_gated, res.ref_gated, valid, gate)
        if valid and res.raw is not None and a.ref is not None and not gate:
            self.change.add_sample(a.t, res.raw.y, a.ref)
        learnt = res.learnt and learn_set is not False
        if block is not None:
            usable = not (res.raw_gated or res.ref_gated) and res.raw is not None
            learnt = False
            closed = self._block_step(block, a, learn_set, usable)
            if closed is not None:
                learn_set, res = closed
                learnt = res.learnt
        if not self.learn_on:
            learnt = False  # at most the current followed the reference
        if learnt and res.raw is not None:
            self._account(learn_set, res.raw.nis)
            self._envelope(a.t, prior)
        collecting = self.learn_on and block is not None and block.n > 0
        return Learnt(valid, bool(learnt), collecting, learn_set, res.raw)

    def _usable(self, a: Aligned) -> bool:
        valid = a.ref_state == "valid" and a.ref is not None
        if valid and self.layout.current and a.cs is None:
            self.counters.no_heading += 1
            valid = False
        return valid

    def _excitation(self, a: Aligned, valid: bool) -> None:
        """Feed the identifiability window (speed through water by the current estimate)."""
        if not valid or a.ref is None:
            return
        current, cs = self.kf.current_mps, a.cs
        proj = 0.0 if current is None or cs is None else current[0] * cs[0] + current[1] * cs[1]
        self.window.add(a.ref - proj, a.raw, a.heading)
        self.n_since_eval += 1
        if self.n_since_eval >= EVAL_EVERY or self.ident is None:
            self._judge(a.t)

    def _learn_set(self, valid: bool, fault: str) -> frozenset[str] | bool:
        if not (valid and not fault and self.lag_s is not None and self.learn_set):
            return False
        if self.learn_on:
            return self.learn_set
        if self.layout.current:
            # Learning off freezes the sensor's parameters, not the sea: the current
            # keeps following a valid reference, so the output is still checked
            # against the reference in the water frame.
            return _TRACK_CURRENT
        return False

    def _block_step(
        self, block: BlockMeans, a: Aligned, learn_set: frozenset[str] | bool, usable: bool
    ) -> tuple[frozenset[str], StepResult] | None:
        """Block means: each sample moves the speed state only; the unknowns learn from
        the means of a block (a noisy reference's errors are correlated over seconds, so
        single samples would overstate what is known). The block's step, when one closed."""
        if not usable or not isinstance(learn_set, frozenset) or a.ref is None:
            return None
        closed = block.add(a.t, a.raw, a.ref, a.cs, learn_set)
        if closed is None:
            return None
        b_raw, b_ref, b_cs, b_learn = closed
        # the speed state followed the last sample; the block's mean speed is another
        # quantity: the mean reference sets it afresh
        self.kf.reacquire_speed()
        shadow = self.shadow
        if shadow is not None:
            # the same blocks: only what it knew at the change differs
            shadow.reacquire_speed()
            shadow.update(
                b_raw, b_ref, 0.0, heading_cs=b_cs, learn=b_learn, max_nis=self.s.gate_nis
            )
        res = self.kf.update(
            b_raw, b_ref, 0.0, heading_cs=b_cs, learn=b_learn, max_nis=self.s.gate_nis
        )
        if res.raw is not None and (res.learnt or res.raw_gated):
            # a gated block measures a change too: it is what did not fit
            self.change.add_block(a.t, res.raw.y, res.raw.S, abs(b_ref))
        return b_learn, res

    def _account(self, learn_set: frozenset[str] | bool, nis: float) -> None:
        self.n_learnt += 1
        self.counters.learnt += 1
        if isinstance(learn_set, frozenset):
            self.learnt_ever |= learn_set
            if CURRENT in learn_set and not {"a", "m"} & learn_set:
                self.nuisance_samples += 1
        if len(self.nis) == self.nis.maxlen:
            self.nis_sum -= self.nis[0]
        self.nis.append(nis)
        self.nis_sum += nis

    def _lag_step(self, t: float, raw: float) -> None:
        lf = self.lag_finder
        if lf is None:
            return
        lf.uut.append((t, raw))
        if not lf.ready():
            return
        lag, std, why = lf.estimate()
        if lag is None:
            self._emit(t, "lag_retry", {"why": why})
            if self.lag_s is None:
                self.lag_s = LAG_FALLBACK_S
                self._emit(t, "lag_fallback", {"lag_s": LAG_FALLBACK_S, "why": why})
            self.lag_note = f"lag not measured ({why}): {LAG_FALLBACK_S:g} s used"
            return
        self._emit(t, "lag_estimated", {"lag_s": round(lag, 3), "why": why})
        self.lag_s, self.lag_std_s = lag, std
        self.lag_note = ""
        self.lag_finder = None

    def _ref_state(self, t: float, ref: float | None) -> RefState:
        if self.lag_s is None and self.t_ref_last == -math.inf:
            return "none"
        if silent(self.t_ref_last, t, max(self.s.ref_stale_s, self.ref.gap_s)):
            # a reference slower than ref_stale_s is stale only past its own cadence
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

    def reopen_current(self) -> bool:
        """The reference jumped (the supervisor's detector saw the sea change): when
        learning sample by sample (a DVL), the current's variance back to its prior, so
        that the jump goes into the current and not into the parameters; True when it
        did. Learning from block means (a noisy reference, whose own jumps a single
        sample cannot tell from the sea's), nothing changes."""
        if not self.layout.current or self.block is not None:
            return False
        for kf in (self.kf, self.shadow):
            if kf is not None:
                kf.reopen([CURRENT])
        return True

    def reopen_for_change(self) -> None:
        """The readings changed (the supervisor's detector withdrew the calibration):
        re-open the parameters by the size of the change, as far as the readings
        measure it (:mod:`emlogd.pipeline.changewindow`). Learning from block means, a
        shadow filter re-opened to the prior (:attr:`shadow`) learns from the same
        blocks and holds the offer until readings after the change determine the
        parameters again, so that a calibration the noise let through is not offered
        again within minutes of its withdrawal."""
        if self.block is not None:
            # a change while a shadow learns: the readings since the first say most
            shadow = (self.shadow if self.shadow is not None else self.kf).copy()
            shadow.reopen(self.layout.params)
            self.shadow = shadow
            change = self.change.block_change()
        else:
            change = self.change.sample_change()
        if change is None:
            self.kf.reopen(self.layout.params)
            return
        delta, v = change
        widen(self.kf, self.layout.params, delta, max(v, self.s.min_ref_speed_mps))

    def _gates(self, t: float, raw_gated: bool, ref_gated: bool, valid: bool, fault: str) -> None:
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
        if raw_gated and not fault:
            # a reading the log's health already refuses (stalled, stuck, zero) says
            # nothing of whether the sensor's calibration changed
            self.gated_run_raw += 1
            if self.gated_run_raw >= s.relearn_gates:
                # The readings no longer fit the calibration while the log is healthy:
                # the sensor changed. Learn its parameters again from the data.
                self.kf.reopen(self.layout.params)
                self.shadow = None
                self.counters.relearn += 1
                self.gated_run_raw = 0
                self._emit(t, "relearn", {"why": "readings gated repeatedly"})
        else:
            self.gated_run_raw = 0

    def _envelope(self, t: float, prior: Params | None) -> None:
        """Restart the parameters when the estimate has run far outside the envelope.

        A learning transient may leave the envelope (nothing outside it is applied or
        persisted); an estimate at twice the limits, or one that cannot be inverted,
        is a filter captured by something the model does not explain.
        """
        why = self._wide.check_values(*self.kf.amb(), self.kf.current_mps)
        if not why:
            return
        self.counters.envelope += 1
        base = prior if prior is not None else zero_params(self.s.model)
        self.kf.restart(base)
        self.shadow = None
        self._emit(t, "envelope", {"why": why, "restart_from": base.as_dict()})

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

    def offer(self) -> Offer | None:
        """The estimate as a candidate, when it is learnt, certain and inside the envelope."""
        if not self.learnt_ever & self._param_names or self.lag_s is None:
            return None
        limits = self.s.max_param_std
        if self.shadow is not None:
            after = self.shadow.param_std_offer
            for name in self.layout.params:
                if name in self.learnt_ever and after[name] > limits.get(name, math.inf):
                    return None
            # the readings since the change determine the parameters: learning goes on
            # from what they say (a change the sea raised: about what was known)
            self.kf, self.shadow = self.shadow, None
        std = self.kf.param_std_offer
        for name in self.layout.params:
            if name in self.learnt_ever and std[name] > limits.get(name, math.inf):
                return None
        if self.s.envelope.check_values(*self.kf.amb(), self.kf.current_mps):
            return None
        if not self._correction_determined(std):
            return None
        return Offer(self.kf.params, std)

    def _correction_determined(self, std_offer: Mapping[str, float]) -> bool:
        """The correction at the speed through the water now is :data:`OFFER_SIGMAS` of
        its own σ from zero (the parameters learnt so far; the others stay at their
        values and count as known)."""
        kf, names = self.kf, self.layout.params
        v = kf.speed_mps
        x = {"a": v * v, "m": v, "b": 1.0}
        idx = [i for i, n in enumerate(names) if n in self.learnt_ever]
        if not idx:
            return False
        cov = kf.covariance()
        std = kf.param_std
        g = [x[names[i]] for i in idx]
        # gᵀ P g over the learnt parameters' block of the covariance
        gp = [sum(g[r] * cov[1 + i][1 + j] for r, i in enumerate(idx)) for j in idx]
        name = names[idx[0]]
        k2 = (std_offer[name] / std[name]) ** 2 if std[name] > 0.0 else 1.0
        var = sum(a * b for a, b in zip(gp, g, strict=True)) * k2
        theta = dict(zip(("a", "m", "b"), kf.amb(), strict=True))
        corr = sum(theta[n] * x[n] for n in names)
        return abs(corr) > OFFER_SIGMAS * math.sqrt(max(var, 0.0))

    @property
    def param_std(self) -> Mapping[str, float]:
        """The filter's standard deviation of each parameter now."""
        return self.kf.param_std

    def nis_mean(self) -> float | None:
        """Running NIS mean over the last 300 learnt samples."""
        return self.nis_sum / len(self.nis) if self.nis else None
