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
  so all candidates are scored on the same samples; nor may it fall into a
  reference outage (a gap longer than :data:`MAX_GAP_S` or :data:`GAP_SPACINGS`
  spacings): the reference is never interpolated across one;
- the grid peak is refined to sub-sample resolution by fitting a parabola through
  it and its two neighbours.

**In the water frame** (a heading given): a ground-referenced reference carries the
sea current projected on the hull, ``c_N·cos ψ + c_E·sin ψ``, which swings with the
heading and would pull a plain correlation peak towards whatever lag best lines the
current's swing up with the speed log's. The score at each τ is then the *multiple*
correlation of the measurement with ``v_ref`` and, over each block of
:data:`CURRENT_BLOCK_S`, a level and a current that may drift linearly,
``[1, cos ψ, sin ψ, t·cos ψ, t·sin ψ]`` (all at ``t − τ``, the heading interpolated
through its cosine and sine, so across 0/360): the current is fitted at every
candidate lag and cannot shift the peak, even while the tide turns. Without a heading
the score is the plain Pearson coefficient (the same thing with one regressor).

:func:`accept` is the one rule deciding whether an estimate is used, for the daemon
and the offline commands alike: a lag is never negative, never beyond the search bound
``max_lag_s``, and never uncertain (σ over :data:`MAX_LAG_STD_S`). Without an accepted
estimate every user falls back to :data:`LAG_FALLBACK_S` and says so.

