"""Latency between a speed log and the reference by cross-correlation (paper eq. (27)).

The paper chooses the shift τ that maximises ``Σₜ v_meas(t + τ)·v_ref(t)``. Here
the series are mean-removed and normalised (the Pearson coefficient), so the peak
value is a quality figure in [−1, 1], and:

- the two series may have different rates and time stamps (EMlog1 1 Hz, DVL
  10 Hz): for each candidate τ the reference is interpolated linearly at the
  measurement times shifted back, ``t_meas − τ``;
- τ runs over a bounded grid ``[−max_lag_s, max_lag_s]`` with step ``step_s``
  (default: the finer of the two median sample intervals), and only measurement
  samples whose shifted time stays inside the reference for **every** τ are used,
  so all candidates are scored on the same samples;
- the grid peak is refined to sub-sample resolution by fitting a parabola through
  it and its two neighbours.

Sign convention: a positive lag means the measurement is late,
``v_meas(t) ≈ v_ref(t − lag)``; align by evaluating the reference at ``t − lag``.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.models import FloatArray


@dataclass(frozen=True, slots=True)
class LagEstimate:
    """Result of :func:`estimate_lag`.

    Attributes:
        lag_s: estimated latency of the measurement behind the reference, s.
        peak_corr: normalised cross-correlation at the peak (quality, ≤ 1).
        step_s: grid step used, s.
        n_samples: measurement samples that entered the correlation.
        at_bound: the peak is at ±max_lag_s (the true lag may lie outside).
    """

    lag_s: float
    peak_corr: float
    step_s: float
    n_samples: int
    at_bound: bool


def _series(name: str, t: npt.ArrayLike, v: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate one (times, speeds) pair: finite, same length, strictly increasing times."""
    ta = np.asarray(t, dtype=np.float64).reshape(-1)
    va = np.asarray(v, dtype=np.float64).reshape(-1)
    if ta.shape != va.shape or ta.size < 3:
        raise DataError(f"{name}: need ≥ 3 samples and equal lengths, got {ta.size}, {va.size}")
    if not (np.all(np.isfinite(ta)) and np.all(np.isfinite(va))):
        raise DataError(f"{name}: times and speeds must be finite")
    if not np.all(np.diff(ta) > 0.0):
        raise DataError(f"{name}: times must be strictly increasing")
    return ta, va


def _pearson(a: FloatArray, b: FloatArray) -> float:
    """Pearson correlation of two equal-length series (0 when one is constant)."""
    a0 = a - a.mean()
    b0 = b - b.mean()
    den = math.sqrt(float(np.dot(a0, a0)) * float(np.dot(b0, b0)))
    return float(np.dot(a0, b0)) / den if den > 0.0 else 0.0


def estimate_lag(
    t_meas: npt.ArrayLike,
    v_meas: npt.ArrayLike,
    t_ref: npt.ArrayLike,
    v_ref: npt.ArrayLike,
    max_lag_s: float,
    *,
    step_s: float | None = None,
    min_samples: int = 30,
) -> LagEstimate:
    """Estimate the latency of a speed series relative to a reference.

    Args:
        t_meas: measurement times in s, shape (N,), strictly increasing.
        v_meas: measured speeds in m/s, shape (N,).
        t_ref: reference times in s, shape (M,), strictly increasing.
        v_ref: reference speeds in m/s, shape (M,).
        max_lag_s: largest |lag| searched, s (> 0).
        step_s: grid step in s (default: the smaller median sample interval).
        min_samples: fewest usable measurement samples.

    Returns:
        The lag, the peak correlation and diagnostics.

    Raises:
        DataError: bad series, too little overlap, or a non-positive max_lag_s/step_s.
    """
    tm, vm = _series("measurement", t_meas, v_meas)
    tr, vr = _series("reference", t_ref, v_ref)
    if not (math.isfinite(max_lag_s) and max_lag_s > 0.0):
        raise DataError("max_lag_s must be positive")
    if step_s is None:
        step_s = float(min(np.median(np.diff(tm)), np.median(np.diff(tr))))
    if not (math.isfinite(step_s) and step_s > 0.0):
        raise DataError("step_s must be positive")
    n_half = max(math.floor(max_lag_s / step_s + 1e-9), 1)
    lags = np.arange(-n_half, n_half + 1, dtype=np.float64) * step_s
    reach = n_half * step_s
    keep = (tm - reach >= tr[0]) & (tm + reach <= tr[-1])
    if int(np.count_nonzero(keep)) < min_samples:
        raise DataError(
            f"only {int(np.count_nonzero(keep))} measurement samples overlap the reference "
            f"within ±{reach:g} s (need {min_samples})"
        )
    tk = tm[keep]
    vk = vm[keep]
    corr = np.array([_pearson(vk, np.interp(tk - lag, tr, vr)) for lag in lags])
    i = int(np.argmax(corr))
    at_bound = i in (0, lags.size - 1)
    lag = float(lags[i])
    peak = float(corr[i])
    if not at_bound:
        c_m, c_0, c_p = float(corr[i - 1]), peak, float(corr[i + 1])
        den = c_m - 2.0 * c_0 + c_p
        if den < 0.0:
            delta = 0.5 * (c_m - c_p) / den
            lag += delta * step_s
            peak = c_0 - 0.25 * (c_m - c_p) * delta
    return LagEstimate(lag, min(peak, 1.0), step_s, int(tk.size), at_bound)
