"""Excitation and identifiability of the error-model parameters (paper section III-B).

For a window of reference speeds the information matrix is ``HᵀWH`` with the design
matrix H of the model (eqs. (18)–(21)) and optional sample weights W. The paper
shows (eqs. (14)–(17)) that for EM3 ``det(HᵀH) = N·Σv² − (Σv)² = N²·var(v)``: it is
0 at constant speed, so scale factor and bias cannot be separated; the same
collapse happens for EM4. On real data the reference is noisy, so the matrix is
never exactly singular; :class:`ExcitationRule` turns the paper's ``det = 0``
into a documented numerical rule. Parameters are **identifiable** when all of:

1. there are at least ``min_samples_per_param × p`` samples;
2. H has full numerical rank p (singular values above ``max(N, p)·ε·s_max``);
3. ``cond(HᵀWH) ≤ max_cond`` (default 1e8; EM4 on a normal manoeuvre is ~1e3–1e5);
4. the speed actually varies or is non-zero, as each model needs:

   - EM1 (θ = [b]): nothing more;
   - EM2 (θ = [m]): the RMS speed is at least ``min_speed_rms_mps`` (a vessel at
     rest says nothing about a scale factor);
   - EM3, EM4: the speed standard deviation is at least ``min_speed_std_mps``
     (default 0.1 m/s; ``det(HᵀH)/N² = var(v)`` for EM3, the paper's criterion).

:func:`excitation` evaluates a batch window exactly (QR of the weighted design
matrix). :class:`ExcitationWindow` is the fixed-memory online version for the
daemon: exponentially forgotten speed moments Σw·vᵏ (k = 0..4), O(1) per sample.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.models import FloatArray, ModelName, check_model, design_matrix, n_params


@dataclass(frozen=True, slots=True)
class ExcitationRule:
    """Thresholds of the identifiability rule (see the module docstring).

    Attributes:
        min_samples_per_param: samples needed per parameter (≥ 1).
        min_speed_std_mps: minimum reference-speed standard deviation for EM3/EM4, m/s.
        min_speed_rms_mps: minimum RMS reference speed for EM2, m/s.
        max_cond: largest acceptable condition number of ``HᵀWH``.

    Raises:
        ValueError: a threshold out of range.
    """

    min_samples_per_param: int = 10
    min_speed_std_mps: float = 0.1
    min_speed_rms_mps: float = 0.3
    max_cond: float = 1e8

    def __post_init__(self) -> None:
        if self.min_samples_per_param < 1:
            raise ValueError("min_samples_per_param must be at least 1")
        if not (self.min_speed_std_mps >= 0.0 and self.min_speed_rms_mps >= 0.0):
            raise ValueError("speed thresholds must be non-negative")
        if not self.max_cond > 1.0:
            raise ValueError("max_cond must exceed 1")


DEFAULT_RULE = ExcitationRule()


@dataclass(frozen=True, slots=True)
class Excitation:
    """Excitation of one window for one model.

    Attributes:
        model: the error model.
        n_samples: number of samples (effective number ``Σw`` for a forgetting window).
        info: the information matrix ``HᵀWH``, p×p, as nested tuples (units follow θ).
        det_info: ``det(HᵀWH)``.
        cond_info: 2-norm condition number of ``HᵀWH`` (``inf`` when singular).
        rank: numerical rank of H (``≤ p``).
        speed_mean_mps: (weighted) mean reference speed, m/s.
        speed_std_mps: (weighted) standard deviation of the reference speed, m/s.
        speed_rms_mps: (weighted) RMS reference speed, m/s.
        identifiable: the verdict of the rule.
        reason: why not identifiable (empty when identifiable), for logs and reports.
    """

    model: ModelName
    n_samples: float
    info: tuple[tuple[float, ...], ...]
    det_info: float
    cond_info: float
    rank: int
    speed_mean_mps: float
    speed_std_mps: float
    speed_rms_mps: float
    identifiable: bool
    reason: str


def judge(
    model: ModelName,
    n_samples: float,
    rank: int,
    cond_info: float,
    speed_std_mps: float,
    speed_rms_mps: float,
    rule: ExcitationRule = DEFAULT_RULE,
) -> str:
    """Apply the identifiability rule.

    Args:
        model: the error model.
        n_samples: (effective) number of samples.
        rank: numerical rank of the design matrix.
        cond_info: condition number of the information matrix.
        speed_std_mps: standard deviation of the reference speed, m/s.
        speed_rms_mps: RMS reference speed, m/s.
        rule: the thresholds.

    Returns:
        ``""`` when identifiable, otherwise the first failed condition in words.
    """
    p = n_params(model)
    if n_samples < rule.min_samples_per_param * p:
        return f"too few samples ({n_samples:.0f} < {rule.min_samples_per_param * p})"
    if rank < p:
        return f"rank-deficient information matrix (rank {rank} < {p})"
    if model == "EM2" and speed_rms_mps < rule.min_speed_rms_mps:
        return f"speed too low for a scale factor (rms {speed_rms_mps:.3f} m/s)"
    if model in ("EM3", "EM4") and speed_std_mps < rule.min_speed_std_mps:
        return f"speed nearly constant (std {speed_std_mps:.3f} m/s < {rule.min_speed_std_mps} m/s)"
    if not cond_info <= rule.max_cond:
        return f"ill-conditioned information matrix (cond {cond_info:.3g} > {rule.max_cond:.3g})"
    return ""


def speed_stats(v: FloatArray, w: FloatArray | None) -> tuple[float, float, float]:
    """Weighted mean, standard deviation and RMS of a speed series (m/s)."""
    if w is None:
        mean = float(np.mean(v))
        rms = float(np.sqrt(np.mean(v * v)))
        std = float(np.std(v))
    else:
        sw = float(np.sum(w))
        mean = float(np.dot(w, v) / sw)
        rms = math.sqrt(float(np.dot(w, v * v)) / sw)
        std = math.sqrt(max(float(np.dot(w, (v - mean) ** 2)) / sw, 0.0))
    return mean, std, rms


def check_weights(weights: npt.ArrayLike | None, n: int) -> FloatArray | None:
    """Validate sample weights.

    Args:
        weights: non-negative finite weights, shape (n,), not all zero; or None.
        n: expected length.

    Returns:
        The weights as float64, or None.

    Raises:
        DataError: wrong shape, negative, non-finite or all-zero weights.
    """
    if weights is None:
        return None
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise DataError(f"weights must have shape ({n},), got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0.0) or not np.any(w > 0.0):
        raise DataError("weights must be finite, non-negative and not all zero")
    return w


def qr_r(A: FloatArray) -> FloatArray:
    """The R factor of the QR factorisation of A, shape (min(N, p), p) (Q is never formed).

    Args:
        A: matrix of shape (N, p).

    Returns:
        The upper-triangular R with ``AᵀA = RᵀR``.
    """
    return cast(FloatArray, np.linalg.qr(A, mode="r"))


def factor_stats(R: FloatArray, n_rows: int) -> tuple[int, float, float]:
    """Rank of A and det, cond of ``AᵀA`` from the triangular factor R of ``A = QR``.

    Working on R (``AᵀA = RᵀR``) avoids forming and inverting ``AᵀA``.

    Args:
        R: the R factor of a matrix A of shape (n_rows, p); shape (min(n_rows, p), p).
        n_rows: number of rows N of A (for the rank tolerance ``max(N, p)·ε·s_max``).

    Returns:
        ``(rank, det(AᵀA), cond(AᵀA))``; cond is ``inf`` when A is rank-deficient.
    """
    p = R.shape[1]
    s = np.linalg.svd(R, compute_uv=False)
    s_max = float(s[0]) if s.size else 0.0
    tol = s_max * max(n_rows, p) * np.finfo(np.float64).eps
    rank = int(np.count_nonzero(s > tol))
    det = float(np.prod(s) ** 2) if s.size == p else 0.0
    cond = (s_max / float(s[-1])) ** 2 if rank == p else math.inf
    return rank, det, cond


def excitation(
    model: str,
    v_ref_mps: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
    *,
    rule: ExcitationRule = DEFAULT_RULE,
) -> Excitation:
    """Excitation of a batch window (paper eqs. (14)–(17)).

    Args:
        model: the error model.
        v_ref_mps: reference speeds in m/s, shape (N,), N ≥ 1.
        weights: optional sample weights, shape (N,).
        rule: identifiability thresholds.

    Returns:
        The information matrix, its determinant and condition number, the speed
        statistics and the identifiability verdict.

    Raises:
        ModelError: unknown model.
        DataError: empty or non-finite speeds, bad weights.
    """
    name = check_model(model)
    v = np.asarray(v_ref_mps, dtype=np.float64).reshape(-1)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise DataError("reference speeds must be a non-empty finite series")
    w = check_weights(weights, v.size)
    H = design_matrix(name, v)
    A = H if w is None else H * np.sqrt(w)[:, None]
    rank, det, cond = factor_stats(qr_r(A), v.size)
    info = A.T @ A
    mean, std, rms = speed_stats(v, w)
    n_eff = float(v.size) if w is None else float(np.sum(w))
    reason = judge(name, n_eff, rank, cond, std, rms, rule)
    return Excitation(
        model=name,
        n_samples=n_eff,
        info=tuple(tuple(float(x) for x in row) for row in info),
        det_info=det,
        cond_info=cond,
        rank=rank,
        speed_mean_mps=mean,
        speed_std_mps=std,
        speed_rms_mps=rms,
        identifiable=not reason,
        reason=reason,
    )


class ExcitationWindow:
    """Fixed-memory online excitation tracker (exponential forgetting).

    Keeps the five moments ``S_k = Σ λ^(age)·v^k`` (k = 0..4) of the reference
    speed, so the information matrix of any model EM1–EM4 can be rebuilt on demand
    (EM3: ``[[S2, S1], [S1, S0]]``). :meth:`add` is O(1) over plain floats;
    :meth:`evaluate` costs a small eigen-decomposition, call it at status rate.

    Args:
        half_life_samples: samples after which a sample's weight has halved
            (``inf`` for a growing window without forgetting).
        rule: identifiability thresholds.

    Raises:
        ValueError: a half-life that is not positive.
    """

    __slots__ = ("_lam", "_s0", "_s1", "_s2", "_s3", "_s4", "rule")

    def __init__(self, half_life_samples: float = math.inf, rule: ExcitationRule = DEFAULT_RULE):
        if not half_life_samples > 0.0:
            raise ValueError("half_life_samples must be positive")
        self._lam = 0.5 ** (1.0 / half_life_samples) if math.isfinite(half_life_samples) else 1.0
        self.rule = rule
        self._s0 = self._s1 = self._s2 = self._s3 = self._s4 = 0.0

    def add(self, v_ref_mps: float) -> None:
        """Add one reference speed (m/s); older samples fade by the forgetting factor."""
        lam = self._lam
        v2 = v_ref_mps * v_ref_mps
        self._s0 = lam * self._s0 + 1.0
        self._s1 = lam * self._s1 + v_ref_mps
        self._s2 = lam * self._s2 + v2
        self._s3 = lam * self._s3 + v2 * v_ref_mps
        self._s4 = lam * self._s4 + v2 * v2

    def reset(self) -> None:
        """Forget every sample."""
        self._s0 = self._s1 = self._s2 = self._s3 = self._s4 = 0.0

    @property
    def n_effective(self) -> float:
        """Effective number of samples ``S_0``."""
        return self._s0

    def evaluate(self, model: str) -> Excitation:
        """Excitation of the current window for one model.

        Args:
            model: the error model.

        Returns:
            The same figures as :func:`excitation` (rank from the eigenvalues of
            the information matrix built from the moments).

        Raises:
            ModelError: unknown model.
        """
        name = check_model(model)
        s0, s1, s2, s3, s4 = self._s0, self._s1, self._s2, self._s3, self._s4
        rows = {
            "EM1": ((s0,),),
            "EM2": ((s2,),),
            "EM3": ((s2, s1), (s1, s0)),
            "EM4": ((s4, s3, s2), (s3, s2, s1), (s2, s1, s0)),
        }[name]
        info = np.array(rows, dtype=np.float64)
        eig = np.linalg.eigvalsh(info)
        e_max = float(eig[-1])
        tol = max(e_max, 0.0) * info.shape[0] * np.finfo(np.float64).eps * 1e3
        rank = int(np.count_nonzero(eig > tol))
        p = info.shape[0]
        cond = e_max / float(eig[0]) if rank == p else math.inf
        det = float(np.prod(eig)) if rank == p else 0.0
        if s0 > 0.0:
            mean = s1 / s0
            std = math.sqrt(max(s2 / s0 - mean * mean, 0.0))
            rms = math.sqrt(max(s2 / s0, 0.0))
        else:
            mean = std = rms = 0.0
        reason = judge(name, s0, rank, cond, std, rms, self.rule)
        return Excitation(
            model=name,
            n_samples=s0,
            info=rows,
            det_info=det,
            cond_info=cond,
            rank=rank,
            speed_mean_mps=mean,
            speed_std_mps=std,
            speed_rms_mps=rms,
            identifiable=not reason,
            reason=reason,
        )