**Whose lag.** With receive times (``emlogd record``, the daemon) the lag is the speed
log's latency behind the reference as they reached the computer. Where the times come
from the log itself (imported NMEA logs and CSV exports, timed by their GNSS fixes;
receive times quantised by 1-s fixes) the lag is the *log's*: how much later the log
wrote the speed than the fix it put beside it — the bus and the logger as much as the
sensor. Fix times of whole seconds make that correlation peak about a second wide
(σ of 0.3–1 s, peaks between −3 and +4 s on real logs), so it is refused, and the
fallback pairs each reading with the reference the log wrote next to it.

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
        std_s: standard error of the lag from the peak's curvature and the residual
            (white residuals assumed; ``inf`` when the peak is flat or at the bound), s.
        corr_at: the score at ``at_s`` on the same samples (nan without one).
    """

    lag_s: float
    peak_corr: float
    step_s: float
    n_samples: int
    at_bound: bool
    std_s: float = math.inf
    corr_at: float = math.nan
    """The correlation at ``at_s`` (:func:`estimate_lag`) on the same samples, or nan."""


def checked_series(name: str, t: npt.ArrayLike, v: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
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


PEAK_HALF_WIDTH_S = 1.0
"""Half-width of the neighbourhood of the grid peak fitted by a parabola, s."""

MAX_GAP_S = 1.0
GAP_SPACINGS = 3.0
"""A reference gap longer than ``max(MAX_GAP_S, GAP_SPACINGS × its median spacing)``
is an outage: the lag is never scored across one (a 10 Hz DVL: 1 s; 1 Hz GNSS: 3 s)."""

MIN_LAG_CORRELATION = 0.6
"""An estimate with a weaker peak is not used: a straight run at constant speed
correlates at ~0.4 wherever the lag is."""

MAX_LAG_STD_S = 0.1
"""An estimate less certain than this is not used: a broad peak (slow speed changes,
whole-second fix times) places the lag anywhere within it. Within it, the misalignment
costs at most 0.1 s × the vessel's acceleration (2 cm/s at 0.2 m/s², below a speed
log's noise); the estimates refused on real logs without receive times have σ of
0.3–1 s."""

LAG_FALLBACK_S = 0.0
"""The lag used while none is accepted, s: each reading paired with the reference of
the same time. Where times come from the log (imported logs) that is the pairing the
log made; with receive times it is the smallest latency there is (a speed log is
never ahead of its reference), and the alignment's cadence-sized gap
(:mod:`emlogd.pipeline.align`) still pairs readings with a reference a sample or two
away. A calibration learnt on it is checked against raw like any other."""


def accept(
    est: LagEstimate,
    min_corr: float = MIN_LAG_CORRELATION,
    max_std_s: float = MAX_LAG_STD_S,
    max_lag_s: float = math.inf,
) -> str:
    """The lag acceptance rule: ``""`` when the estimate may be used, else why not.

    An estimate is used when the peak is not at the search bound, the lag is neither
    negative nor beyond ``max_lag_s``, its correlation is at least ``min_corr`` and
    its standard error at most ``max_std_s``. A negative lag would put the speed log
    ahead of the reference: it is an artefact (a reference whose own filter lags, log
    times quantised by whole-second fixes), and aligning on it would pair readings
    with a reference from their future.
    """
    if est.at_bound:
        return f"correlation peak at the search bound ({est.lag_s:+.2f} s, r={est.peak_corr:.2f})"
    if est.lag_s < 0.0:
        return f"negative lag ({est.lag_s:+.2f} s): a speed log is never ahead of its reference"
    if est.lag_s > max_lag_s:
        return f"lag {est.lag_s:+.2f} s beyond max_lag_s {max_lag_s:g} s"
    if not est.peak_corr >= min_corr:
        return f"no clear correlation peak (r={est.peak_corr:.2f} < {min_corr})"
    if not est.std_s <= max_std_s:
        return f"correlation peak too broad (lag {est.lag_s:+.2f} ± {est.std_s:.2f} s)"
    return ""


def combine(estimates: list[LagEstimate]) -> float:
    """One lag from several accepted estimates: their median weighted by 1/σ².

    Robust to one window whose peak is off (the median), and leaning on the
    sharpest peaks (the weights).

    Raises:
        DataError: no estimate.
    """
    if not estimates:
        raise DataError("no lag estimate to combine")
    order = sorted(estimates, key=lambda e: e.lag_s)
    w = [1.0 / max(e.std_s, 1e-6) ** 2 for e in order]
    half = 0.5 * sum(w)
    acc = 0.0
    for e, wi in zip(order, w, strict=True):
        acc += wi
        if acc >= half:
            return e.lag_s
    return order[-1].lag_s


def _pearson(a: FloatArray, b: FloatArray) -> float:
    """Pearson correlation of two equal-length series (0 when one is constant)."""
    a0 = a - a.mean()
    b0 = b - b.mean()
    den = math.sqrt(float(np.dot(a0, a0)) * float(np.dot(b0, b0)))
    return float(np.dot(a0, b0)) / den if den > 0.0 else 0.0


CURRENT_BLOCK_S = 300.0
"""In the water frame the current is fitted afresh over each block of this length, as a
value and a rate of change: a current that drifts within the window (a tide turning, a
change of area) fitted as one constant leaves a residual that follows the heading, and
that pulls the peak (by +1 s on a simulated figure-8 under a slowly varying current)."""


class CurrentBlocks:
    """The blocks of :data:`CURRENT_BLOCK_S` over the measurement times ``t``.

    Attributes:
        starts: start index of each block holding samples (a tail shorter than a block
            joins the last).
        spans: ``(start, end)`` indices of each block.
        tau: each sample's time from its block's mean time, in blocks.
    """

    __slots__ = ("spans", "starts", "tau")

    def __init__(self, t: FloatArray, block_s: float) -> None:
        n = max(int((t[-1] - t[0]) / block_s), 1)
        # a block with no sample (a gap in the series longer than a block) is dropped
        self.starts = np.unique(np.searchsorted(t, t[0] + block_s * np.arange(n, dtype=np.float64)))
        ends = np.append(self.starts[1:], t.size)
        self.spans = list(zip(self.starts.tolist(), ends.tolist(), strict=True))
        sizes = ends - self.starts
        index = np.repeat(np.arange(self.starts.size), sizes)
        self.tau = (t - (np.add.reduceat(t, self.starts) / sizes)[index]) / block_s

    def residual(self, X: FloatArray, V: FloatArray) -> FloatArray:
        """Each column of ``V`` less its least-squares fit on the columns of ``X``, block
        by block (one pseudo-inverse per block serves every column).

        Each block's normal matrix is pseudo-inverted: a block on one heading cannot
        tell a current from a level, and then just loses both together.
        """
        out = np.empty_like(V)
        for s, e in self.spans:
            Xb, Vb = X[s:e], V[s:e]
            out[s:e] = Vb - Xb @ (np.linalg.pinv(Xb.T @ Xb, rcond=1e-9) @ (Xb.T @ Vb))
        return out


def _multiple(
    y: FloatArray, ref: FloatArray, cos_h: FloatArray, sin_h: FloatArray, blocks: CurrentBlocks
) -> float:
    """Multiple correlation of y with ``ref`` and, per block, a level and a drifting current.

    Per block the regressors are ``[1, cos ψ, sin ψ, τ·cos ψ, τ·sin ψ]`` (τ the time in
    the block): they are projected out of y and ``ref``, the reference's one coefficient
    follows from the residuals (Frisch–Waugh), and the score is ``sqrt(1 − RSS/TSS)``,
    signed by that coefficient.
    """
    y0 = y - y.mean()
    tss = float(y0 @ y0)
    if tss <= 0.0:
        return 0.0
    tau = blocks.tau
    X = np.stack((np.ones_like(ref), cos_h, sin_h, tau * cos_h, tau * sin_h), axis=1)
    ey, er = blocks.residual(X, np.stack((y, ref), axis=1)).T
    rr = float(er @ er)
    if rr <= 0.0:
        return 0.0
    ry = float(er @ ey)
    r2 = max(1.0 - (float(ey @ ey) - ry * ry / rr) / tss, 0.0)
    return math.copysign(math.sqrt(min(r2, 1.0)), ry)


SMOOTH_S = 0.5
"""Both series are averaged over at least this window before correlating: the
reference's own noise, interpolated at every candidate lag, would otherwise make the
correlation curve jagged at the sample spacing (a 10 Hz DVL at ±1 cm/s)."""


def smooth(t: FloatArray, v: FloatArray, width_s: float) -> FloatArray:
    """Centred moving average over about ``width_s`` (in samples of the median spacing)."""
    if t.size < 3:
        return v
    k = round(width_s / float(np.median(np.diff(t))))
    if k < 2:
        return v
    half = k // 2
    c = np.concatenate(([0.0], np.cumsum(v)))
    idx = np.arange(v.size)
    lo = np.clip(idx - half, 0, v.size)
    hi = np.clip(idx + half + 1, 0, v.size)
    return np.asarray((c[hi] - c[lo]) / (hi - lo), dtype=np.float64)


COARSE_STEP_S = 0.5
"""The lags are first scored this far apart, then at every step within
``COARSE_STEP_S + PEAK_HALF_WIDTH_S`` of the best: the score is smooth at this scale
(both series are averaged over at least :data:`SMOOTH_S`), and the water-frame score
costs a fit per lag."""


def _curve(
    tk: FloatArray,
    vk: FloatArray,
    tr: FloatArray,
    vr: FloatArray,
    regress: tuple[FloatArray, FloatArray, FloatArray] | None,
    lags: FloatArray,
) -> FloatArray:
    """The correlation score at the candidate lags (−inf where not scored, see
    :data:`COARSE_STEP_S`)."""
    if regress is None:

        def score(lag: float) -> float:
            return _pearson(vk, np.interp(tk - lag, tr, vr))

    else:
        th, cos_h, sin_h = regress
        blocks = CurrentBlocks(tk, CURRENT_BLOCK_S)

        def score(lag: float) -> float:
            return _multiple(
                vk,
                np.interp(tk - lag, tr, vr),
                np.interp(tk - lag, th, cos_h),
                np.interp(tk - lag, th, sin_h),
                blocks,
            )

    corr = np.full(lags.size, -np.inf)
    step = float(lags[1] - lags[0]) if lags.size > 1 else 1.0
    every = max(round(COARSE_STEP_S / step), 1)
    coarse = sorted({*range(0, lags.size, every), lags.size - 1})
    for i in coarse:
        corr[i] = score(float(lags[i]))
    reach = every + math.ceil(PEAK_HALF_WIDTH_S / step) + 1
    filled: set[int] = set()
    while (best := int(np.argmax(corr))) not in filled:
        # around the best so far; again if the best moved near the edge of that
        filled.add(best)
        for i in range(max(best - reach, 0), min(best + reach, lags.size - 1) + 1):
            if corr[i] == -np.inf:
                corr[i] = score(float(lags[i]))
    return corr


def _peak(
    lags: FloatArray, corr: FloatArray, step_s: float, dof: int
) -> tuple[float, float, float, bool]:
    """``(lag, peak, std, at_bound)`` of a correlation curve (see the module docstring)."""
    i = int(np.argmax(corr))
    at_bound = i in (0, lags.size - 1)
    lag = float(lags[i])
    peak = float(corr[i])
    std = math.inf
    if at_bound:
        return lag, peak, std, at_bound
    # The residual fraction s = 1 − r² near its minimum is a parabola,
    # s(τ) ≈ s_min + A·(τ − τ̂)², fitted over ±PEAK_HALF_WIDTH_S (at least two grid
    # steps each side) so that what noise is left averages out. var(τ̂) = σ²/A with
    # σ² the residual fraction per degree of freedom (the least-squares result).
    half = max(2, round(PEAK_HALF_WIDTH_S / step_s))
    lo, hi = max(i - half, 0), min(i + half, lags.size - 1)
    tau = lags[lo : hi + 1] - lags[i]
    s_frac = 1.0 - corr[lo : hi + 1] * np.abs(corr[lo : hi + 1])
    A, B, C = (float(v) for v in np.polyfit(tau, s_frac, 2))
    if A > 0.0:
        vertex = -B / (2.0 * A)
        if abs(vertex) <= float(tau[-1] - tau[0]) / 2.0:
            lag = float(lags[i]) + vertex
            s_min = max(C - B * B / (4.0 * A), 0.0)
            peak = math.sqrt(max(1.0 - s_min, 0.0))
            if dof > 0:
                std = math.sqrt(s_min / dof / A)
    return lag, peak, std, at_bound


def _dof(t: FloatArray, water_frame: bool) -> int:
    """Degrees of freedom of the fit at the peak: the samples less the unknowns."""
    if not water_frame:
        return t.size - 2
    return t.size - 1 - 5 * CurrentBlocks(t, CURRENT_BLOCK_S).starts.size


def estimate_lag(
    t_meas: npt.ArrayLike,
    v_meas: npt.ArrayLike,
    t_ref: npt.ArrayLike,
    v_ref: npt.ArrayLike,
    max_lag_s: float,
    *,
    step_s: float | None = None,
    min_samples: int = 30,
    heading: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
    at_s: float | None = None,
    split: bool = True,
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
        heading: ``(t_h, heading_deg)`` of the heading at the reference's clock
            (strictly increasing times): score with the current modelled (see the
            module docstring).
        at_s: also score this lag (within ``±max_lag_s``) on the same samples
            (:attr:`LagEstimate.corr_at`): how much worse than the best a claimed lag is.
        split: widen σ by the disagreement of the window's two halves (below); False
            (a third of the cost): σ from the curvature alone.

    Returns:
        The lag, the peak correlation and diagnostics.

    Raises:
        DataError: bad series, too little overlap, or a non-positive max_lag_s/step_s.
    """
    tm, vm = checked_series("measurement", t_meas, v_meas)
    tr, vr = checked_series("reference", t_ref, v_ref)
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
    # Both series are smoothed over at least twice the coarser sample spacing: two 1 Hz
    # series sampled at whole seconds otherwise correlate best wherever their samples
    # line up (a comb of peaks a second apart); a symmetric average keeps the phase.
    width = max(SMOOTH_S, 2.0 * float(max(np.median(np.diff(tm)), np.median(np.diff(tr)))))
    # Never across a reference outage: a sample whose shifted time (or smoothing window)
    # could fall into a gap is left out, so the series is scored segment by segment.
    gap_s = max(MAX_GAP_S, GAP_SPACINGS * float(np.median(np.diff(tr))))
    for i in np.flatnonzero(np.diff(tr) > gap_s).tolist():
        keep &= (tm + reach + width <= tr[i]) | (tm - reach - width >= tr[i + 1])
    if int(np.count_nonzero(keep)) < min_samples:
        raise DataError(
            f"only {int(np.count_nonzero(keep))} measurement samples overlap the reference "
            f"within ±{reach:g} s (need {min_samples})"
        )
    vm = smooth(tm, vm, width)
    vr = smooth(tr, vr, width)
    tk = tm[keep]
    vk = vm[keep]
    regress: tuple[FloatArray, FloatArray, FloatArray] | None = None
    if heading is not None:
        th, psi = checked_series("heading", heading[0], heading[1])
        if th[0] > tk[0] - reach or th[-1] < tk[-1] + reach:
            keep_h = (tk - reach >= th[0]) & (tk + reach <= th[-1])
            if int(np.count_nonzero(keep_h)) < min_samples:
                raise DataError("the heading does not cover the measurement window")
            tk, vk = tk[keep_h], vk[keep_h]
        rad = np.radians(psi)
        regress = (th, np.cos(rad), np.sin(rad))
    corr = _curve(tk, vk, tr, vr, regress, lags)
    lag, peak, std, at_bound = _peak(lags, corr, step_s, _dof(tk, regress is not None))
    if split and not at_bound and tk.size >= 2 * min_samples:
        # The curvature's σ assumes white residuals; the two halves of the window
        # must also agree (a flat, jagged correlation peak does not repeat).
        half = tk.size // 2
        halves = [
            _peak(
                lags,
                _curve(tk[sl], vk[sl], tr, vr, regress, lags),
                step_s,
                _dof(tk[sl], regress is not None),
            )
            for sl in (slice(0, half), slice(half, None))
        ]
        if any(h[3] for h in halves):
            std = math.inf
        else:
            std = max(std, abs(halves[0][0] - halves[1][0]) / 2.0)
    corr_at = math.nan
    if at_s is not None:
        corr_at = float(_curve(tk, vk, tr, vr, regress, np.array([float(at_s)]))[0])
    return LagEstimate(lag, min(peak, 1.0), step_s, int(tk.size), at_bound, std, corr_at)
