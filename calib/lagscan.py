"""The lags scored each on the readings that overlap the reference at that lag.

:func:`calib.lag.estimate_lag` scores every candidate lag on the same readings: those
whose shifted time stays inside the reference, clear of any outage, for **every** lag.
Searching minutes either way (a reference whose clock is off), one outage of the
reference (a DVL losing the bottom for 20 s) then rules out every reading within the
range of it, and a window of ten minutes with one outage has none left to score.

:func:`scan_lags` scores each lag τ on the readings whose time ``t − τ`` falls inside the
reference, clear of any outage by the smoothing width: a gap costs the readings that face
it at that lag only. Scores on different readings are compared by their *adjusted*
coefficient of determination, ``1 − (RSS/(n − k)) / (TSS/(n − 1))`` with ``k`` the
unknowns fitted (the reference's coefficient, and per block of
:data:`calib.lag.CURRENT_BLOCK_S` a level and a drifting current in the water frame, a
level otherwise): fewer readings or more blocks cannot make a lag look better by the
fit's freedom alone. A lag scored on fewer than ``min_samples`` readings is not scored.
The lags are scored :data:`SCAN_COARSE_S` apart, then at every step around the best.
The score reported is the signed square root of that adjusted figure (as
:func:`calib.lag.estimate_lag`'s correlation), and the estimate's ``n_samples`` the
readings at the best lag.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.lag import (
    CURRENT_BLOCK_S,
    GAP_SPACINGS,
    MAX_GAP_S,
    SMOOTH_S,
    CurrentBlocks,
    LagEstimate,
    checked_series,
    smooth,
)
from calib.models import FloatArray

SCAN_COARSE_S = 3.0
"""The lags are first scored this far apart, then at every step around the best: both
series are averaged over two sample spacings, and a correlation peak minutes off is
tens of seconds wide, so a coarse grid finds it at a third of the cost."""


def _adjusted(y: FloatArray, X: FloatArray, ref: FloatArray, blocks: CurrentBlocks | None) -> float:
    """Signed root of the adjusted R² of ``y`` on ``ref`` and the nuisance columns ``X``
    (fitted per block when ``blocks`` is given, once otherwise)."""
    n = y.size
    y0 = y - y.mean()
    tss = float(y0 @ y0)
    V = np.stack((y, ref), axis=1)
    if blocks is None:
        ey, er = (V - X @ np.linalg.lstsq(X, V, rcond=None)[0]).T
        k = X.shape[1] + 1
    else:
        ey, er = blocks.residual(X, V).T
        k = X.shape[1] * len(blocks.spans) + 1
    rr = float(er @ er)
    if tss <= 0.0 or rr <= 0.0 or n - k < 1:
        return -math.inf
    ry = float(er @ ey)
    rss = max(float(ey @ ey) - ry * ry / rr, 0.0)
    adj = 1.0 - (rss / (n - k)) / (tss / (n - 1))
    return math.copysign(math.sqrt(max(adj, 0.0)), ry)


def _clear(tr: FloatArray, edge_s: float) -> tuple[FloatArray, FloatArray]:
    """``(starts, ends)`` of the reference's stretches without an outage, each shrunk by
    ``edge_s`` at both ends (a stretch shorter than twice that is dropped)."""
    gap_s = max(MAX_GAP_S, GAP_SPACINGS * float(np.median(np.diff(tr))))
    cut = np.flatnonzero(np.diff(tr) > gap_s)
    starts = np.concatenate(([tr[0]], tr[cut + 1])) + edge_s
    ends = np.concatenate((tr[cut], [tr[-1]])) - edge_s
    ok = ends > starts
    return starts[ok], ends[ok]


def scan_lags(
    t_meas: npt.ArrayLike,
    v_meas: npt.ArrayLike,
    t_ref: npt.ArrayLike,
    v_ref: npt.ArrayLike,
    max_lag_s: float,
    *,
    step_s: float,
    min_samples: int,
    heading: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    at_s: float | None = None,
) -> LagEstimate:
    """The best lag over ``±max_lag_s`` in steps of ``step_s``, each lag scored on the
    readings that overlap the reference at it (see the module docstring).

    Args:
        t_meas, v_meas: the readings' times (s, strictly increasing) and speeds (m/s).
        t_ref, v_ref: the reference's.
        max_lag_s: largest |lag| scored, s (> 0).
        step_s: grid step, s (> 0).
        min_samples: fewest readings a lag is scored on.
        heading: ``(t_h, heading_deg)`` at the reference's clock: score in the water
            frame (a level and a drifting current per block fitted).
        at_s: also score this lag (:attr:`calib.lag.LagEstimate.corr_at`; nan when it
            overlaps too few readings).

    Returns:
        The best lag on the grid (``std_s`` inf: the grid's step is its resolution),
        its score, the readings it was scored on, and whether it lies at the range's
        bound or next to a lag that could not be scored (where the best lies, unknown).

    Raises:
        DataError: bad series, a non-positive range or step, or no lag scored on
            ``min_samples`` readings.
    """
    tm, vm = checked_series("measurement", t_meas, v_meas)
    tr, vr = checked_series("reference", t_ref, v_ref)
    if not (math.isfinite(max_lag_s) and max_lag_s > 0.0 and math.isfinite(step_s) and step_s > 0):
        raise DataError("max_lag_s and step_s must be positive")
    n_half = max(math.floor(max_lag_s / step_s + 1e-9), 1)
    lags = np.arange(-n_half, n_half + 1, dtype=np.float64) * step_s
    width = max(SMOOTH_S, 2.0 * float(max(np.median(np.diff(tm)), np.median(np.diff(tr)))))
    vm = smooth(tm, vm, width)
    vr = smooth(tr, vr, width)
    starts, ends = _clear(tr, width)
    cos_h = sin_h = th = None
    if heading is not None:
        th, psi = checked_series("heading", heading[0], heading[1])
        cos_h, sin_h = np.cos(np.radians(psi)), np.sin(np.radians(psi))
        starts, ends = np.maximum(starts, th[0]), np.minimum(ends, th[-1])

    def score(lag: float) -> tuple[float, int]:
        ts = tm - lag
        seg = np.searchsorted(starts, ts, side="right") - 1
        keep = (seg >= 0) & (ts <= ends[np.clip(seg, 0, None)])
        n = int(np.count_nonzero(keep))
        if n < min_samples:
            return -math.inf, n
        tk, yk, sk = tm[keep], vm[keep], ts[keep]
        ref = np.interp(sk, tr, vr)
        if th is None or cos_h is None or sin_h is None:
            return _adjusted(yk, np.ones((n, 1)), ref, None), n
        blocks = CurrentBlocks(tk, CURRENT_BLOCK_S)
        c, s = np.interp(sk, th, cos_h), np.interp(sk, th, sin_h)
        tau = blocks.tau
        X = np.stack((np.ones(n), c, s, tau * c, tau * s), axis=1)
        return _adjusted(yk, X, ref, blocks), n

    corr = np.full(lags.size, np.nan)
    counts = np.zeros(lags.size, dtype=np.int64)

    def fill(idx: range | list[int]) -> None:
        for j in idx:
            if math.isnan(corr[j]):
                corr[j], counts[j] = score(float(lags[j]))

    every = max(round(SCAN_COARSE_S / step_s), 1)
    fill([*range(0, lags.size, every), lags.size - 1])
    seen: set[int] = set()
    while (i := int(np.nanargmax(np.nan_to_num(corr, nan=-np.inf)))) not in seen:
        # every step around the best so far; again if the best moved
        seen.add(i)
        fill(range(max(i - every, 0), min(i + every, lags.size - 1) + 1))
    if not math.isfinite(float(corr[i])):
        raise DataError(f"no lag within ±{max_lag_s:g} s overlaps {min_samples} readings")
    at_bound = i in (0, lags.size - 1) or not (
        math.isfinite(float(corr[i - 1])) and math.isfinite(float(corr[i + 1]))
    )
    corr_at = math.nan
    if at_s is not None:
        c_at = score(float(at_s))[0]
        corr_at = c_at if math.isfinite(c_at) else math.nan
    return LagEstimate(
        float(lags[i]),
        min(float(corr[i]), 1.0),
        step_s,
        int(counts[i]),
        at_bound,
        math.inf,
        corr_at,
    )
