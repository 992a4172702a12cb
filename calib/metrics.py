"""Accuracy and consistency metrics (paper section IV-C).

- RMSE of reference minus corrected speed (eq. (28)) and the improvement over raw,
  ``100·(1 − RMSE_cal/RMSE_raw)`` %, as in the paper's Tables II and III;
- the RMSE in the water frame (:func:`water_rmse`): the reference minus the current
  *of each sample's time* projected on the hull, against the raw or corrected
  reading — the one definition ``calibrate``, ``evaluate``, ``crossval`` and the trace
  use (a current taken at its final value over a whole log would score the raw reading
  against a current it never saw);
- the correlation of residuals (:func:`correlation_factor`): how many times fewer
  independent samples a series holds than samples, for standard errors that do not
  take correlated residuals (GNSS errors over seconds, a sailing log's tack-dependent
  error over minutes) for independent ones;
- the IMO accuracy verdict (:func:`imo_verdict`): IMO resolution A.824(19), as amended
  by MSC.96(72), asks a speed log's error not to exceed 2 % of the ship's speed or
  0.2 kn, whichever is greater; the fraction of samples within that bound and whether
  the log meets it (at least :data:`IMO_MEETS_FRACTION` of them within);
- NIS statistics (eqs. (29)–(31)): for a consistent filter with a scalar
  measurement each NISₖ is χ²(1), so its mean is 1 and 95 % of the samples fall
  inside the two-sided 95 % χ²(1) bounds [0.00098, 5.024]. The filter is declared
  **consistent** when the sample mean lies inside the two-sided 95 % interval of
  χ²(N)/N (Wilson–Hilferty approximation) — the classical test of
  Bar-Shalom et al. (2001) — which assumes uncorrelated innovations.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.models import FloatArray, Params, zero_params


def rmse(ref_mps: npt.ArrayLike, est_mps: npt.ArrayLike) -> float:
    """Root-mean-square error (eq. (28)), ignoring samples where either is nan.

    Args:
        ref_mps: reference speeds in m/s, shape (N,).
        est_mps: estimated (raw or corrected) speeds in m/s, shape (N,).

    Returns:
        The RMSE in m/s.

    Raises:
        DataError: different shapes or no finite pair.
    """
    ref = np.asarray(ref_mps, dtype=np.float64)
    est = np.asarray(est_mps, dtype=np.float64)
    if ref.shape != est.shape:
        raise DataError(f"shapes differ: {ref.shape} and {est.shape}")
    d = ref - est
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise DataError("no finite sample pair for the RMSE")
    return math.sqrt(float(np.dot(d, d)) / d.size)


def water_target(
    ref_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike | None,
    current_mps: npt.ArrayLike | None,
) -> FloatArray:
    """The speed through the water along the hull the reference implies, m/s.

    ``ref − c_N·cos ψ − c_E·sin ψ`` with the current of each sample's time.

    Args:
        ref_mps: reference speeds along the hull (over the ground), m/s, shape (N,).
        heading_deg: headings, degrees, shape (N,) (None: no current).
        current_mps: the current (north, east) per sample, shape (N, 2), or one
            (north, east) pair for every sample; None: no current (the reference as is).
            A nan current (not determined at that time) leaves that sample's reference
            as it is.

    Raises:
        DataError: shapes that do not match.
    """
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    if current_mps is None or heading_deg is None:
        return ref.copy()
    hd = np.asarray(heading_deg, dtype=np.float64).reshape(-1)
    cur = np.asarray(current_mps, dtype=np.float64)
    if cur.shape == (2,):
        cur = np.broadcast_to(cur, (ref.size, 2))
    if hd.shape != ref.shape or cur.shape != (ref.size, 2):
        raise DataError(
            f"reference {ref.shape}, heading {hd.shape} and current {cur.shape} do not match"
        )
    psi = np.radians(hd)
    proj = cur[:, 0] * np.cos(psi) + cur[:, 1] * np.sin(psi)
    return np.asarray(np.where(np.isfinite(proj), ref - proj, ref), dtype=np.float64)


def water_rmse(
    ref_mps: npt.ArrayLike,
    est_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike | None = None,
    current_mps: npt.ArrayLike | None = None,
) -> float:
    """RMSE of a reading (raw or corrected) against the water speed of :func:`water_target`.

    Args:
        ref_mps: reference speeds along the hull, m/s, shape (N,).
        est_mps: the raw or corrected readings, m/s, shape (N,).
        heading_deg: headings, degrees (None: no current).
        current_mps: per-sample (N, 2) or one (north, east) current, m/s; None: none.

    Raises:
        DataError: shapes that differ, or no finite pair.
    """
    return rmse(water_target(ref_mps, heading_deg, current_mps), est_mps)


CURRENT_WINDOW_S = 1800.0
"""The window over which :func:`water_targets` takes the current as constant, s: long
enough for the heading to cover the sectors that tell a current from a bias (a yacht
tacks, a survey turns), short against a tide (a tidal current turns in hours)."""


def water_scores(
    targets: tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
) -> tuple[float, float]:
    """RMSE of the raw and of the corrected reading in the water frame: the one definition.

    Each reading against the water speed :func:`water_targets` gives it (the same
    targets :func:`water_imo` judges): the reference, or with headings the reference
    minus the current of its time projected on the hull.

    Args:
        targets: what :func:`water_targets` returns for the readings.

    Returns:
        ``(rmse_raw, rmse_corrected)``, m/s; nan for a reading with no target at all.

    Raises:
        DataError: a reading with targets but no finite pair.
    """
    out = [rmse(target, est) if np.isfinite(target).any() else math.nan for target, est in targets]
    return out[0], out[1]


def water_targets(
    t_s: npt.ArrayLike,
    ref_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    corrected_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike | None,
    params: Params,
    *,
    window_s: float = CURRENT_WINDOW_S,
    min_heading_sectors: int = 3,
) -> tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]:
    """The water speed each reading is scored against (:func:`water_scores`,
    :func:`water_imo`): the one definition.

    Without headings: the reference. With them, for each reading the reference minus
    the current of its time, projected on the hull: the current that best explains each ``window_s`` window (:func:`calib.lsq.fit_current`) for that
    reading's own calibration — the ideal sensor for the raw reading, ``params`` for
    the corrected one — so the raw RMSE of a series is the same whatever method
    calibrated it, and a current that turns over hours is followed. A window whose
    heading covers fewer than ``min_heading_sectors`` 45° sectors takes the whole
    series' current; without one either, that window is scored against the reference.

    Args:
        t_s: sample times, s, shape (N,), non-decreasing.
        ref_mps: reference along the hull (over the ground), m/s.
        raw_mps: raw readings, m/s.
        corrected_mps: the readings corrected with ``params``, m/s.
        heading_deg: headings, degrees (None: no current).
        params: the calibration that corrected them.
        window_s: the window, s (> 0).
        min_heading_sectors: sectors a window needs to determine its current.

    Returns:
        ``((target_raw, raw), (target_corrected, corrected))``: per sample, the target
        (nan where a sample is not scored) beside the reading, m/s.

    Raises:
        DataError: shapes that differ, or a window that is not positive.
    """
    from calib.excitation import ExcitationRule
    from calib.lsq import fit_current  # calib.lsq imports this module

    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    cor = np.asarray(corrected_mps, dtype=np.float64).reshape(-1)
    if not t.shape == ref.shape == raw.shape == cor.shape:
        raise DataError("time, reference, raw and corrected must have the same length")
    if heading_deg is None:
        return (ref, raw), (ref, cor)
    hd = np.asarray(heading_deg, dtype=np.float64).reshape(-1)
    if hd.shape != t.shape:
        raise DataError("the heading must be as long as the speeds")
    if not (math.isfinite(window_s) and window_s > 0.0):
        raise DataError(f"window_s must be > 0, not {window_s!r}")
    rule = ExcitationRule(min_heading_sectors=min_heading_sectors)
    ok = np.isfinite(t) & np.isfinite(ref) & np.isfinite(raw) & np.isfinite(hd)
    out = []
    for p, est in ((zero_params(params.model), raw), (params, cor)):
        cur = np.full((t.size, 2), math.nan)
        good = ok & np.isfinite(est)
        if good.any():
            whole = fit_current(p, ref[good], raw[good], hd[good], rule=rule)
            t0 = float(t[good][0])
            win = np.floor((t - t0) / window_s)
            for w in np.unique(win[good]):
                sel = good & (win == w)
                c = fit_current(p, ref[sel], raw[sel], hd[sel], rule=rule) or whole
                if c is not None:
                    cur[sel] = c
        target = np.full(t.size, math.nan)
        if good.any():
            target[good] = water_target(ref[good], hd[good], cur[good])
        out.append((target, est))
    return out[0], out[1]


def water_imo(
    targets: tuple[tuple[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
) -> tuple[ImoVerdict, ImoVerdict]:
    """The IMO verdict (:func:`imo_verdict`) of the raw and the corrected reading against
    the same water speed :func:`water_scores` scores them against.

    Args:
        targets: what :func:`water_targets` returns for the readings.
    """
    (t_raw, raw), (t_cor, cor) = targets
    return imo_verdict(t_raw, raw), imo_verdict(t_cor, cor)


KNOT_MPS = 1852.0 / 3600.0
"""One knot in m/s."""

IMO_SPEED_FRACTION = 0.02
"""IMO A.824(19) (MSC.96(72)): the error may reach this fraction of the ship's speed..."""

