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

The state layout shared by the least squares (:mod:`calib.twoaxis`) and the filter
(:mod:`calib.twoaxis_kf`): the unknowns' indices, the residuals and their Jacobian on
both axes (``Problem``), the prior as a state and a state as parameters.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.errors import ModelError
from calib.models import (
    CURRENT,
    PARAM_NAMES,
    FloatArray,
    ModelName,
    Params,
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
"""Inside a fit, a transverse scale the data do not determine follows the longitudinal
scale (one coil's field drives both electrode pairs of an EM sensor, so their gains
move together), rather than the prior's, so that the athwart axis still tells the
current across the hull. It is not reported: without it the misalignment is refused,
and the fit reports the transverse scale and bias at the prior
(:func:`calib.twoaxis.hold_without_misalignment`)."""

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


# indices of the full unknown vector
_A, _M, _B, _AL, _MT, _BT, _CN, _CE, _DL, _DT = range(10)
_N_FIXED = 10
_PARAM_INDEX = {"a": _A, "m": _M, "b": _B, ALPHA: _AL, M_T: _MT, B_T: _BT}


class Problem:
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


def _index(unknown: str, n_blocks: int) -> list[int]:
    if unknown == CURRENT:
        return [_CN, _CE, *range(_N_FIXED, _N_FIXED + 2 * (n_blocks - 1))]
    return [_PARAM_INDEX[unknown]]


def _free_indices(determined: Sequence[str], offset: bool, n_blocks: int) -> list[int]:
    free = sorted(i for u in determined for i in _index(u, n_blocks))
    if offset:
        free += [_DL, _DT]
    return sorted(set(free))


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
