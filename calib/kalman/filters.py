"""KF-EM1..KF-EM4 online, optionally with the sea current: O(1) per sample, fixed memory.

The paper's KF-EMx (eqs. (22)–(24), extended to EM4)::

    x = [v, θ]            θ = [b] | [m] | [m, b] | [a, m, b]
    Φ = I                  P0 = p0·I on θ, x0 = [v0, θ0] (θ0 = 0: the ideal sensor)
    raw = H_k·x + η        H_k = [1, h(v_op)] = [1, 1] | [1, v] | [1, v, 1] | [1, v², v, 1]

``v`` is the speed through the water along the hull and ``h`` the design row of
:mod:`calib.models`: the pseudo-linear operating point ``v_op`` is a measured speed, so
the filter stays linear. The paper takes the reference; here (``fused_operating_point``)
it is the reference (minus the projected current) and the corrected reading weighted by
their variances: ``v_op = w·v̂ + (1 − w)·v_raw`` with v̂ the speed state just updated
with the reference (variance P_vv), v_raw the corrected reading and
``w = σ²_raw/f'² / (σ²_raw/f'² + P_vv)``. Either speed alone carries its own noise into
the regressor of a scale whose innovation holds that same noise (errors in variables):
with the reference, the scale is pulled down by about ``σ²_ref / (var(u) + σ²_ref)`` —
with GNSS at 0.3 m/s and a boat holding its speed within 0.3 m/s, by a half, the bias
taking the difference. The variance-weighted speed is the one whose error is
uncorrelated with the raw innovation ``raw − f(v̂)`` (the two terms cancel), so the
scale is learnt without that pull whichever sensor is the noisier. That holds when v̂ is
the reference's speed alone: the speed state re-acquired before the update (learning
from block means, :meth:`KfCalibrator.reacquire_speed` for each block). A speed state
with a memory of earlier samples has an error the filter's P_vv does not describe
sample by sample, and the weighting over-corrects (a simulated DVL and EMlog at 1 Hz:
the scale 0.4 off), so there the paper's reference operating point is kept: with a DVL
its noise is too small to pull the scale. Beyond the paper:

- **The reference is a measurement too**: ``ref = v + ε`` (H = [1, 0…]) updates the
  speed state; the reference update comes first, then the raw one. The raw
  innovation returned (and its NIS) is against the state already updated with the
  simultaneous reference, so it measures the calibration model.
- **The water frame** (``current=True``): two more states, the sea current north and
  east ``c = (c_N, c_E)`` in m/s. A ground-referenced reference (DVL bottom track,
  GNSS) sees the speed through the water plus the current projected on the hull,
  ``ref = v + c_N·cos ψ + c_E·sin ψ + ε`` with the heading ψ; the raw row is
  unchanged and its operating point becomes the reference minus the projected
  current. Without a heading for a sample the reference cannot be used (the
  sample is treated as a reference outage).
- **Process noise**: v is a random walk driven by acceleration white noise of
  spectral density ``accel_psd_m2ps3`` (``q_v = psd·dt``); the sensor parameters take
  the paper's tiny ``q_params`` per second (per step of a log at 1 Hz or slower:
  :data:`Q_PARAMS_STEP_S`; they change over weeks); the current is a
  random walk of spectral density ``current_psd_m2ps3`` (it changes over minutes).
- **Learning is per unknown**: the caller says which unknowns the data determine
  (``learn``); the others are held at their value (the prior: the last good
  calibration, else nominal) and taken as known for that sample
  (:mod:`calib.kalman.kernels`). The speed state always moves.
- **Honest noise** (``adaptive=True``): the measurement noises the filter is given
  are what the sensors promise, not what a window of data holds (block means of a
  GNSS speed, a log quantised to 0.1 kn, a yacht's leeway, a lake's current that
  does not move or a bay's that turns). A noise scale λ multiplies both R and the
  current's random walk (the level of what the filter does not know of the sea and the
  sensors, in the proportions configured; the speed's random walk follows the vessel
  and the parameters' is the paper's tuning, neither scaled). λ is the data's own R
  (covariance matching): each learnt-from raw update measures it as
  ``λ̂ = (y² − S_state)/(R_raw + R_ref)``, what the innovation's square leaves once the
  state's share of S is taken off (``S_state = S − λ(R_raw + R_ref)``; the NIS capped,
  λ̂ at least 0: :mod:`calib.kalman.adapt`), and λ is the running mean of λ̂ weighted by
  f = λ(R_raw + R_ref)/S, the share of S the noises make (samples whose S is mostly the
  state's uncertainty, the parameters just re-opened, barely move it), with a memory
  of N_λ = ``adapt_samples`` weights. Its first updates set it (no prior weight), so the
  NIS mean is near 1 within a few updates from any start: block means of a GNSS speed
  and a log quantised to 0.1 kn hold a twentieth to a tenth of a single sample's noise
  variance. λ within the bounds of :mod:`calib.kalman.adapt`. Residuals correlated from
  one sample to the next (GNSS errors over seconds, a tack's log error over minutes)
  hold fewer independent samples than samples: the lag-one correlation ρ of the normalised raw innovations
  (an average over N_λ samples, within [0, :data:`RHO_MAX`]) makes each raw update count
  as ``(1 − ρ)/(1 + ρ)`` of a sample (the AR(1) variance factor of a mean; the
  kernel's ``deweight``), so that P, the σ reported, says what the data determine.
  Both adapt on updates whose speed state was re-acquired for them (learning from
  block means: a GNSS reference), where the configured noises describe single samples
  and not the blocks. Learning sample by sample (a DVL) keeps the configured noises:
  there the speed state carries the samples' memory and the noises are the tuning of
  how fast it learns (scaled to a simulated EMlog's innovations, the water-frame replay
  of docs/REPRODUCTION.md scored 0.18–0.25 m/s against 0.108 with the configured ones).
- **Evidence for an offer** (:attr:`KfCalibrator.param_std_offer`): λ matched to the
  data makes σ honest from the first blocks, before the blocks have shown a change of
  speed, heading or current that tells the parameters apart from one another. A second,
  slow noise scale λ_slow says how much to trust them: it starts at 1 and moves as a
  running mean of the log NIS, ``ln λ_slow += f·(ln NIS_slow − E[ln χ²(1)])/N``,
  N = min(k + :data:`ADAPT_START`, N_λ) (the NIS taken against the innovation variance
  λ_slow gives, within the bounds of :mod:`calib.kalman.adapt`, f its
  noises' share), so it comes down to λ over about N_λ updates, hours of blocks. Both
  are tracked; ``matched_noise`` says which one scales the noises (λ: the σ and NIS
  reported offline; λ_slow: the daemon, whose estimates, gates and offers are then those
  of a filter adapted slowly). The σ an offer is judged on is P's times
  ``√max(λ_slow/scale, 1)``, what P would say with the scale floored at λ_slow (P of
  the parameters scales with the noises once the data determine them).
- **Gating**: an update whose NIS exceeds ``max_nis`` is not applied and reported
  as gated (integrity monitoring decides what a run of them means).
- **Reference outage** (no reference, or no heading with a current): predict, then
  the raw reading updates the speed state only, every unknown held; the operating
  point is then the corrected raw reading (inverse model), so the raw innovation is
  exactly ``corrected(raw) − v̂`` for every model, EM4 included.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from calib.errors import DataError, ModelError
from calib.kalman.adapt import (
    matched_scale,
    slow_scale,
)
from calib.kalman.kernels import check_covariance, condition, scalar_update, to_lists
from calib.kalman.reference import Innovation
from calib.models import AMB_STATES, CURRENT, Layout, Params, check_model, design_row, invert

DEFAULT_R_RAW_MPS2 = 0.0514**2
"""EMlog measurement variance: the Airmar DX900+ specification ±0.1 kn taken as 1σ."""

DEFAULT_R_REF_MPS2 = 0.01**2
"""DVL bottom-track variance (Rowe SeaPILOT ±0.25 % ≈ 0.005 m/s at 2 m/s, doubled)."""

ADAPT_START = 10
"""The slow noise scale's and the innovations' correlation's first steps average over
the samples so far plus this many (a running mean that settles in tens of samples, then
a memory of ``adapt_samples``)."""

SPEED_UNKNOWN_VAR_M2PS2 = 100.0
"""The speed state's variance when nothing is known of it (σ 10 m/s: any vessel's
speed), so that the next measurement sets it: see :meth:`KfCalibrator.reacquire_speed`."""

FRESH_SPEED_VAR_M2PS2 = 0.5 * SPEED_UNKNOWN_VAR_M2PS2
"""A speed state this uncertain before the reference update has been re-acquired: the
update leaves it the reference's speed alone (the fused operating point's condition)."""

MIN_SLOPE2 = 0.25
"""The smallest squared slope ``f'(v)²`` the fused operating point divides the reading's
noise by (a sensor's slope is 1 ± 0.5 inside the envelope)."""

RHO_MAX = 0.95
"""The largest lag-one correlation taken: a raw update counts as at least 1/39 of a
sample."""

Q_PARAMS_STEP_S = 1.0
"""The time step, s, that ``q_params`` is the parameters' random walk over (the paper's
``Q`` per step of its 1-Hz log): a step of ``dt`` adds ``q_params·min(dt, 1 s)/1 s``. A
sensor's scale and bias drift with time, not with its sentences, so a 10-Hz log's walk
as fast per second as a 1-Hz log's; with ``Q`` per step they walked √10 faster, and a
fast log's bias followed the curvature of an error the model has no term for at the
speed of the moment (its current absorbing the difference on a straight leg). A step
longer than this (a gap, a slower log) adds one step's worth, as the paper's filter
does. Against the ground (no current states: the paper's filter) the walk stays the
paper's, per step: there the parameters stand in for the sea's changes too (a tidal
trial replayed so, its 15-Hz log had a 5-min window 1.20 times raw's with the walk per
second, 1.00 per step)."""


@dataclass(frozen=True, slots=True)
class KfConfig:
    """Tuning of the KF-EMx filters (paper section IV-A-4 defaults, plus the current).

    Attributes:
        r_raw_mps2: raw EMlog measurement variance R, (m/s)², from the sensor spec.
        r_ref_mps2: reference measurement variance, (m/s)².
        p0: initial variance of every sensor parameter (paper: P0 = 0.25·I), units².
        q_params: process noise added to each parameter variance per second, at most
            per step (paper: Q = 1e-7·I per step of its 1-Hz log;
            :data:`Q_PARAMS_STEP_S`), parameter units².
        accel_psd_m2ps3: spectral density of the speed random walk, (m/s²)²/Hz.
        current_p0_m2ps2: initial variance of each current component, (m/s)².
        current_psd_m2ps3: spectral density of the current random walk, (m/s)²/s
            (1.7e-5: a standard deviation of 0.1 m/s per 10 minutes, tidal change).
        fused_operating_point: the raw row's operating point is the noise-weighted
            speed of the reference and the corrected reading (module docstring), not the
            reference alone (the paper's).
        adaptive: scale the noises to the innovations and count correlated raw
            updates as fewer samples (the module docstring, "Honest noise").
        adapt_samples: N_λ, the memory of the noise scale and of the correlation, in
            learnt-from samples (60: 20 minutes of 20-s block means, a minute of
            samples at 1 Hz).
        matched_noise: the noises are scaled by λ, matched to the innovations' covariance
            (False: by the slow λ_slow, tracked both ways; the module docstring, "Honest
            noise" and "Evidence for an offer").

    Raises:
        ValueError: a variance that is not positive (process noises may be 0).
    """

    r_raw_mps2: float = DEFAULT_R_RAW_MPS2
    r_ref_mps2: float = DEFAULT_R_REF_MPS2
    p0: float = 0.25
    q_params: float = 1e-7
    accel_psd_m2ps3: float = 0.01
    current_p0_m2ps2: float = 0.25
    current_psd_m2ps3: float = 1.7e-5
    fused_operating_point: bool = True
    adaptive: bool = True
    adapt_samples: float = 60.0
    matched_noise: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.adapt_samples) and self.adapt_samples >= 1.0):
            raise ValueError(f"adapt_samples must be at least 1, got {self.adapt_samples!r}")
        for name in ("r_raw_mps2", "r_ref_mps2", "p0", "current_p0_m2ps2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")
        for name in ("q_params", "accel_psd_m2ps3", "current_psd_m2ps3"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be non-negative and finite, got {value!r}")


class StepResult(NamedTuple):
    """What one :meth:`KfCalibrator.update` did.

    Attributes:
        raw: innovation of the raw reading (None without a usable raw reading).
        ref: innovation of the reference (None when no reference was used).
        raw_gated: the raw update was refused by the NIS gate.
        ref_gated: the reference update was refused by the NIS gate.
        learnt: the unknowns were allowed to move on this sample (reference used).
    """

    raw: Innovation | None
    ref: Innovation | None
    raw_gated: bool
    ref_gated: bool
    learnt: bool


_INF = math.inf


class KfCalibrator:
    """KF-EMx (optionally with current) online: one object per unit under test.

    Per sample call :meth:`update` with the raw reading, the lag-aligned reference
    (None during an outage), the time step and, with a current, the heading at the
    reference's time. Semantics in the module docstring.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        config: tuning (R, P0, Q).
        current: estimate the sea current (two more states).
        params0: initial parameters (default: the ideal sensor, θ = 0).
        current0_mps: initial current (north, east) in m/s (default 0).
        P0: initial covariance over the whole state, shape (n, n) (default: the
            speed and each unknown from ``config``).
        v0_mps: initial speed in m/s.

    Raises:
        ModelError: unknown model, params of another model, bad P0 or x0.
    """

    __slots__ = (
        "_P",
        "_c0",
        "_c1",
        "_gains",
        "_n_adapt",
        "_nu_prev",
        "_params",
        "_w_adapt",
        "_x",
        "config",
        "layout",
        "noise_scale",
        "noise_scale_matched",
        "noise_scale_slow",
    )

    def __init__(
        self,
        model: str = "EM3",
        config: KfConfig | None = None,
        *,
        current: bool = False,
        params0: Params | None = None,
        current0_mps: tuple[float, float] | None = None,
        P0: npt.ArrayLike | None = None,
        v0_mps: float = 0.0,
    ) -> None:
        self.layout = Layout(check_model(model), bool(current))
        self.config = config if config is not None else KfConfig()
        if params0 is not None and params0.model != self.layout.model:
            raise ModelError(f"params0 are {params0.model}, the filter is {self.layout.model}")
        theta = params0.theta if params0 is not None else (0.0,) * len(self.layout.params)
        cur = tuple(current0_mps) if (current and current0_mps is not None) else (0.0, 0.0)
        x0 = [float(v0_mps), *theta, *(cur if current else ())]
        if not all(math.isfinite(v) for v in x0):
            raise ModelError("initial state must be finite")
        n = self.layout.n
        if P0 is None:
            diag = [self.config.p0] * n
            if current:
                diag[-2] = diag[-1] = self.config.current_p0_m2ps2
            M = np.diag(diag)
        else:
            M = np.asarray(P0, dtype=np.float64)
        check_covariance(M, n)
        self._x = x0
        self._P = to_lists(M)
        self._gains: dict[object, list[float]] = {}
        self._params: tuple[tuple[float, ...], Params] | None = None
        self.noise_scale = 1.0
        """The factor on both measurement noises: λ, or λ_slow without
        ``config.matched_noise`` (1 without ``config.adaptive``)."""
        self.noise_scale_matched = 1.0
        """λ: the noise scale matched to the innovations' covariance."""
        self.noise_scale_slow = 1.0
        """λ_slow: the slowly adapted noise scale an offer's σ is floored at."""
        self._c0 = 1.0
        self._c1 = 0.0
        self._nu_prev = math.nan
        self._n_adapt = 0
        self._w_adapt = 0.0

    # -- the per-sample path ------------------------------------------------

    def predict(self, dt_s: float) -> None:
        """Time update over ``dt_s`` seconds (Φ = I): add the process noises (the current's × λ).

        Raises:
            DataError: a negative or non-finite time step.
        """
        if not 0.0 <= dt_s < _INF:
            raise DataError(f"dt_s must be finite and non-negative, got {dt_s!r}")
        P = self._P
        cfg = self.config
        P[0][0] += cfg.accel_psd_m2ps3 * dt_s
        p = len(self.layout.params)
        q = cfg.q_params
        if self.layout.current:  # the water frame (Q_PARAMS_STEP_S)
            q *= min(dt_s, Q_PARAMS_STEP_S) / Q_PARAMS_STEP_S
        for i in range(1, 1 + p):
            P[i][i] += q
        if self.layout.current:
            dq = self.noise_scale * cfg.current_psd_m2ps3 * dt_s
            P[1 + p][1 + p] += dq
            P[2 + p][2 + p] += dq

    def gains(self, learn: bool | Collection[str]) -> list[float]:
        """The gain mask for a set of unknowns that may learn (the speed always may).

        Args:
            learn: True (every unknown), False (none) or the names that may learn.
        """
        key: object = learn if isinstance(learn, bool) else frozenset(learn)
        cached = self._gains.get(key)
        if cached is not None:
            return cached
        lay = self.layout
        g = [1.0] * lay.n if learn is True else [0.0] * lay.n
        g[0] = 1.0
        if not isinstance(learn, bool):
            for name in learn:
                for i in lay.indices(name):
                    g[i] = 1.0
        self._gains[key] = g
        return g

    def update(
        self,
        raw_mps: float | None,
        ref_mps: float | None,
        dt_s: float,
        *,
        heading_cs: tuple[float, float] | None = None,
        learn: bool | Collection[str] = True,
        max_nis: float = _INF,
        scaled: bool = True,
        adapt: bool = True,
    ) -> StepResult:
        """One sample: predict over ``dt_s``, then the reference, then the raw update.

        Args:
            raw_mps: raw EMlog reading in m/s, or None if the UUT gave nothing.
            ref_mps: lag-aligned reference speed in m/s (along the hull; over the
                ground with a current), or None during an outage.
            dt_s: seconds since the previous call (≥ 0).
            heading_cs: ``(cos ψ, sin ψ)`` of the heading at the reference's time;
                needed when the filter has a current.
            learn: which unknowns may move (True: all, False: none; the speed state
                always moves).
            max_nis: NIS gate for both updates (``inf``: no gate).
            scaled: the measurement noises are the configured ones times the noise
                scale λ (False: the configured ones, what a single sample holds when λ
                was adapted to block means: the samples between blocks).
            adapt: with ``config.adaptive``, a learnt update whose speed state was
                re-acquired for it adapts the noise scale and the correlation (False:
                they stay, as learning sample by sample keeps the configured noises).

        Returns:
            The innovations and what was applied.

        Raises:
            DataError: a negative or non-finite time step.
        """
        self.predict(dt_s)
        lay = self.layout
        x, P = self._x, self._P
        lam = self.noise_scale if scaled else 1.0
        n = lay.n
        use_ref = ref_mps is not None and (not lay.current or heading_cs is not None)
        inn_ref: Innovation | None = None
        ref_gated = False
        gains = self.gains(learn) if use_ref else self.gains(False)
        v_op = math.nan
        # the speed state knows nothing but what this reference will tell it
        fresh = P[0][0] >= FRESH_SPEED_VAR_M2PS2
        if use_ref and ref_mps is not None:
            h_ref = [0.0] * n
            h_ref[0] = 1.0
            if lay.current and heading_cs is not None:
                h_ref[-2], h_ref[-1] = heading_cs
            y, s, applied = scalar_update(
                x, P, h_ref, ref_mps, lam * self.config.r_ref_mps2, gains, max_nis
            )
            inn_ref = Innovation(y, s, y * y / s)
            if applied:
                v_op = ref_mps
                if lay.current and heading_cs is not None:
                    v_op -= x[-2] * heading_cs[0] + x[-1] * heading_cs[1]
                if raw_mps is not None and fresh and self.config.fused_operating_point:
                    v_op = self._fused(raw_mps)
            else:
                ref_gated = True
                gains = self.gains(False)
        if raw_mps is None:
            return StepResult(
                None, inn_ref, False, ref_gated, inn_ref is not None and not ref_gated
            )
        if math.isnan(v_op):
            v_op = self.corrected(raw_mps)
            if not math.isfinite(v_op):
                return StepResult(None, inn_ref, False, ref_gated, False)
        h_raw = [0.0] * n
        h_raw[0] = 1.0
        h_raw[1 : 1 + len(lay.params)] = design_row(lay.model, v_op)
        learning = use_ref and not ref_gated and any(gains[1:])
        y, s, applied = scalar_update(
            x,
            P,
            h_raw,
            raw_mps,
            lam * self.config.r_raw_mps2,
            gains,
            max_nis,
            self.correlation if learning else 1.0,
        )
        learnt = use_ref and not ref_gated and applied
        if learnt and learning and fresh and adapt and self.config.adaptive:
            self._adapt(y, s)
        return StepResult(Innovation(y, s, y * y / s), inn_ref, not applied, ref_gated, learnt)

    def _fused(self, raw_mps: float) -> float:
        """The speed through the water from the speed state (just updated with the
        reference) and the corrected reading, weighted by their variances: the operating
        point the raw innovation is orthogonal to."""
        v = self._x[0]
        v_raw = self.corrected(raw_mps)
        if not math.isfinite(v_raw):
            return v
        a, m, _ = self.amb()
        slope = 1.0 + m + 2.0 * a * v
        var_raw = self.noise_scale * self.config.r_raw_mps2 / max(slope * slope, MIN_SLOPE2)
        w = var_raw / (var_raw + self._P[0][0])
        return w * v + (1.0 - w) * v_raw

    @property
    def correlation(self) -> float:
        """Samples per independent sample of the raw innovations, ``(1 + ρ)/(1 − ρ)``."""
        if not self.config.adaptive:
            return 1.0
        rho = min(max(self._c1 / self._c0, 0.0), RHO_MAX) if self._c0 > 0.0 else 0.0
        return (1.0 + rho) / (1.0 - rho)

    def _adapt(self, y: float, s: float) -> None:
        """The noise scales and the innovations' correlation after one learnt raw update
        (module docstring, "Honest noise" and "Evidence for an offer"): one outlier, its
        NIS capped at :data:`~calib.kalman.adapt.ADAPT_NIS_CAP`, moves λ by at most
        ``(ADAPT_NIS_CAP − 1)·f/W`` of itself, W the weights in memory."""
        self._n_adapt += 1
        a = 1.0 / min(self._n_adapt + ADAPT_START, self.config.adapt_samples)
        r_sum = self.config.r_raw_mps2 + self.config.r_ref_mps2
        s_state = s - self.noise_scale * r_sum  # the state's share of S
        lam, self._w_adapt = matched_scale(
            self.noise_scale_matched,
            self._w_adapt,
            y,
            (s, s_state, r_sum),
            self.config.adapt_samples,
        )
        self.noise_scale_matched = lam
        self.noise_scale_slow = slow_scale(self.noise_scale_slow, y, (s, s_state, r_sum), a)
        self.noise_scale = lam if self.config.matched_noise else self.noise_scale_slow
        nu = y / math.sqrt(s)
        self._c0 += a * (nu * nu - self._c0)
        if self._nu_prev == self._nu_prev:
            self._c1 += a * (nu * self._nu_prev - self._c1)
        self._nu_prev = nu

    def corrected(self, raw_mps: float) -> float:
        """The raw reading corrected with the current parameters (inverse model), m/s."""
        a, m, b = self.amb()
        return invert(a, m, b, raw_mps)

    def amb(self) -> tuple[float, float, float]:
        """The parameters ``a``, ``m`` and ``b`` now (0.0 for one the model has not)."""
        x, (ia, im, ib) = self._x, AMB_STATES[self.layout.model]
        return (x[ia] if ia else 0.0, x[im] if im else 0.0, x[ib] if ib else 0.0)

    # -- covariance management ------------------------------------------------

    def reopen(self, unknowns: Collection[str]) -> None:
        """Forget what is known of some unknowns: their variance back to the prior.

        Their cross-covariances are zeroed and their values kept (a sensor swap or a
        calibration that stopped fitting: learn them again from the data).
        """
        lay = self.layout
        P = self._P
        for name in unknowns:
            var = self.config.current_p0_m2ps2 if name == CURRENT else self.config.p0
            for i in lay.indices(name):
                for j in range(lay.n):
                    P[i][j] = P[j][i] = 0.0
                P[i][i] = var

    def widen(self, added: dict[str, float]) -> None:
        """Add variance to some unknowns, each up to its prior (a change of known size).

        Args:
            added: the variance to add by unknown's name (parameter units²; the
                current's m²/s²); the values and the cross-covariances are kept.
        """
        lay = self.layout
        P = self._P
        for name, var in added.items():
            if not (math.isfinite(var) and var > 0.0):
                continue
            prior = self.config.current_p0_m2ps2 if name == CURRENT else self.config.p0
            for i in lay.indices(name):
                P[i][i] = max(P[i][i], min(P[i][i] + var, prior))

    def age_current(self, elapsed_s: float) -> None:
        """The current's random walk over ``elapsed_s`` the filter did not run.

        Each component's variance grows by ``current_psd_m2ps3 · elapsed_s``, up to its
        prior (a current restored from hours ago is no longer known, and should not be
        trusted as if it were). A negative or NaN ``elapsed_s`` (saved by a clock ahead of
        the data's) is an age unknown: the variance goes to its prior. Nothing happens
        without current states.
        """
        lay = self.layout
        if not lay.current or elapsed_s == 0.0:
            return
        cfg = self.config
        grow = cfg.current_psd_m2ps3 * elapsed_s if elapsed_s > 0.0 else math.inf
        for i in (lay.n - 2, lay.n - 1):
            var = self._P[i][i]
            self._P[i][i] = max(var, min(var + grow, cfg.current_p0_m2ps2))

    def copy(self) -> KfCalibrator:
        """An independent copy of the filter: its state, covariance, noise scale and the
        innovations' correlation (a shadow whose covariance answers "what would the
        filter know had it forgotten …", :meth:`follow`)."""
        other = KfCalibrator.__new__(KfCalibrator)
        other.layout, other.config = self.layout, self.config
        other._P = [list(row) for row in self._P]
        other._gains, other._params = {}, None
        other._x = list(self._x)
        other.follow(self)
        return other

    def follow(self, other: KfCalibrator) -> None:
        """Take ``other``'s state mean, noise scale and correlation, keeping this
        filter's own covariance: the next update then uses the same measurement rows
        and noises as ``other``'s, and only what is known of the state differs."""
        self._x = list(other._x)
        self.noise_scale = other.noise_scale
        self.noise_scale_matched = other.noise_scale_matched
        self.noise_scale_slow = other.noise_scale_slow
        self._c0, self._c1 = other._c0, other._c1
        self._nu_prev, self._n_adapt = other._nu_prev, other._n_adapt
        self._w_adapt = other._w_adapt

    def condition(self, values: Mapping[str, float]) -> None:
        """Hold some parameters at given values, every other state moved to its Gaussian
        conditional on them (:func:`calib.kalman.kernels.condition`): a parameter the data
        do not determine, reported at its prior, leaves the others where the data put them
        given that prior (what least squares holding it fits), not where a few samples
        moved all of them together.

        Raises:
            ModelError: a name that is not a parameter of the filter, or a value that is
                not finite.
        """
        for name, value in values.items():
            if name not in self.layout.params or not math.isfinite(value):
                raise ModelError(
                    f"cannot hold {name!r} at {value!r}: not a finite value of a "
                    f"parameter of {self.layout.model}"
                )
            condition(self._x, self._P, self.layout.indices(name)[0], value)
        self._params = None

    def reacquire_speed(self) -> None:
        """Forget the speed state: :data:`SPEED_UNKNOWN_VAR_M2PS2`, its correlations
        dropped, so that the next measurement sets the speed (after the state lost the
        reference, or at a start from saved parameters: the speed then is not the
        speed when they were saved)."""
        P = self._P
        for j in range(self.layout.n):
            P[0][j] = P[j][0] = 0.0
        P[0][0] = SPEED_UNKNOWN_VAR_M2PS2

    def restart(self, params: Params) -> None:
        """Start the parameters again from ``params`` with their prior variance.

        The speed and the current are kept.

        Raises:
            ModelError: parameters of another model.
        """
        if params.model != self.layout.model:
            raise ModelError(f"params are {params.model}, the filter is {self.layout.model}")
        p = len(self.layout.params)
        self._x[1 : 1 + p] = list(params.theta)
        self.reopen(self.layout.params)

    # -- read-outs ----------------------------------------------------------

    @property
    def x(self) -> tuple[float, ...]:
        """The state mean (a copy), in :attr:`Layout.states` order."""
        return tuple(self._x)

    def covariance(self) -> list[list[float]]:
        """The full state covariance P (a copy, n rows of n floats)."""
        return [list(row) for row in self._P]

    @property
    def params(self) -> Params:
        """The current parameter estimate θ̂."""
        theta = tuple(self._x[1 : 1 + len(self.layout.params)])
        memo = self._params
        if memo is None or memo[0] != theta:
            memo = self._params = (theta, Params.from_theta(self.layout.model, theta))
        return memo[1]

    @property
    def param_std(self) -> dict[str, float]:
        """Standard deviation of each parameter from P, by short name."""
        P = self._P
        return {name: math.sqrt(P[1 + i][1 + i]) for i, name in enumerate(self.layout.params)}

    @property
    def param_std_offer(self) -> dict[str, float]:
        """The standard deviations an offer is judged on: :attr:`param_std` with the scale
        floored at λ_slow (module docstring, "Evidence for an offer")."""
        k = math.sqrt(max(self.noise_scale_slow / self.noise_scale, 1.0))
        return {name: k * sd for name, sd in self.param_std.items()}

    @property
    def current_mps(self) -> tuple[float, float] | None:
        """The current estimate (north, east) in m/s, None without current states."""
        return (self._x[-2], self._x[-1]) if self.layout.current else None

    @property
    def current_std_mps(self) -> tuple[float, float] | None:
        """Standard deviations of the current components in m/s."""
        if not self.layout.current:
            return None
        P = self._P
        return (math.sqrt(P[-2][-2]), math.sqrt(P[-1][-1]))

    @property
    def speed_mps(self) -> float:
        """The speed state v̂ (through the water), m/s."""
        return self._x[0]

    @property
    def speed_std_mps(self) -> float:
        """Standard deviation of v̂ in m/s."""
        return math.sqrt(self._P[0][0])