IMO_MIN_ERROR_MPS = 0.2 * KNOT_MPS
"""...or 0.2 kn, whichever is greater (the two meet at 10 kn)."""

IMO_MEETS_FRACTION = 0.95
"""A log meets the bound when at least this fraction of its samples are within it. The
resolution states a bound, not a statistic; a recorded series always holds a few
samples taken in a turn, at a reference outage's edge or through a wave, so "every
sample" would fail a log for one outlier. 95 % is the confidence level IMO's
navigation-equipment standards state accuracies at (e.g. the GNSS receivers'
position accuracy), and it is what a log whose error is normally distributed with a
standard deviation of half the bound achieves (95.4 % within two standard
deviations)."""

IMO_BOUND_RTOL = 1e-9
"""Relative slack on the bound, so that an error of exactly 2 % or 0.2 kn (computed
through m/s in floating point) counts as within it, as the resolution's "not exceed"
says."""


@dataclass(frozen=True, slots=True)
class ImoVerdict:
    """The IMO A.824(19) verdict over a series of samples."""

    n: int
    """Samples with a finite reference and reading."""
    within: int
    """Of those, the samples whose error does not exceed the bound."""
    meets: bool
    """At least :data:`IMO_MEETS_FRACTION` of ``n`` within (False when ``n`` is 0)."""

    @property
    def fraction(self) -> float:
        """The fraction of samples within the bound (nan without samples)."""
        return self.within / self.n if self.n else math.nan

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: ``n``, ``within``, ``fraction`` (None without samples), ``meets``."""
        return {
            "n": self.n,
            "within": self.within,
            "fraction": self.fraction if self.n else None,
            "meets": self.meets,
        }


def imo_bound_mps(speed_mps: npt.ArrayLike) -> FloatArray:
    """The largest error IMO A.824(19) allows at each speed: ``max(2 % · |v|, 0.2 kn)``, m/s."""
    v = np.abs(np.asarray(speed_mps, dtype=np.float64))
    return np.maximum(IMO_SPEED_FRACTION * v, IMO_MIN_ERROR_MPS)


def imo_bound_one_mps(speed_mps: float) -> float:
    """:func:`imo_bound_mps` at one speed, over a Python float (a per-sample score)."""
    return max(IMO_SPEED_FRACTION * abs(speed_mps), IMO_MIN_ERROR_MPS)


def imo_verdict(
    ref_mps: npt.ArrayLike,
    est_mps: npt.ArrayLike,
    *,
    meets_fraction: float = IMO_MEETS_FRACTION,
) -> ImoVerdict:
    """How many samples meet IMO A.824(19)'s accuracy bound, and whether the log does.

    The ship's speed of the bound is the reference's (the speed the log should read);
    samples where either is nan are left out.

    Args:
        ref_mps: the reference (or true) speeds, m/s, shape (N,).
        est_mps: the raw or corrected readings, m/s, shape (N,).
        meets_fraction: the fraction of samples that must be within the bound.

    Raises:
        DataError: different shapes, or ``meets_fraction`` outside [0, 1].
    """
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    est = np.asarray(est_mps, dtype=np.float64).reshape(-1)
    if ref.shape != est.shape:
        raise DataError(f"shapes differ: {ref.shape} and {est.shape}")
    if not 0.0 <= meets_fraction <= 1.0:
        raise DataError(f"meets_fraction must be within [0, 1], not {meets_fraction!r}")
    ok = np.isfinite(ref) & np.isfinite(est)
    err = np.abs(est[ok] - ref[ok])
    within = int(np.count_nonzero(err <= imo_bound_mps(ref[ok]) * (1.0 + IMO_BOUND_RTOL)))
    n = int(ok.sum())
    return ImoVerdict(n=n, within=within, meets=n > 0 and within >= meets_fraction * n)


MAX_CORRELATION_FACTOR = 100.0
"""The largest :func:`correlation_factor` (a series with fewer than 1 % of its samples
independent says nothing more precise than that)."""


def correlation_factor(residuals: npt.ArrayLike) -> float:
    """How many samples of a series make one independent sample: ``N / N_eff``.

    ``1 + 2·Σ ρₖ`` over the lags k ≥ 1 of the residuals' autocorrelation, summed
    while it stays positive (Geyer's initial positive sequence) and up to N/4 lags:
    the variance of a mean, or of a least-squares estimate, of residuals correlated
    this way is this many times what independent residuals would give. 1 for white
    residuals; at least 1, at most :data:`MAX_CORRELATION_FACTOR`. Nan entries are
    dropped; fewer than 8 finite samples: 1 (too few to tell).

    Args:
        residuals: the residuals in time order, shape (N,).
    """
    r = np.asarray(residuals, dtype=np.float64).reshape(-1)
    r = r[np.isfinite(r)]
    n = r.size
    if n < 8:
        return 1.0
    r = r - float(np.mean(r))
    var = float(np.dot(r, r))
    if var <= 0.0:
        return 1.0
    m = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(r, m)
    acf = np.fft.irfft(f * np.conj(f), m)[: n // 4 + 1] / var
    total = 1.0
    for rho in acf[1:]:
        if not rho > 0.0:
            break
        total += 2.0 * float(rho)
    return float(min(max(total, 1.0), MAX_CORRELATION_FACTOR))


def improvement_pct(rmse_raw_mps: float, rmse_cal_mps: float) -> float:
    """Relative RMSE reduction ``100·(1 − cal/raw)`` in % (negative: calibration hurt).

    Args:
        rmse_raw_mps: RMSE of the raw readings, m/s (> 0).
        rmse_cal_mps: RMSE of the corrected readings, m/s.

    Returns:
        The improvement in percent (``nan`` when the raw RMSE is 0).
    """
    if rmse_raw_mps <= 0.0:
        return math.nan
    return 100.0 * (1.0 - rmse_cal_mps / rmse_raw_mps)


def chi2_1_quantile(p: float) -> float:
    """Quantile of the χ²(1) distribution: ``x`` with ``P(X ≤ x) = p``.

    Args:
        p: probability in (0, 1).

    Returns:
        ``z²`` with z the standard-normal quantile of ``(1 + p)/2``.
    """
    z = NormalDist().inv_cdf(0.5 * (1.0 + p))
    return z * z


def chi2_mean_bounds(n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds of the mean of n independent χ²(1) samples (χ²(n)/n).

    Wilson–Hilferty: ``χ²_p(n) ≈ n·(1 − 2/(9n) + z_p·√(2/(9n)))³``.

    Args:
        n: number of samples (≥ 1).
        confidence: two-sided confidence level.

    Returns:
        ``(lower, upper)`` for the sample mean.
    """
    c = 2.0 / (9.0 * n)
    z = NormalDist().inv_cdf(0.5 * (1.0 + confidence))
    lo = max(1.0 - c - z * math.sqrt(c), 0.0) ** 3
    hi = (1.0 - c + z * math.sqrt(c)) ** 3
    return lo, hi


@dataclass(frozen=True, slots=True)
class NisStats:
    """Summary of a NIS series.

    Attributes:
        n: number of finite NIS samples used.
        mean: their mean (1 for a consistent filter).
        frac_inside: fraction inside ``[lower, upper]`` (≈ ``confidence``).
        lower: lower χ²(1) bound of a single sample.
        upper: upper χ²(1) bound of a single sample.
        mean_lower: lower bound of the mean (χ²(n)/n).
        mean_upper: upper bound of the mean.
        consistent: ``mean_lower ≤ mean ≤ mean_upper``.
    """

    n: int
    mean: float
    frac_inside: float
    lower: float
    upper: float
    mean_lower: float
    mean_upper: float
    consistent: bool


def nis_stats(nis: npt.ArrayLike, *, confidence: float = 0.95, skip: int = 0) -> NisStats:
    """NIS mean, fraction inside the χ²(1) bounds, and the consistency verdict.

    Args:
        nis: NIS series, shape (N,); nan entries (no update) are ignored.
        confidence: two-sided level of the bounds (0.95 as in the paper's figure).
        skip: leading samples to drop (initial convergence transient).

    Returns:
        The statistics.

    Raises:
        DataError: no finite NIS sample, or a confidence outside (0, 1).
    """
    if not 0.0 < confidence < 1.0:
        raise DataError("confidence must be in (0, 1)")
    a = np.asarray(nis, dtype=np.float64).reshape(-1)[skip:]
    a = a[np.isfinite(a)]
    if a.size == 0:
        raise DataError("no finite NIS sample")
    lower = chi2_1_quantile((1.0 - confidence) / 2.0)
    upper = chi2_1_quantile((1.0 + confidence) / 2.0)
    mean = float(np.mean(a))
    inside = float(np.mean((a >= lower) & (a <= upper)))
    m_lo, m_hi = chi2_mean_bounds(a.size, confidence)
    return NisStats(
        n=int(a.size),
        mean=mean,
        frac_inside=inside,
        lower=lower,
        upper=upper,
        mean_lower=m_lo,
        mean_upper=m_hi,
        consistent=m_lo <= mean <= m_hi,
    )
