"""Batch least squares LS-EM1..LS-EM4 (paper section II-A and III-C-1).

The error ``z = raw − v_ref`` is linear in the model parameters θ:
``z = H·θ + η`` with the paper's design matrices H (eqs. (18)–(21)). The estimate
minimises the cost J(θ) = Σ wₖ (zₖ − hₖ·θ)² (eq. (1); wₖ = 1 without weights).
The paper writes its solution with the normal equations (eq. (2)),
``θ = (HᵀH)⁻¹Hᵀz``; here it is computed stably from one QR factorisation of the
augmented matrix ``√W·[H | z]``: ``R·θ = Qᵀz``, never inverting ``HᵀH``. The
residual sum of squares is the last diagonal element of that R squared.

Standard errors are ``√diag(σ̂²·(HᵀWH)⁻¹)`` with the residual variance
``σ̂² = Σwₖrₖ² / (Σwₖ/N̄·(N − p))`` — for unit weights the textbook
``RSS/(N − p)``; weights are treated as relative (only their ratios matter).
``(HᵀWH)⁻¹ = R⁻¹R⁻ᵀ`` uses the small triangular factor only. When H is
rank-deficient (constant speed for EM3/EM4: the paper's ``det(HᵀH) = 0``) the fit
does not raise: θ is the minimum-norm solution, the standard errors are ``inf``
and ``identifiable`` is False (rule in :mod:`calib.excitation`).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.excitation import (
    DEFAULT_RULE,
    ExcitationRule,
    check_weights,
    factor_stats,
    judge,
    qr_r,
    speed_stats,
)
from calib.models import PARAM_NAMES, FloatArray, ModelName, Params, check_model, design_matrix


@dataclass(frozen=True, slots=True)
class LsFit:
    """Result of one least-squares calibration.

    Attributes:
        model: the error model.
        params: the estimated parameters θ̂.
        stderr: standard errors of θ̂ in θ order and units (``inf`` if not full rank).
        rmse_mps: RMS of the fit residuals ``z − Hθ̂`` in m/s (weighted RMS with weights).
        n_samples: number of samples N.
        rank: numerical rank of H.
        det_info: ``det(HᵀWH)`` (units follow θ).
        cond_info: condition number of ``HᵀWH`` (``inf`` when rank-deficient).
        identifiable: verdict of :class:`calib.excitation.ExcitationRule`.
        reason: why not identifiable (empty otherwise).
    """

    model: ModelName
    params: Params
    stderr: tuple[float, ...]
    rmse_mps: float
    n_samples: int
    rank: int
    det_info: float
    cond_info: float
    identifiable: bool
    reason: str

    def stderr_dict(self) -> dict[str, float]:
        """Standard errors by short parameter name, e.g. ``{"m": ..., "b": ...}``."""
        return dict(zip(PARAM_NAMES[self.model], self.stderr, strict=True))

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready summary with stable keys (non-finite floats become None)."""

        def fin(x: float) -> float | None:
            return x if math.isfinite(x) else None

        return {
            "model": self.model,
            "method": "ls",
            "params": self.params.as_dict(),
            "stderr": {k: fin(v) for k, v in self.stderr_dict().items()},
            "rmse_fit": self.rmse_mps,
            "n_samples": self.n_samples,
            "rank": self.rank,
            "det_info": self.det_info,
            "condition_number": fin(self.cond_info),
            "identifiable": self.identifiable,
            "reason": self.reason,
        }


def check_pair(ref_mps: npt.ArrayLike, raw_mps: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate a (reference, raw) pair of aligned speed series.

    Args:
        ref_mps: reference speeds in m/s, shape (N,).
        raw_mps: raw EMlog speeds in m/s, shape (N,).

    Returns:
        Both as float64 arrays.

    Raises:
        DataError: different shapes, empty, not one-dimensional or not finite.
    """
    ref = np.asarray(ref_mps, dtype=np.float64)
    raw = np.asarray(raw_mps, dtype=np.float64)
    if ref.ndim != 1 or ref.shape != raw.shape:
        raise DataError(f"ref and raw must be 1-D of equal length, got {ref.shape} and {raw.shape}")
    if ref.size == 0:
        raise DataError("no samples")
    if not (np.all(np.isfinite(ref)) and np.all(np.isfinite(raw))):
        raise DataError("ref and raw must be finite (drop or interpolate gaps first)")
    return ref, raw


def fit_ls(
    model: str,
    ref_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
    *,
    rule: ExcitationRule = DEFAULT_RULE,
) -> LsFit:
    """LS-EMx: fit one error model to aligned reference and raw speeds.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        ref_mps: reference (DVL) speeds in m/s, shape (N,), already lag-aligned.
        raw_mps: raw EMlog speeds in m/s, shape (N,).
        weights: optional non-negative sample weights, shape (N,) (e.g. 1/σₖ²).
        rule: identifiability thresholds.

    Returns:
        The fit; never raises on rank deficiency (see ``identifiable``).

    Raises:
        ModelError: unknown model.
        DataError: bad series or weights.
    """
    name = check_model(model)
    ref, raw = check_pair(ref_mps, raw_mps)
    n = ref.size
    w = check_weights(weights, n)
    H = design_matrix(name, ref)
    p = H.shape[1]
    A = np.empty((n, p + 1), dtype=np.float64)
    A[:, :p] = H
    np.subtract(raw, ref, out=A[:, p])
    if w is not None:
        A *= np.sqrt(w)[:, None]
    R_aug = qr_r(A)
    R = R_aug[:p, :p]
    rank, det, cond = factor_stats(R, n)
    qtz = R_aug[:p, p]
    rss = float(R_aug[p, p] ** 2) if R_aug.shape[0] > p else 0.0
    if rank == p:
        theta = np.linalg.solve(R, qtz)
    else:
        theta = np.linalg.lstsq(R, qtz, rcond=max(n, p) * np.finfo(np.float64).eps)[0]
        rss = float(np.sum((A[:, p] - A[:, :p] @ theta) ** 2))
    w_mean = 1.0 if w is None else float(np.sum(w)) / n
    rmse = math.sqrt(rss / (w_mean * n))
    if rank == p and n > p:
        sigma2 = rss / (w_mean * (n - p))
        r_inv = np.linalg.solve(R, np.eye(p))
        cov = sigma2 * w_mean * (r_inv @ r_inv.T)
        stderr = tuple(float(math.sqrt(max(c, 0.0))) for c in np.diag(cov))
    else:
        stderr = (math.inf,) * p
    _, std, rms = speed_stats(ref, w)
    reason = judge(name, float(n), rank, cond, std, rms, rule)
    return LsFit(
        model=name,
        params=Params.from_theta(name, theta.tolist()),
        stderr=stderr,
        rmse_mps=rmse,
        n_samples=n,
        rank=rank,
        det_info=det,
        cond_info=cond,
        identifiable=not reason,
        reason=reason,
    )
