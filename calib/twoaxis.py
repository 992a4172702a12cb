"""The two-axis error model: a log that reports the forward and the athwart speed.

A dual-axis EMlog (an Airmar DX900+, a Ben Marine Alize sending ``$--VBW``) measures
the water's velocity along two axes of its own. Mounted a little off the keel line,
its axes are turned by the **misalignment** α from the hull's (α > 0: the sensor's
forward axis points to starboard of the bow). In the hull frame (x forward, y to
starboard) the speed through the water is ``(u, w)`` (surge, sway); the sensor sees

    u_s =  u·cos α + w·sin α        (along its own forward axis)
    w_s = −u·sin α + w·cos α        (along its own starboard axis)

and reads

    raw_L = a·u_s² + (1 + m)·u_s + b      (the longitudinal: EM1–EM4 of calib.models)
    raw_T = (1 + m_t)·w_s + b_t            (the transverse: a scale and a bias)

A misalignment of 3° at 3 m/s puts ``−sin α·u`` = 0.16 m/s of phantom leeway on the
transverse axis and takes ``1 − cos α`` = 0.14 % off the forward one.

**The water frame.** A ground-referenced reference (a DVL's bottom track, or GNSS
velocity turned into the hull frame with the heading ψ) gives the ground velocity
``(g_f, g_s)`` forward and to starboard. With the sea current ``c = (c_N, c_E)``
shared by both axes (the same two states projected onto each)

    u = g_f − c_N·cos ψ − c_E·sin ψ
    w = g_s + c_N·sin ψ − c_E·cos ψ

**Least squares** (:func:`fit_two_axis`): Gauss–Newton on both axes' residuals
stacked, each axis weighted by the inverse of its residual variance (estimated from
a first fit), over the unknowns the data determine. Standard errors are
``√diag((JᵀWJ)⁻¹)`` inflated by the larger of the two axes' residual correlation
factors (:func:`calib.metrics.correlation_factor`), as :mod:`calib.lsq` does.

**Identifiability** (:func:`judge_two_axis`), in order, in the words of
:mod:`calib.excitation` where the longitudinal rules are the same:

1. the longitudinal scale (``m``, and ``a`` for EM4) needs the speed through the
   water to vary (EM2: its RMS), as on one axis;
2. the current needs the heading to cover ``min_heading_sectors`` 45° sectors;
   without it the current, the longitudinal bias and the **transverse bias** are
   refused: on a steady heading each axis's bias and the current projected on it are
   one unknown, and a nuisance offset per axis takes their sum;
3. the **misalignment** needs the speed through the water to vary: its signature on
   the transverse axis is ``−(1 + m_t)·sin α·u``, which at constant u is a constant
   — the transverse bias and the current across the hull again. A straight run
   at one throttle setting refuses it, with the reason;
4. the **transverse scale** needs the transverse speed through the water (the sway
   of turns) to vary by ``min_transverse_std_mps``; without it the misalignment is
   refused too: its athwart signature is ``(1 + m_t)·sin α·u``, so a transverse
   scale held where the log's differs by Δm would put ``Δm·α`` into α (a 3°
   misalignment of a log whose axes' scales differ by 0.11, learnt on a transit:
   3.41°);
5. enough samples (``min_samples_per_param`` per unknown), then the information:
   the standard deviation of each remaining unknown from the information matrix
   must be under its bound; the worst offender is refused and the rest judged
   again (a transverse scale refused so takes the misalignment with it). In
   steady circles and on transits the sway follows the surge: only the
   figure-8's alternating turns, whose sway swings without the surge, determine
   the transverse scale and with it the misalignment.

An unknown refused is held at its prior (the given parameters, else the ideal
sensor; zero current) and its σ is not reported.

**Kalman filter** (:func:`kf_two_axis`): the same unknowns as states (the current a
random walk, the sensor's parameters nearly constant), the two readings a vector
measurement with the reference's ground velocity taken as known (a DVL's millimetre
noise), extended about the state; the unknowns the window refuses are held at their
prior as in least squares.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from calib.errors import DataError, ModelError
from calib.excitation import (
    DEFAULT_RULE,
    N_SECTORS,
    ExcitationRule,
    Verdict,
    heading_sectors,
)
from calib.metrics import correlation_factor
from calib.models import (
    CURRENT,
    PARAM_NAMES,
    FloatArray,
    ModelName,
    Params,
    check_model,
    correct_array,
    forward_array,
)

ALPHA = "alpha"
"""The unknown name of the misalignment."""
M_T = "m_t"
"""The unknown name of the transverse scale error."""
B_T = "b_t"
"""The unknown name of the transverse bias."""

TRANSVERSE_NAMES: tuple[str, ...] = (ALPHA, M_T, B_T)
"""The two-axis model's unknowns beyond the longitudinal model's, in their order."""

TIE_HELD_SCALE = True
"""A transverse scale the data do not determine follows the longitudinal scale (one
coil's field drives both electrode pairs of an EM sensor, so their gains move
together), rather than the prior's: the athwart speed is then corrected by the
gain the forward axis shows."""

MAX_MISALIGN_DEG = 20.0
"""The largest misalignment a two-axis calibration may hold, degrees (a sensor turned
further is mounted wrongly, not misaligned)."""


@dataclass(frozen=True, slots=True)
class TwoAxisParams:
    """The parameters of a two-axis log.

    Attributes:
        longitudinal: the forward axis's error model (EM1–EM4) on the sensor's axis.
        misalign_rad: α, the sensor's forward axis from the bow, rad (> 0: to starboard).
        m_t: the transverse scale error, dimensionless.
        b_t_mps: the transverse bias, m/s.

    Raises:
        ModelError: a non-finite value, or a misalignment beyond :data:`MAX_MISALIGN_DEG`.
    """

    longitudinal: Params
    misalign_rad: float = 0.0
    m_t: float = 0.0
    b_t_mps: float = 0.0

    def __post_init__(self) -> None:
        for name in ("misalign_rad", "m_t", "b_t_mps"):
            if not math.isfinite(getattr(self, name)):
                raise ModelError(f"two-axis parameter {name} is not finite")
        if abs(self.misalign_rad) > math.radians(MAX_MISALIGN_DEG):
            raise ModelError(
                f"misalignment {math.degrees(self.misalign_rad):.1f}° beyond ±{MAX_MISALIGN_DEG:g}°"
            )

    @property
    def model(self) -> ModelName:
        """The longitudinal error model."""
        return self.longitudinal.model

    @property
    def misalign_deg(self) -> float:
        """α in degrees."""
        return math.degrees(self.misalign_rad)

    def as_dict(self) -> dict[str, float]:
        """The longitudinal parameters by short name, then ``misalign_deg``, ``m_t``, ``b_t``."""
        return self.longitudinal.as_dict() | {
            "misalign_deg": self.misalign_deg,
            M_T: self.m_t,
            B_T: self.b_t_mps,
        }

    def forward(self, u_mps: npt.ArrayLike, w_mps: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """What the log reads for the speed through the water (u forward, w to starboard).

        Returns:
            (longitudinal, transverse) readings, m/s, noise-free.
        """
        u = np.asarray(u_mps, dtype=np.float64)
        w = np.asarray(w_mps, dtype=np.float64)
        ca, sa = math.cos(self.misalign_rad), math.sin(self.misalign_rad)
        us = u * ca + w * sa
        ws = -u * sa + w * ca
        return forward_array(self.longitudinal, us), np.asarray(
            (1.0 + self.m_t) * ws + self.b_t_mps, dtype=np.float64
        )

    def correct(
        self, raw_l_mps: npt.ArrayLike, raw_t_mps: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """The speed through the water in the hull frame for two readings: each axis's
        inverse (the longitudinal one that of :mod:`calib.models`), then the sensor's
        axes turned back by α.

        Returns:
            (forward, starboard) speeds through the water, m/s (``nan`` where an axis
            cannot be inverted: a gain ``1 + m ≤ 0``).
        """
        us = correct_array(self.longitudinal, raw_l_mps)
        gain = 1.0 + self.m_t
        raw_t = np.asarray(raw_t_mps, dtype=np.float64)
        ws = (raw_t - self.b_t_mps) / gain if gain > 0.0 else np.full_like(raw_t, np.nan)
        ca, sa = math.cos(self.misalign_rad), math.sin(self.misalign_rad)
        return (
            np.asarray(us * ca - ws * sa, dtype=np.float64),
            np.asarray(us * sa + ws * ca, dtype=np.float64),
        )


def leeway_deg(u_mps: npt.ArrayLike, w_mps: npt.ArrayLike) -> FloatArray:
    """The leeway (drift) angle of the speed through the water, degrees: the angle
    from the bow to the water's velocity over the hull, positive when the hull moves
    to starboard of its heading (``atan2(w, u)``)."""
    return np.asarray(
        np.degrees(np.arctan2(np.asarray(w_mps, float), np.asarray(u_mps, float))),
        dtype=np.float64,
    )


def water_velocity(
    ref_fwd_mps: npt.ArrayLike,
    ref_stb_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    current_mps: tuple[float, float] | FloatArray | None,
) -> tuple[FloatArray, FloatArray]:
    """The speed through the water in the hull frame a ground reference implies:
    ``(g_f − c_N·cos ψ − c_E·sin ψ, g_s + c_N·sin ψ − c_E·cos ψ)``.

    Args:
        ref_fwd_mps: ground speed forward, m/s, shape (N,).
        ref_stb_mps: ground speed to starboard, m/s, shape (N,).
        heading_deg: headings, degrees, shape (N,).
        current_mps: (north, east) for every sample, or shape (N, 2); None: no current.
    """
    gf = np.asarray(ref_fwd_mps, dtype=np.float64)
    gs = np.asarray(ref_stb_mps, dtype=np.float64)
    if current_mps is None:
        return gf, gs
    c = np.asarray(current_mps, dtype=np.float64)
    cn, ce = (c[..., 0], c[..., 1])
    psi = np.radians(np.asarray(heading_deg, dtype=np.float64))
    cp, sp = np.cos(psi), np.sin(psi)
    return (
        np.asarray(gf - cn * cp - ce * sp, dtype=np.float64),
        np.asarray(gs + cn * sp - ce * cp, dtype=np.float64),
    )


@dataclass(frozen=True, slots=True)
class TwoAxisRule:
    """The thresholds of the two-axis identifiability rule (module docstring).

    Attributes:
        base: the one-axis rule: the longitudinal's thresholds, the heading sectors
            the current needs, the samples per unknown, the bounds of the
            longitudinal parameters and of the current.
        min_speed_std_misalign_mps: least spread of the speed through the water
            (forward) for the misalignment, m/s.
        min_transverse_std_mps: least spread of the transverse speed through the
            water for the transverse scale, m/s.
        max_std_misalign_deg: largest standard deviation of a determined α, degrees.
        max_std_m_t: largest standard deviation of a determined transverse scale.
        max_std_b_t_mps: largest standard deviation of a determined transverse bias, m/s.

    Raises:
        ValueError: a threshold out of range.
    """

    base: ExcitationRule = DEFAULT_RULE
    min_speed_std_misalign_mps: float = 0.1
    min_transverse_std_mps: float = 0.03
    max_std_misalign_deg: float = 0.15
    max_std_m_t: float = 0.05
    max_std_b_t_mps: float = 0.03

    def __post_init__(self) -> None:
        if not (self.min_speed_std_misalign_mps >= 0.0 and self.min_transverse_std_mps >= 0.0):
            raise ValueError("speed thresholds must be non-negative")
        for name in ("max_std_misalign_deg", "max_std_m_t", "max_std_b_t_mps"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive")

    def max_std(self, unknown: str) -> float:
        """The largest standard deviation of a determined unknown, in the unit its
        estimate is held in (α in rad)."""
        if unknown == ALPHA:
            return math.radians(self.max_std_misalign_deg)
        if unknown == M_T:
            return self.max_std_m_t
        if unknown == B_T:
            return self.max_std_b_t_mps
        return self.base.max_std(unknown)


DEFAULT_TWO_AXIS_RULE = TwoAxisRule()

_LABEL = {
    "a": "curvature",
    "m": "scale",
    "b": "bias",
    ALPHA: "misalignment",
    M_T: "transverse scale",
    B_T: "transverse bias",
    CURRENT: "current",
}
_UNIT = {"a": " s/m", "m": "", "b": " m/s", ALPHA: "°", M_T: "", B_T: " m/s", CURRENT: " m/s"}

# indices of the full unknown vector
_A, _M, _B, _AL, _MT, _BT, _CN, _CE, _DL, _DT = range(10)
_N_FIXED = 10
_PARAM_INDEX = {"a": _A, "m": _M, "b": _B, ALPHA: _AL, M_T: _MT, B_T: _BT}
_MAX_ITER = 30


_ALPHA_WITH_SCALE = (
    "misalignment not separable from the transverse scale: its athwart signature is "
    "(1 + m_t)·sin α times the forward speed, and the transverse scale is not determined"
)


def unknowns_of(model: ModelName, current: bool) -> tuple[str, ...]:
    """The unknowns of a two-axis calibration: the longitudinal parameters, α, the
    transverse scale and bias, then the current."""
    return (*PARAM_NAMES[model], *TRANSVERSE_NAMES, *((CURRENT,) if current else ()))


@dataclass(frozen=True, slots=True)
class TwoAxisIdent:
    """The verdict on every unknown of a two-axis window.

    Attributes:
        model: the longitudinal model.
        current: whether a current is estimated.
        verdicts: one per unknown, in :func:`unknowns_of` order.
        nuisance_offset: an offset per axis took the biases and the current together.
        speed_std_mps: spread of the forward speed through the water, m/s.
        transverse_std_mps: spread of the transverse speed through the water, m/s.
        heading_sectors: 45° sectors covered.
        n_samples: samples per axis.
    """

    model: ModelName
    current: bool
    verdicts: tuple[Verdict, ...]
    nuisance_offset: bool
    speed_std_mps: float
    transverse_std_mps: float
    heading_sectors: int
    n_samples: int

    @property
    def determined(self) -> tuple[str, ...]:
        """The unknowns the window determines."""
        return tuple(v.unknown for v in self.verdicts if v.determined)

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """The unknowns it does not determine."""
        return tuple(v.unknown for v in self.verdicts if not v.determined)

    @property
    def reason(self) -> str:
        """Why some unknowns are not determined, each reason once (empty when all are)."""
        seen: list[str] = []
        for v in self.verdicts:
            if not v.determined and v.reason not in seen:
                seen.append(v.reason)
        return "; ".join(seen)

    def verdict(self, unknown: str) -> Verdict:
        """The verdict on one unknown.

        Raises:
            ModelError: not an unknown of this window.
        """
        for v in self.verdicts:
            if v.unknown == unknown:
                return v
        raise ModelError(f"{unknown!r} is not an unknown of this two-axis window")


class _Problem:
    """The data of one two-axis fit, and its residuals and Jacobian at a point."""

    def __init__(
        self,
        gf: FloatArray,
        gs: FloatArray,
        raw_l: FloatArray,
        raw_t: FloatArray,
        psi: FloatArray,
        basis: FloatArray | None,
    ) -> None:
        self.gf, self.gs, self.raw_l, self.raw_t = gf, gs, raw_l, raw_t
        self.cos_h, self.sin_h = np.cos(psi), np.sin(psi)
        self.basis = basis
        """Each sample's weight on each current node, shape (N, K) (None: one current)."""
        self.n_blocks = 1 if basis is None else int(basis.shape[1])
        self.scale = np.ones(2)
        """Each axis's weight, 1/σ (longitudinal, transverse)."""
        self.tie = False
        """The transverse scale is held at the longitudinal one (:data:`TIE_HELD_SCALE`)."""

    def gain_t(self, x: FloatArray) -> float:
        """The transverse gain ``1 + m_t`` (``1 + m`` when tied)."""
        return 1.0 + float(x[_M] if self.tie else x[_MT])

    def size(self) -> int:
        return _N_FIXED + 2 * (self.n_blocks - 1)

    def current_at(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self.basis is None:
            return np.full(self.gf.size, x[_CN]), np.full(self.gf.size, x[_CE])
        cn = self.basis @ np.concatenate([[x[_CN]], x[_N_FIXED::2]])
        ce = self.basis @ np.concatenate([[x[_CE]], x[_N_FIXED + 1 :: 2]])
        return np.asarray(cn, dtype=np.float64), np.asarray(ce, dtype=np.float64)

    def water(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        cn, ce = self.current_at(x)
        u = self.gf - cn * self.cos_h - ce * self.sin_h
        w = self.gs + cn * self.sin_h - ce * self.cos_h
        return np.asarray(u, dtype=np.float64), np.asarray(w, dtype=np.float64)

    def residuals(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Unweighted residuals (longitudinal, transverse)."""
        u, w = self.water(x)
        ca, sa = math.cos(x[_AL]), math.sin(x[_AL])
        us, ws = u * ca + w * sa, -u * sa + w * ca
        pl = (x[_A] * us + 1.0 + x[_M]) * us + x[_B] + x[_DL]
        pt = self.gain_t(x) * ws + x[_BT] + x[_DT]
        return self.raw_l - pl, self.raw_t - pt

    def jacobian(self, x: FloatArray) -> FloatArray:
        """∂(prediction)/∂x, both axes stacked, weighted, shape (2N, K)."""
        u, w = self.water(x)
        n = u.size
        ca, sa = math.cos(x[_AL]), math.sin(x[_AL])
        us, ws = u * ca + w * sa, -u * sa + w * ca
        slope = 2.0 * x[_A] * us + 1.0 + x[_M]
        gain_t = self.gain_t(x)
        c_pa = self.cos_h * ca - self.sin_h * sa  # cos(ψ + α)
        s_pa = self.sin_h * ca + self.cos_h * sa  # sin(ψ + α)
        one = np.ones(n)
        jl = np.zeros((n, self.size()))
        jt = np.zeros((n, self.size()))
        jl[:, _A], jl[:, _M], jl[:, _B], jl[:, _DL] = us * us, us, one, one
        jl[:, _AL] = slope * ws
        jl[:, _CN], jl[:, _CE] = -slope * c_pa, -slope * s_pa
        jt[:, _M if self.tie else _MT], jt[:, _BT], jt[:, _DT] = ws, one, one
        jt[:, _AL] = -gain_t * us
        jt[:, _CN], jt[:, _CE] = gain_t * s_pa, -gain_t * c_pa
        if self.basis is not None:
            base = (jl[:, _CN].copy(), jl[:, _CE].copy(), jt[:, _CN].copy(), jt[:, _CE].copy())
            for k in range(self.n_blocks):
                phi = self.basis[:, k]
                cols = (_CN, _CE) if k == 0 else (_N_FIXED + 2 * (k - 1), _N_FIXED + 2 * k - 1)
                jl[:, cols[0]], jl[:, cols[1]] = phi * base[0], phi * base[1]
                jt[:, cols[0]], jt[:, cols[1]] = phi * base[2], phi * base[3]
        return np.vstack([jl * self.scale[0], jt * self.scale[1]])

    def weighted(self, x: FloatArray) -> FloatArray:
        rl, rt = self.residuals(x)
        return np.concatenate([rl * self.scale[0], rt * self.scale[1]])


def _solve(problem: _Problem, x0: FloatArray, free: list[int]) -> FloatArray:
    """Gauss–Newton over the ``free`` unknowns."""
    x = x0.copy()
    if not free:
        return x
    for _ in range(_MAX_ITER):
        r = problem.weighted(x)
        jf = problem.jacobian(x)[:, free]
        step = np.linalg.lstsq(jf, r, rcond=None)[0]
        x[free] += step
        if float(np.max(np.abs(step))) < 1e-12 * (1.0 + float(np.max(np.abs(x[free])))):
            break
    return x


def _index(unknown: str, n_blocks: int) -> list[int]:
    if unknown == CURRENT:
        return [_CN, _CE, *range(_N_FIXED, _N_FIXED + 2 * (n_blocks - 1))]
    return [_PARAM_INDEX[unknown]]


def _free_indices(determined: Sequence[str], offset: bool, n_blocks: int) -> list[int]:
    free = sorted(i for u in determined for i in _index(u, n_blocks))
    if offset:
        free += [_DL, _DT]
    return sorted(set(free))


def _spread(x: FloatArray) -> float:
    return float(np.std(x)) if x.size else 0.0


def judge_two_axis(
    model: ModelName,
    u_mps: FloatArray,
    w_mps: FloatArray,
    raw_l_mps: FloatArray,
    heading_deg: FloatArray,
    *,
    current: bool,
    info_of: _Problem | None = None,
    x: FloatArray | None = None,
    rule: TwoAxisRule = DEFAULT_TWO_AXIS_RULE,
    outside: dict[str, str] | None = None,
) -> TwoAxisIdent:
    """The two-axis identifiability rule on one window (module docstring, rules 1–5).

    Args:
        model: the longitudinal model.
        u_mps: forward speed through the water (at the current estimate), m/s.
        w_mps: transverse speed through the water, m/s.
        raw_l_mps: the longitudinal readings (the spread of rule 1 is theirs, as on
            one axis), m/s.
        heading_deg: headings, degrees.
        current: whether the current is an unknown.
        info_of: the weighted problem whose information matrix rule 5 reads (None:
            rules 1–4 only).
        x: the point at which rule 5 takes the Jacobian.
        rule: the thresholds.
        outside: unknowns refused beforehand, with the reason (an estimate outside
            the envelope, :data:`ENVELOPE`).
    """
    unknowns = unknowns_of(model, current)
    base = rule.base
    refused: dict[str, str] = dict(outside or {})
    std_raw = _spread(raw_l_mps)
    std_u, std_w = _spread(u_mps), _spread(w_mps)
    rms_raw = float(np.sqrt(np.mean(raw_l_mps * raw_l_mps))) if raw_l_mps.size else 0.0
    scale: list[str] = [k for k in ("a", "m") if k in unknowns]
    if model == "EM2":
        if rms_raw < base.min_speed_rms_mps:
            refused["m"] = (
                f"scale not determinable: speed through water too low (rms {rms_raw:.2f} m/s)"
            )
    elif scale and std_raw < base.min_speed_std_mps:
        why = (
            "scale not determinable: speed through water nearly constant "
            f"(spread {std_raw:.2f} m/s)"
        )
        for k in scale:
            refused[k] = why
    sectors = heading_sectors(heading_deg) if heading_deg.size else 0
    offset = False
    if current and sectors < base.min_heading_sectors:
        refused[CURRENT] = (
            f"current not separable from bias: heading covered {sectors} of {N_SECTORS} sectors"
        )
    if CURRENT in refused:
        offset = True
        for k, label in (("b", "bias"), (B_T, "transverse bias")):
            if k in unknowns:
                refused[k] = (
                    f"{label} not separable from the current: heading covered "
                    f"{sectors} of {N_SECTORS} sectors"
                )
    if std_u < rule.min_speed_std_misalign_mps:
        refused[ALPHA] = (
            "misalignment not separable from the transverse bias and the current: "
            f"speed through water nearly constant (spread {std_u:.2f} m/s)"
        )
    if std_w < rule.min_transverse_std_mps:
        refused[M_T] = (
            "transverse scale not determinable: transverse speed through water "
            f"nearly constant (spread {std_w:.3f} m/s)"
        )
    if M_T in refused and ALPHA not in refused:
        refused[ALPHA] = _ALPHA_WITH_SCALE
    free = [k for k in unknowns if k not in refused]
    n = int(u_mps.size)
    stds: dict[str, float] = {}
    n_blocks = info_of.n_blocks if info_of is not None else 1
    n_cols = len(_free_indices(free, offset, n_blocks))
    if free and 2 * n < base.min_samples_per_param * n_cols:
        why = f"too few samples ({2 * n} < {base.min_samples_per_param * n_cols})"
        for k in free:
            refused[k] = why
        free = []
    if info_of is not None and x is not None and free:
        jac = info_of.jacobian(x)
        while free:
            cols = _free_indices(free, offset, n_blocks)
            info = jac[:, cols].T @ jac[:, cols]
            try:
                cov = np.linalg.inv(info)
                diag = np.sqrt(np.maximum(np.diag(cov), 0.0))
            except np.linalg.LinAlgError:
                diag = np.full(len(cols), math.inf)
            where = {c: i for i, c in enumerate(cols)}
            stds = {k: max(float(diag[where[i]]) for i in _index(k, n_blocks)) for k in free}
            ratios = {k: stds[k] / rule.max_std(k) for k in free}
            worst = max(free, key=lambda k: ratios[k])
            if ratios[worst] <= 1.0:
                break
            sd = stds[worst]
            shown = math.degrees(sd) if worst == ALPHA else sd
            bound = rule.max_std(worst)
            bound = math.degrees(bound) if worst == ALPHA else bound
            refused[worst] = (
                f"{_LABEL[worst]} not determinable: weak excitation "
                f"(standard error {shown:.3g} > {bound:g}{_UNIT[worst]})"
                if math.isfinite(sd)
                else f"{_LABEL[worst]} not determinable: information matrix singular"
            )
            free.remove(worst)
            if worst == M_T and ALPHA in free:
                free.remove(ALPHA)
                refused[ALPHA] = _ALPHA_WITH_SCALE
            if worst == CURRENT:
                offset = True
                for k in ("b", B_T):
                    if k in free:
                        free.remove(k)
                        refused[k] = refused[CURRENT].replace("current", _LABEL[k], 1)
    verdicts = tuple(
        Verdict(k, False, refused[k], None) if k in refused else Verdict(k, True, "", stds.get(k))
        for k in unknowns
    )
    return TwoAxisIdent(model, current, verdicts, offset, std_u, std_w, sectors, n)


@dataclass(frozen=True, slots=True)
class TwoAxisFit:
    """Result of one two-axis calibration.

    Attributes:
        params: the estimate; an unknown the data do not determine is at its prior.
        stderr: standard error of each parameter by unknown name (α in degrees under
            ``misalign_deg``); None: not determined.
        current_mps: the current (north, east), m/s; None when not estimated or not
            determined.
        current_std_mps: its standard errors, m/s.
        rmse_l_mps: RMS of the longitudinal residuals, m/s.
        rmse_t_mps: RMS of the transverse residuals, m/s.
        n_samples: samples per axis.
        ident: the verdict on every unknown.
        correlation: samples per independent sample (the larger axis's figure).
        method: ``"LS"`` or ``"KF"``.
    """

    params: TwoAxisParams
    stderr: dict[str, float | None]
    current_mps: tuple[float, float] | None
    current_std_mps: tuple[float, float] | None
    rmse_l_mps: float
    rmse_t_mps: float
    n_samples: int
    ident: TwoAxisIdent
    correlation: float = 1.0
    method: str = "LS"
    current_series: FloatArray | None = field(default=None, compare=False)
    """The current at each sample, shape (N, 2) (None: not determined)."""

    @property
    def misalign_deg(self) -> float:
        """α in degrees."""
        return self.params.misalign_deg

    @property
    def misalign_std_deg(self) -> float | None:
        """σ of α in degrees (None: not determined)."""
        return self.stderr.get("misalign_deg")

    @property
    def identifiable(self) -> bool:
        """Every unknown is determined."""
        return not self.ident.unidentifiable

    def to_dict(self) -> dict[str, object]:
        """Plain types for JSON: the parameters, their σ, the verdicts."""

        def fin(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else v

        return {
            "model": self.params.model,
            "method": self.method,
            "params": self.params.as_dict(),
            "stderr": {k: fin(v) for k, v in self.stderr.items()},
            "misalign_deg": self.misalign_deg,
            "misalign_std_deg": fin(self.misalign_std_deg),
            "current_mps": None if self.current_mps is None else list(self.current_mps),
            "current_std_mps": None if self.current_std_mps is None else list(self.current_std_mps),
            "rmse_l_mps": fin(self.rmse_l_mps),
            "rmse_t_mps": fin(self.rmse_t_mps),
            "n_samples": self.n_samples,
            "correlation": self.correlation,
            "unidentifiable": list(self.ident.unidentifiable),
            "reason": self.ident.reason,
        }


@dataclass(frozen=True, slots=True)
class _Series:
    gf: FloatArray
    gs: FloatArray
    raw_l: FloatArray
    raw_t: FloatArray
    hd: FloatArray


def _check(
    ref_fwd: npt.ArrayLike,
    ref_stb: npt.ArrayLike,
    raw_l: npt.ArrayLike,
    raw_t: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
) -> _Series:
    arrays = [
        np.asarray(a, dtype=np.float64).reshape(-1)
        for a in (ref_fwd, ref_stb, raw_l, raw_t, heading_deg)
    ]
    n = arrays[0].size
    if n == 0:
        raise DataError("no samples")
    if any(a.size != n for a in arrays):
        raise DataError("references, readings and headings must have the same length")
    if not all(bool(np.all(np.isfinite(a))) for a in arrays):
        raise DataError("references, readings and headings must be finite")
    return _Series(*arrays)


def _x0(prior: TwoAxisParams | None, size: int) -> FloatArray:
    x0 = np.zeros(size)
    if prior is not None:
        p = prior.longitudinal
        x0[_A], x0[_M], x0[_B] = p.a_spm, p.m, p.b_mps
        x0[_AL], x0[_MT], x0[_BT] = prior.misalign_rad, prior.m_t, prior.b_t_mps
    return x0


def _params_of(model: ModelName, x: FloatArray, tie: bool) -> TwoAxisParams:
    lon = Params.from_theta(model, [float(x[_PARAM_INDEX[p]]) for p in PARAM_NAMES[model]])
    alpha = float(np.clip(x[_AL], -math.radians(MAX_MISALIGN_DEG), math.radians(MAX_MISALIGN_DEG)))
    return TwoAxisParams(lon, alpha, float(x[_M] if tie else x[_MT]), float(x[_BT]))


ENVELOPE: dict[str, float] = {"a": 0.1, "m": 0.5, "b": 1.0, M_T: 0.5, B_T: 1.0}
"""The largest magnitude of each parameter a two-axis fit may report (the one-axis
envelope's |a| ≤ 0.1 s/m, |m| ≤ 0.5, |b| ≤ 1 m/s, the same for the transverse scale
and bias; α: :data:`MAX_MISALIGN_DEG`). An estimate beyond it — a transverse gain
driven to zero where a current the model cannot follow leaves that axis nothing
to explain — is refused with the reason and the rest fitted again."""


def _outside(x: FloatArray, determined: Sequence[str]) -> dict[str, str]:
    """The determined unknown furthest beyond the envelope (relative to its bound),
    with the reason; empty when every one lies inside. One at a time: a curvature
    and a scale that trade against each other leave the scale inside once the
    curvature is held."""
    worst, ratio = "", 1.0
    for k in determined:
        if k == ALPHA or k in ENVELOPE:
            bound = math.radians(MAX_MISALIGN_DEG) if k == ALPHA else ENVELOPE[k]
            r = abs(float(x[_PARAM_INDEX[k]])) / bound
            if r > ratio:
                worst, ratio = k, r
    if not worst:
        return {}
    if worst == ALPHA:
        return {
            ALPHA: f"misalignment outside the envelope ({math.degrees(float(x[_AL])):.1f}°, "
            f"at most ±{MAX_MISALIGN_DEG:g}°)"
        }
    return {
        worst: f"{_LABEL[worst]} outside the envelope ({float(x[_PARAM_INDEX[worst]]):.3g}"
        f"{_UNIT[worst]}, at most ±{ENVELOPE[worst]:g}{_UNIT[worst]})"
    }


def _ties(model: ModelName, ident: TwoAxisIdent) -> bool:
    """Whether the held transverse scale follows the longitudinal one."""
    return TIE_HELD_SCALE and "m" in PARAM_NAMES[model] and M_T in ident.unidentifiable


def _prepare(
    model: str,
    ref_fwd_mps: npt.ArrayLike,
    ref_stb_mps: npt.ArrayLike,
    raw_l_mps: npt.ArrayLike,
    raw_t_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    prior: TwoAxisParams | None,
    current: bool,
    t_s: npt.ArrayLike | None,
    current_knot_s: float | None,
) -> tuple[ModelName, _Series, _Problem]:
    name = check_model(model)
    s = _check(ref_fwd_mps, ref_stb_mps, raw_l_mps, raw_t_mps, heading_deg)
    if prior is not None and prior.model != name:
        raise DataError(f"prior parameters are {prior.model}, the fit is {name}")
    basis = None
    if current and current_knot_s is not None:
        basis = current_basis(t_s, s.gf.size, current_knot_s)
    return name, s, _Problem(s.gf, s.gs, s.raw_l, s.raw_t, np.radians(s.hd), basis)


def current_basis(t_s: npt.ArrayLike | None, n: int, knot_s: float) -> FloatArray | None:
    """The hat functions of a current linear between knots ``knot_s`` apart from the
    first sample: shape (N, K), each row summing to 1 (None: the samples span less
    than one interval, one current).

    Raises:
        DataError: no times, times of another length, not finite or decreasing, a bad
            interval.
    """
    if t_s is None:
        raise DataError("a current that changes needs the sample times")
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    if t.size != n or not np.all(np.isfinite(t)):
        raise DataError("times must be finite and as long as the speeds")
    if n > 1 and not np.all(np.diff(t) >= 0.0):
        raise DataError("times must not decrease")
    if not (math.isfinite(knot_s) and knot_s > 0.0):
        raise DataError(f"the current's knot interval must be > 0, not {knot_s!r}")
    span = float(t[-1] - t[0]) if n else 0.0
    if span < knot_s:
        return None
    k = math.ceil(span / knot_s) + 1
    knots = t[0] + knot_s * np.arange(k)
    return np.asarray(
        np.maximum(0.0, 1.0 - np.abs(t[:, None] - knots[None, :]) / knot_s), dtype=np.float64
    )


def fit_two_axis(
    model: str,
    ref_fwd_mps: npt.ArrayLike,
    ref_stb_mps: npt.ArrayLike,
    raw_l_mps: npt.ArrayLike,
    raw_t_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    *,
    current: bool = True,
    prior: TwoAxisParams | None = None,
    rule: TwoAxisRule = DEFAULT_TWO_AXIS_RULE,
    t_s: npt.ArrayLike | None = None,
    current_knot_s: float | None = None,
) -> TwoAxisFit:
    """Least squares of the two-axis model on aligned series (module docstring).

    Args:
        model: the longitudinal model, ``"EM1"`` … ``"EM4"``.
        ref_fwd_mps: the reference's ground (or, without ``current``, water) speed
            forward along the hull, m/s, shape (N,), lag-aligned.
        ref_stb_mps: its speed to starboard, m/s, shape (N,).
        raw_l_mps: the longitudinal readings, m/s, shape (N,).
        raw_t_mps: the transverse readings (positive to starboard), m/s, shape (N,).
        heading_deg: headings at the reference's time, degrees, shape (N,).
        current: estimate the sea current shared by both axes.
        prior: the value of an unknown the data do not determine (default the ideal
            sensor, aligned).
        rule: the identifiability thresholds.
        t_s: sample times, s (needed with ``current_knot_s``).
        current_knot_s: the current changes linearly between knots this many
            seconds apart (:func:`current_basis`; None: one current throughout). A
            current that turns with the tide, taken as constant, leaves its change
            on both axes; taken as constant per block, its steps between blocks
            take the misalignment's signature where the speed steps too (circles
            at three throttle settings). The transverse axis sees the current
            across the hull on any heading, and the along-hull part of a straight
            leg's current is told from the bias (one for all the knots) by the
            turns.

    Returns:
        The fit; never raises on poor excitation (see ``ident``).

    Raises:
        ModelError: unknown model.
        DataError: bad series, a prior of another model.
    """
    name, s, problem = _prepare(
        model,
        ref_fwd_mps,
        ref_stb_mps,
        raw_l_mps,
        raw_t_mps,
        heading_deg,
        prior,
        current,
        t_s,
        current_knot_s,
    )
    x0 = _x0(prior, problem.size())
    u, w = problem.water(x0)
    ident = judge_two_axis(name, u, w, s.raw_l, s.hd, current=current, rule=rule)
    x = x0
    outside: dict[str, str] = {}
    for _ in range(2 * len(ident.verdicts) + 2):
        problem.tie = _ties(name, ident)
        free = _free_indices(ident.determined, ident.nuisance_offset, problem.n_blocks)
        x = _solve(problem, x0, free)
        rl, rt = problem.residuals(x)
        dof = max(s.gf.size - len(free) // 2, 1)
        problem.scale = np.array(
            [
                1.0 / max(math.sqrt(float(rl @ rl) / dof), 1e-6),
                1.0 / max(math.sqrt(float(rt @ rt) / dof), 1e-6),
            ]
        )
        u, w = problem.water(x)
        new = judge_two_axis(
            name,
            u,
            w,
            s.raw_l,
            s.hd,
            current=current,
            info_of=problem,
            x=x,
            rule=rule,
            outside=outside,
        )
        done = new.determined == ident.determined
        ident = new
        if done:
            beyond = _outside(x, ident.determined)
            if not beyond:
                break
            outside |= beyond
            ident = judge_two_axis(
                name,
                u,
                w,
                s.raw_l,
                s.hd,
                current=current,
                info_of=problem,
                x=x,
                rule=rule,
                outside=outside,
            )
    for _ in range(len(ident.verdicts) + 1):  # each pass refuses one more, or ends
        problem.tie = _ties(name, ident)
        free = _free_indices(ident.determined, ident.nuisance_offset, problem.n_blocks)
        x = _solve(problem, x0, free)
        beyond = _outside(x, ident.determined)
        if not beyond:
            break
        outside |= beyond
        ident = judge_two_axis(
            name,
            u,
            w,
            s.raw_l,
            s.hd,
            current=current,
            info_of=problem,
            x=x,
            rule=rule,
            outside=outside,
        )
    rl, rt = problem.residuals(x)
    factor = max(correlation_factor(rl), correlation_factor(rt))
    std = np.full(x.size, math.nan)
    cov_full = np.zeros((x.size, x.size))
    if free and 2 * s.gf.size > len(free):
        jf = problem.jacobian(x)[:, free]
        try:
            cov = factor * np.linalg.inv(jf.T @ jf)
            std[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
            cov_full[np.ix_(free, free)] = cov
        except np.linalg.LinAlgError:
            std[free] = math.inf
    params = _params_of(name, x, problem.tie)
    determined = set(ident.determined)
    stderr: dict[str, float | None] = {
        p: (float(std[_PARAM_INDEX[p]]) if p in determined else None) for p in PARAM_NAMES[name]
    }
    stderr["misalign_deg"] = math.degrees(float(std[_AL])) if ALPHA in determined else None
    stderr[M_T] = float(std[_MT]) if M_T in determined else None
    stderr[B_T] = float(std[_BT]) if B_T in determined else None
    cur = cur_std = None
    series = None
    if current and CURRENT in determined:
        cn, ce = problem.current_at(x)
        series = np.column_stack([cn, ce])
        cur = (float(np.mean(cn)), float(np.mean(ce)))
        g = np.zeros((2, x.size))
        g[0, _CN] = g[1, _CE] = 1.0
        if problem.basis is not None:
            share = problem.basis.mean(axis=0)
            g[0, _CN] = g[1, _CE] = share[0]
            g[0, _N_FIXED::2] = share[1:]
            g[1, _N_FIXED + 1 :: 2] = share[1:]
        var = np.einsum("ij,jk,ik->i", g, cov_full, g)
        cur_std = (math.sqrt(max(float(var[0]), 0.0)), math.sqrt(max(float(var[1]), 0.0)))
    n = s.gf.size
    return TwoAxisFit(
        params=params,
        stderr=stderr,
        current_mps=cur,
        current_std_mps=cur_std,
        rmse_l_mps=math.sqrt(float(rl @ rl) / n),
        rmse_t_mps=math.sqrt(float(rt @ rt) / n),
        n_samples=n,
        ident=ident,
        correlation=factor,
        method="LS",
        current_series=series,
    )


class ModelState:
    """The two-axis model's state vector and measurement, sample by sample: what a
    filter (:mod:`calib.twoaxis_kf`) needs without the layout's indices.

    Attributes:
        n: samples.
        free: the state indices the verdicts leave free (the determined unknowns, and
            a nuisance offset per axis when the current is not separable).
    """

    def __init__(self, name: ModelName, s: _Series, ident: TwoAxisIdent) -> None:
        self.model = name
        self.n = s.gf.size
        self.tie = _ties(name, ident)
        self.free = _free_indices(ident.determined, ident.nuisance_offset, 1)
        psi = np.radians(s.hd)
        self._gf, self._gs = s.gf.tolist(), s.gs.tolist()
        self._rl, self._rt = s.raw_l.tolist(), s.raw_t.tolist()
        self._cp, self._sp = np.cos(psi).tolist(), np.sin(psi).tolist()

    @staticmethod
    def x0(prior: TwoAxisParams | None) -> FloatArray:
        """The initial state: the prior (else the ideal sensor), no current."""
        return _x0(prior, _N_FIXED)

    @staticmethod
    def index(unknown: str) -> int:
        """The state index of a parameter."""
        return _PARAM_INDEX[unknown]

    @staticmethod
    def name_of(index: int) -> str:
        """The unknown a state index belongs to (``current`` for the current and the
        nuisance offsets)."""
        for k, i in _PARAM_INDEX.items():
            if i == index:
                return k
        return CURRENT

    @staticmethod
    def is_current(index: int) -> bool:
        """Whether a state index is a current component."""
        return index in (_CN, _CE)

    @staticmethod
    def current(x: FloatArray) -> tuple[float, float]:
        """The current (north, east) of a state, m/s."""
        return float(x[_CN]), float(x[_CE])

    @staticmethod
    def current_std(std: FloatArray) -> tuple[float, float]:
        """The current's σ (north, east) from the states' σ, m/s."""
        return float(std[_CN]), float(std[_CE])

    def params(self, x: FloatArray) -> TwoAxisParams:
        """The parameters of a state."""
        return _params_of(self.model, x, self.tie)

    def step(self, x: FloatArray, j: int) -> tuple[FloatArray, FloatArray]:
        """Sample ``j``'s innovation (the two readings less the model's) and the
        measurement's Jacobian, shape (2, 10), at ``x``."""
        cp, sp = self._cp[j], self._sp[j]
        cn, ce = float(x[_CN]), float(x[_CE])
        u = self._gf[j] - cn * cp - ce * sp
        w = self._gs[j] + cn * sp - ce * cp
        al = float(x[_AL])
        ca, sa = math.cos(al), math.sin(al)
        us, ws = u * ca + w * sa, -u * sa + w * ca
        a, m = float(x[_A]), float(x[_M])
        slope = 2.0 * a * us + 1.0 + m
        gain_t = 1.0 + float(x[_M] if self.tie else x[_MT])
        c_pa, s_pa = cp * ca - sp * sa, sp * ca + cp * sa
        pl = (a * us + 1.0 + m) * us + float(x[_B]) + float(x[_DL])
        pt = gain_t * ws + float(x[_BT]) + float(x[_DT])
        h = np.zeros((2, _N_FIXED))
        h[0, _A], h[0, _M], h[0, _B], h[0, _DL] = us * us, us, 1.0, 1.0
        h[0, _AL], h[0, _CN], h[0, _CE] = slope * ws, -slope * c_pa, -slope * s_pa
        h[1, _M if self.tie else _MT], h[1, _BT], h[1, _DT] = ws, 1.0, 1.0
        h[1, _AL], h[1, _CN], h[1, _CE] = -gain_t * us, gain_t * s_pa, -gain_t * c_pa
        return np.array([self._rl[j] - pl, self._rt[j] - pt]), h


def model_state(
    model: str,
    ref_fwd_mps: npt.ArrayLike,
    ref_stb_mps: npt.ArrayLike,
    raw_l_mps: npt.ArrayLike,
    raw_t_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    ident: TwoAxisIdent,
) -> ModelState:
    """The state and measurement of a series under the verdicts ``ident``.

    Raises:
        ModelError: unknown model.
        DataError: bad series.
    """
    return ModelState(
        check_model(model),
        _check(ref_fwd_mps, ref_stb_mps, raw_l_mps, raw_t_mps, heading_deg),
        ident,
    )


def fit_current_two_axis(
    params: TwoAxisParams,
    ref_fwd_mps: npt.ArrayLike,
    ref_stb_mps: npt.ArrayLike,
    raw_l_mps: npt.ArrayLike,
    raw_t_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    *,
    t_s: npt.ArrayLike | None = None,
    current_knot_s: float | None = None,
) -> FloatArray:
    """The current that best explains a segment on both axes with the sensor's
    parameters frozen (what scoring a calibration on another segment needs, as
    :func:`calib.lsq.fit_current` on one axis). With both axes and the parameters
    frozen the current is determined on any heading; on a steady heading it takes
    each axis's remaining offset, for the raw reading (the ideal sensor's
    parameters) and for a calibration alike, so neither is judged on an offset a
    current could explain.

    Args:
        params: the frozen parameters.
        ref_fwd_mps: ground speed forward, m/s.
        ref_stb_mps: ground speed to starboard, m/s.
        raw_l_mps: longitudinal readings, m/s.
        raw_t_mps: transverse readings, m/s.
        heading_deg: headings, degrees.
        t_s: sample times, s (needed with ``current_knot_s``).
        current_knot_s: the current linear between knots this far apart
            (:func:`current_basis`; None: one current).

    Returns:
        The current (north, east) at each sample, m/s, shape (N, 2).

    Raises:
        DataError: bad series or times.
    """
    s = _check(ref_fwd_mps, ref_stb_mps, raw_l_mps, raw_t_mps, heading_deg)
    basis = None
    if current_knot_s is not None:
        basis = current_basis(t_s, s.gf.size, current_knot_s)
    problem = _Problem(s.gf, s.gs, s.raw_l, s.raw_t, np.radians(s.hd), basis)
    x0 = _x0(params, problem.size())
    x = _solve(problem, x0, _index(CURRENT, problem.n_blocks))
    cn, ce = problem.current_at(x)
    return np.column_stack([cn, ce])
