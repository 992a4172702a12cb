"""Batch least squares LS-EM1..LS-EM4 (paper sections II-A and III-C-1), optionally in the water frame.

The paper fits ``raw − v_ref = H·θ`` with its design matrices (eqs. (18)–(21)). Here
the reference may be ground-referenced (DVL bottom track, GNSS): with a current
``c = (c_N, c_E)`` and the heading ψ the speed through the water along the hull is
``u = v_ref − c_N·cos ψ − c_E·sin ψ`` and the EMlog reads

    raw = f_θ(u) + η = a·u² + (1 + m)·u + b + η.

The unknowns are θ and, with ``current=True``, c. The cost ``J = Σ wₖ rₖ²`` (eq. (1))
is minimised by Gauss–Newton on the residuals ``r = raw − f_θ(u)`` with the Jacobian
columns ``∂f/∂θ = h(u)`` (the paper's rows) and ``∂f/∂c = −f'(u)·(cos ψ, sin ψ)``;
without a current the problem is the paper's linear one and a single step solves
it exactly (QR of the weighted Jacobian, never inverting ``HᵀH``).

Only what the data determine is estimated (:mod:`calib.excitation`): an unknown the
window does not determine is held at its prior (the given prior parameters, else
the ideal sensor; zero current) and reported as unidentifiable. When the current is
not separable from the bias a nuisance offset takes their sum, so a scale can still
be learnt from speed changes. With a current per block (``current_block_s``) a
parameter is held too when its standard deviation from that fit's information exceeds
the rule's bound: the rule judges one current over the window, and the blocks' currents
take whatever of a column follows the heading within each block. Standard errors are ``√diag(σ̂²·(JᵀWJ)⁻¹)`` over the
estimated unknowns with ``σ̂² = κ·Σwₖrₖ² / (Σwₖ/N̄·(N − p))``, where κ is the residuals'
correlation factor (:func:`calib.metrics.correlation_factor`, 1 for white residuals):
residuals correlated over seconds or minutes hold κ times fewer independent samples.
The identifiability verdicts use σ̂² without κ (the excitation rule's thresholds are
set on the white-noise figure: whether the manoeuvres separate the unknowns, not how
precisely this log's residuals let them be known).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.estimate import Estimate, Estimated
from calib.excitation import (
    DEFAULT_RULE,
    ExcitationRule,
    Identifiability,
    check_weights,
    heading_sectors,
    judge,
    window_stats,
)
from calib.metrics import correlation_factor
from calib.models import CURRENT, FloatArray, Layout, Params, check_model

_A, _M, _B, _CN, _CE, _D = range(6)
"""Indices of the full unknown vector ``[a, m, b, c_N, c_E, offset]``."""

_MAX_ITER = 30


@dataclass(frozen=True, slots=True)
class LsFit(Estimated):
    """Result of one least-squares calibration.

    Attributes:
        layout: the model and whether a current was estimated.
        estimate: θ̂ (an unknown the data do not determine at its prior), the standard
            error of each parameter (None: not determined) and the current with its
            standard errors (None when not estimated or not determined).
        rmse_mps: RMS of the fit residuals ``raw − f_θ(u)``, m/s (weighted RMS with weights).
        n_samples: number of samples N.
        ident: the verdict on every unknown (see :mod:`calib.excitation`).
        correlation: samples per independent sample of the residuals
            (:func:`calib.metrics.correlation_factor`); the standard errors are those
            of ``n_samples / correlation`` independent samples.
        current_blocks: with ``current_block_s``, each block's (start time s, north,
            east) current, m/s (empty: one current throughout).
    """

    layout: Layout
    estimate: Estimate
    rmse_mps: float
    n_samples: int
    ident: Identifiability
    correlation: float = 1.0
    current_blocks: tuple[tuple[float, float, float], ...] = ()

    @property
    def identifiable(self) -> bool:
        """Every unknown is determined."""
        return self.ident.identifiable

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """The unknowns the data do not determine."""
        return self.ident.unidentifiable

    @property
    def reason(self) -> str:
        """Why some unknowns are not determined (empty when all are)."""
        return self.ident.reason

    @property
    def cond_info(self) -> float:
        """Condition number of the information matrix over the determined unknowns."""
        return self.ident.cond_info


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


class _Problem:
    """The data of one fit, with the model's Jacobian at a point."""

    def __init__(
        self,
        ref: FloatArray,
        raw: FloatArray,
        cos_h: FloatArray,
        sin_h: FloatArray,
        sqrt_w: FloatArray | None,
        block: npt.NDArray[np.int64] | None = None,
        w_ref: float = 1.0,
    ) -> None:
        self.ref, self.raw, self.cos_h, self.sin_h, self.sqrt_w = ref, raw, cos_h, sin_h, sqrt_w
        self.w_ref = w_ref
        """The reference's weight in the operating point (1: the paper's, :func:`fit_ls`)."""
        self.block = block
        """Each sample's current block (0 … K−1), or None: one current throughout."""
        self.n_blocks = 1 if block is None or block.size == 0 else int(block.max()) + 1

    def current_at(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The current (north, east) at each sample: block 0's plus its block's offset."""
        cn = np.full(self.ref.size, x[_CN])
        ce = np.full(self.ref.size, x[_CE])
        if self.block is not None and self.n_blocks > 1:
            dn = np.concatenate([[0.0], x[_D + 1 :: 2]])
            de = np.concatenate([[0.0], x[_D + 2 :: 2]])
            cn = cn + dn[self.block]
            ce = ce + de[self.block]
        return cn, ce

    def u(self, x: FloatArray) -> FloatArray:
        """Speed through the water at the unknowns ``x``."""
        cn, ce = self.current_at(x)
        return np.asarray(self.ref - cn * self.cos_h - ce * self.sin_h, dtype=np.float64)

    def operating_point(self, x: FloatArray, u: FloatArray) -> FloatArray:
        """Where the correction ``a·v² + m·v + b`` is evaluated: ``u`` itself (``w_ref``
        1), else ``w_ref·u + (1 − w_ref)·`` the readings corrected at ``x``."""
        if self.w_ref >= 1.0:
            return u
        a, slope, off = x[_A], 1.0 + x[_M], self.raw - x[_B] - x[_D]
        if abs(a) < 1e-12:
            corr = off / slope
        else:
            disc = np.maximum(slope * slope + 4.0 * a * off, 0.0)
            corr = 2.0 * off / (slope + np.sqrt(disc))
        return np.asarray(
            np.where(np.isfinite(corr), self.w_ref * u + (1.0 - self.w_ref) * corr, u),
            dtype=np.float64,
        )

    def residual_jacobian(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        u = self.u(x)
        v = self.operating_point(x, u)
        pred = u + (x[_A] * v + x[_M]) * v + x[_B] + x[_D]
        r = self.raw - pred
        slope = 1.0 + self.w_ref * (2.0 * x[_A] * v + x[_M])
        cols = [v * v, v, np.ones_like(u), -slope * self.cos_h, -slope * self.sin_h]
        cols.append(np.ones_like(u))
        if self.block is not None:
            for j in range(1, self.n_blocks):
                inside = self.block == j
                cols += [np.where(inside, cols[_CN], 0.0), np.where(inside, cols[_CE], 0.0)]
        J = np.column_stack(cols)
        if self.sqrt_w is not None:
            r = r * self.sqrt_w
            J = J * self.sqrt_w[:, None]
        return np.asarray(r, dtype=np.float64), np.asarray(J, dtype=np.float64)


def _solve(
    problem: _Problem, x0: FloatArray, free: list[int]
) -> tuple[FloatArray, float, FloatArray]:
    """Gauss–Newton over the ``free`` unknowns; returns (x, weighted RSS, JᵀWJ over free)."""
    x = x0.copy()
    for _ in range(_MAX_ITER):
        r, J = problem.residual_jacobian(x)
        if not free:
            break
        Jf = J[:, free]
        step = np.linalg.lstsq(Jf, r, rcond=None)[0]
        x[free] += step
        if float(np.max(np.abs(step))) < 1e-12 * (1.0 + float(np.max(np.abs(x[free])))):
            break
    r, J = problem.residual_jacobian(x)
    Jf = J[:, free]
    return x, float(r @ r), Jf.T @ Jf


def fit_ls(
    model: str,
    ref_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
    *,
    heading_deg: npt.ArrayLike | None = None,
    current: bool = False,
    prior: Params | None = None,
    rule: ExcitationRule = DEFAULT_RULE,
    t_s: npt.ArrayLike | None = None,
    current_block_s: float | None = None,
    noise_ratio: float | None = None,
) -> LsFit:
    """LS-EMx: fit one error model (and the current) to aligned series.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        ref_mps: reference speeds along the hull in m/s, shape (N,), lag-aligned
            (over the ground when ``current``).
        raw_mps: raw EMlog speeds in m/s, shape (N,).
        weights: optional non-negative sample weights, shape (N,) (e.g. 1/σₖ²).
        heading_deg: heading at the reference's time, degrees, shape (N,) (needed
            with ``current``; without it only the sector verdict uses it).
        current: estimate the sea current.
        prior: value of any parameter the data do not determine (default the ideal
            sensor).
        rule: identifiability thresholds.
        t_s: sample times, s, shape (N,), non-decreasing (needed with ``current_block_s``).
        current_block_s: with ``current``, a current of its own for each block of this
            many seconds (None: one current throughout). A current that turns with the
            tide over hours, fitted as one, leaves its change to the scale and the bias;
            piecewise, each block's current comes from that block's headings. A block
            whose heading covers fewer than ``rule.min_heading_sectors`` sectors cannot
            tell its current from the bias: it joins the block before it (the first
            block, the one after).

        noise_ratio: the reference's noise variance over the reading's, σ²_ref/σ²_raw
            (None: the paper's fit, the correction evaluated at the reference's speed).
            Given, the correction is evaluated at the variance-weighted speed
            ``v = w·u + (1 − w)·f⁻¹(raw)``, ``w = 1/(1 + noise_ratio·f'²)``, as the
            Kalman filter does with block means (:mod:`calib.kalman.filters`): the
            reference's noise no longer pulls the scale down (errors in variables).

    Returns:
        The fit; never raises on poor excitation (see ``ident``). With blocks,
        ``current_mps`` is their sample-weighted mean and ``current_blocks`` each one.

    Raises:
        ModelError: unknown model, prior of another model.
        DataError: bad series, weights or headings.
    """
    name = check_model(model)
    ref, raw = check_pair(ref_mps, raw_mps)
    n = ref.size
    w = check_weights(weights, n)
    layout = Layout(name, current)
    hd = _checked_heading(heading_deg, n, current)
    if prior is not None and prior.model != name:
        raise DataError(f"prior parameters are {prior.model}, the fit is {name}")
    psi = np.radians(hd) if hd is not None else np.zeros(n)
    block = None
    if current and current_block_s is not None and hd is not None:
        block = current_blocks(t_s, hd, current_block_s, rule.min_heading_sectors)
    w_ref = _reference_weight(noise_ratio, prior)
    problem = _Problem(
        ref, raw, np.cos(psi), np.sin(psi), None if w is None else np.sqrt(w), block, w_ref
    )
    k = problem.n_blocks
    x0 = np.zeros(6 + 2 * (k - 1))
    if prior is not None:
        x0[_A], x0[_M], x0[_B] = prior.a_spm, prior.m, prior.b_mps
    index = {"a": [_A], "m": [_M], "b": [_B], CURRENT: [_CN, _CE, *range(_D + 1, x0.size)]}
    w_mean = 1.0 if w is None else float(np.sum(w)) / n
    ident = judge(layout, window_stats(ref, raw, hd, w), 0.0, rule)
    x, rss, info = x0, math.nan, np.zeros((0, 0))
    for _ in range(len(layout.unknowns) + 1):
        free = _free(ident, index)
        x, rss, info = _solve(problem, x0, free)
        dof = max(n - len(free), 1)
        sigma2 = rss / (w_mean * dof)
        u = problem.u(x)
        new = judge(layout, window_stats(u, raw, hd, w), sigma2, rule)
        if new.determined == ident.determined and new.nuisance_offset == ident.nuisance_offset:
            ident = new
            break
        ident = new
    ident = _judged_with_blocks(problem, x0, ident, index, w_mean, rule)
    free = _free(ident, index)
    x, rss, info = _solve(problem, x0, free)
    dof = max(n - len(free), 1)
    factor = correlation_factor(problem.residual_jacobian(x)[0])
    sigma2 = rss / (w_mean * dof)
    std = np.full(x0.size, math.nan)
    cov_full = np.full((x0.size, x0.size), math.nan)
    if free and n > len(free):
        try:
            cov = factor * sigma2 * w_mean * np.linalg.inv(info)
            std[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
            cov_full[np.ix_(free, free)] = cov
        except np.linalg.LinAlgError:
            std[free] = math.inf
    params = Params.from_theta(
        name, [float(x[{"a": _A, "m": _M, "b": _B}[p]]) for p in layout.params]
    )
    determined = set(ident.determined)
    stderr = {
        p: (float(std[{"a": _A, "m": _M, "b": _B}[p]]) if p in determined else None)
        for p in layout.params
    }
    cur = cur_std = None
    blocks: tuple[tuple[float, float, float], ...] = ()
    if current and CURRENT in determined:
        cur = (float(x[_CN]), float(x[_CE]))
        cur_std = (float(std[_CN]), float(std[_CE]))
        if k > 1 and block is not None:
            cur, cur_std, blocks = _block_currents(problem, x, cov_full, block, t_s)
    return LsFit(
        layout=layout,
        estimate=Estimate(params, stderr, cur, cur_std),
        rmse_mps=math.sqrt(rss / (w_mean * n)),
        n_samples=n,
        ident=ident,
        correlation=factor,
        current_blocks=blocks,
    )


def _checked_heading(heading_deg: npt.ArrayLike | None, n: int, current: bool) -> FloatArray | None:
    """:func:`fit_ls`'s heading as an array of ``n`` finite values (None without one).

    Raises:
        DataError: not finite or not as long as the speeds, or none with ``current``.
    """
    hd: FloatArray | None = None
    if heading_deg is not None:
        hd = np.asarray(heading_deg, dtype=np.float64).reshape(-1)
        if hd.shape != (n,) or not np.all(np.isfinite(hd)):
            raise DataError("heading must be finite and as long as the speeds")
    if current and hd is None:
        raise DataError("a fit with the current needs the heading")
    return hd


def _reference_weight(noise_ratio: float | None, prior: Params | None) -> float:
    """The reference's weight in the operating point (1: the reference's speed alone;
    see :func:`fit_ls`'s ``noise_ratio``).

    Raises:
        DataError: a noise ratio that is negative or not finite.
    """
    if noise_ratio is None:
        return 1.0
    if not (math.isfinite(noise_ratio) and noise_ratio >= 0.0):
        raise DataError(f"noise_ratio must be finite and non-negative, not {noise_ratio!r}")
    slope0 = 1.0 + (prior.m if prior is not None else 0.0)
    return 1.0 / (1.0 + noise_ratio * slope0 * slope0)


def _judged_with_blocks(
    problem: _Problem,
    x0: FloatArray,
    ident: Identifiability,
    index: dict[str, list[int]],
    w_mean: float,
    rule: ExcitationRule,
) -> Identifiability:
    """``ident`` with every parameter held whose standard deviation, from the information
    of the fit with a current per block, exceeds the rule's bound (σ̂² without κ, as
    the rule). The rule judges one current over the window; a current per block also
    takes whatever of a parameter's column follows the heading within each block (a
    scale whose speed changes with the heading, the speed changing from one block to
    the next), and what the blocks' currents can take the data do not determine."""
    if problem.n_blocks <= 1:
        return ident
    free = _free(ident, index)
    _, rss, info = _solve(problem, x0, free)
    sigma2 = rss / (w_mean * max(problem.raw.size - len(free), 1))
    try:
        var = np.diag(np.linalg.inv(info)) * sigma2 * w_mean
    except np.linalg.LinAlgError:
        var = np.full(len(free), math.inf)
    verdicts = []
    for v in ident.verdicts:
        if v.determined and v.unknown != CURRENT:
            std = math.sqrt(max(float(var[free.index(index[v.unknown][0])]), 0.0))
            if not std <= rule.max_std(v.unknown):
                what = "scale" if v.unknown in ("a", "m") else "bias"
                why = (
                    f"{what} not determinable with a current per block: standard error "
                    f"{std:.3g} > {rule.max_std(v.unknown):g}"
                )
                v = replace(v, determined=False, reason=why, std=None)
        verdicts.append(v)
    return replace(ident, verdicts=tuple(verdicts))


def _free(ident: Identifiability, index: dict[str, list[int]]) -> list[int]:
    """The columns of the unknowns ``ident`` determines, and the nuisance offset's when
    it takes the bias."""
    free = sorted(i for u in ident.determined for i in index[u])
    if ident.nuisance_offset and "b" not in ident.determined:
        free.append(_D)
    return free


def _block_currents(
    problem: _Problem,
    x: FloatArray,
    cov_full: FloatArray,
    block: npt.NDArray[np.int64],
    t_s: npt.ArrayLike | None,
) -> tuple[tuple[float, float], tuple[float, float], tuple[tuple[float, float, float], ...]]:
    """With a current per block: their sample-weighted mean and its standard deviation,
    and each block's (start time s, north, east) current, m/s."""
    k, n = problem.n_blocks, block.size
    cn, ce = problem.current_at(x)
    share = np.bincount(block, minlength=k) / n
    g = np.zeros((2, x.size))
    g[0, _CN] = g[1, _CE] = 1.0
    g[0, _D + 1 :: 2] = share[1:]
    g[1, _D + 2 :: 2] = share[1:]
    var = np.einsum("ij,jk,ik->i", g, np.nan_to_num(cov_full, nan=0.0), g)
    cur = (float(np.mean(cn)), float(np.mean(ce)))
    cur_std = (math.sqrt(max(var[0], 0.0)), math.sqrt(max(var[1], 0.0)))
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    first = np.flatnonzero(np.concatenate([[True], block[1:] != block[:-1]]))
    return cur, cur_std, tuple((float(t[i]), float(cn[i]), float(ce[i])) for i in first)


def current_blocks(
    t_s: npt.ArrayLike | None,
    heading_deg: FloatArray,
    block_s: float,
    min_sectors: int,
) -> npt.NDArray[np.int64]:
    """Each sample's current block for :func:`fit_ls` (0 … K−1, in time order).

    Blocks of ``block_s`` from the first sample; one whose heading covers fewer than
    ``min_sectors`` 45° sectors joins the block before it (the first, the one after).

    Raises:
        DataError: no times, times of another length or decreasing, a bad block length.
    """
    if t_s is None:
        raise DataError("a current per block needs the sample times")
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    if t.shape != heading_deg.shape or not np.all(np.isfinite(t)):
        raise DataError("times must be finite and as long as the speeds")
    if t.size > 1 and not np.all(np.diff(t) >= 0.0):
        raise DataError("times must not decrease")
    if not (math.isfinite(block_s) and block_s > 0.0):
        raise DataError(f"current_block_s must be > 0, not {block_s!r}")
    if t.size == 0:
        return np.zeros(0, dtype=np.int64)
    raw_id = np.floor((t - t[0]) / block_s).astype(np.int64)
    ids = np.unique(raw_id)
    good = [heading_sectors(heading_deg[raw_id == i]) >= min_sectors for i in ids]
    merged: dict[int, int] = {}
    last_good: int | None = None
    pending: list[int] = []
    for i, ok in zip(ids.tolist(), good, strict=True):
        if ok:
            last_good = i
            merged[i] = i
            for p in pending:
                merged[p] = i
            pending = []
        elif last_good is None:
            pending.append(i)
        else:
            merged[i] = last_good
    for p in pending:  # no block determines a current: one current throughout
        merged[p] = int(ids[0])
    target = np.array([merged[i] for i in raw_id.tolist()], dtype=np.int64)
    _, dense = np.unique(target, return_inverse=True)
    return np.asarray(dense.reshape(-1), dtype=np.int64)


def fit_current(
    params: Params,
    ref_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike,
    *,
    rule: ExcitationRule = DEFAULT_RULE,
) -> tuple[float, float] | None:
    """The current that best explains a segment with the sensor's parameters frozen.

    What scoring a frozen calibration on another segment needs: the current there is
    the sea's, not the sensor's, so it is estimated from that segment (north and
    east, Gauss–Newton with θ fixed) and the corrected speed compared with the
    reference minus the projected current.

    Args:
        params: the frozen parameters.
        ref_mps: reference over the ground along the hull, m/s, shape (N,).
        raw_mps: raw readings, m/s, shape (N,).
        heading_deg: headings at the reference's time, degrees, shape (N,).
        rule: the heading-sector threshold of the identifiability rule.

    Returns:
        (north, east) in m/s, or None when the heading covers too few sectors for the
        current to be separable from a bias.

    Raises:
        DataError: bad series.
    """
    ref, raw = check_pair(ref_mps, raw_mps)
    hd = np.asarray(heading_deg, dtype=np.float64).reshape(-1)
    if hd.shape != ref.shape or not np.all(np.isfinite(hd)):
        raise DataError("heading must be finite and as long as the speeds")
    if heading_sectors(hd) < rule.min_heading_sectors:
        return None
    psi = np.radians(hd)
    problem = _Problem(ref, raw, np.cos(psi), np.sin(psi), None)
    x0 = np.zeros(6)
    x0[_A], x0[_M], x0[_B] = params.a_spm, params.m, params.b_mps
    x, _, _ = _solve(problem, x0, [_CN, _CE])
    return float(x[_CN]), float(x[_CE])


@dataclass(frozen=True, slots=True)
class Averaged:
    """Block means of a series (:func:`block_average`)."""

    t: FloatArray
    raw: FloatArray
    ref: FloatArray
    heading_deg: FloatArray


MIN_HEADING_COHERENCE = 0.9
"""A block is kept when its mean heading vector is at least this long (1: a steady
heading; 0.9: a turn of about 50° inside the block)."""

BLOCK_MAX_GAP_S = 5.0
"""The longest gap between two samples of one block, s."""


def block_average(
    t_s: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    ref_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike | None,
    window_s: float,
    *,
    max_gap_s: float = BLOCK_MAX_GAP_S,
) -> Averaged:
    """Means of consecutive ``window_s`` blocks, for a fit on a noisy reference.

    Least squares of the reading on a reference with noise of its own underestimates
    the scale (errors in the regressor: the slope shrinks by var(u)/(var(u) + σ²)).
    A GNSS speed projected on the hull has σ ≈ 0.3 m/s against speed changes of about
    1 m/s: 8 % off. Averaging over blocks much longer than the noise's correlation time
    and shorter than the manoeuvres keeps the speed changes and divides the noise
    variance by the samples in a block. The model is linear in the current's
    direction cosines, so a block's heading is the direction of its mean heading
    vector; a block turning too much to have one (:data:`MIN_HEADING_COHERENCE`), one
    less than half full, or one spanning a gap longer than ``max_gap_s`` is dropped.

    Args:
        t_s: sample times, s, increasing.
        raw_mps: readings, m/s.
        ref_mps: reference, m/s.
        heading_deg: headings (None: no current in the fit), degrees.
        window_s: the block length, s (> 0).
        max_gap_s: the longest gap inside a block, s.

    Raises:
        DataError: series of different lengths, times not increasing, a bad window.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    hd = (
        np.zeros_like(t)
        if heading_deg is None
        else np.asarray(heading_deg, dtype=np.float64).reshape(-1)
    )
    if not (t.shape == raw.shape == ref.shape == hd.shape):
        raise DataError("time, readings, reference and heading must have the same length")
    if not (math.isfinite(window_s) and window_s > 0.0):
        raise DataError(f"window_s must be > 0, not {window_s!r}")
    if t.size > 1 and not np.all(np.diff(t) >= 0.0):
        raise DataError("times must not decrease")
    empty = np.empty(0)
    if t.size == 0:
        return Averaged(empty, empty, empty, empty)
    spacing = float(np.median(np.diff(t))) if t.size > 1 else window_s
    need = max(1, math.ceil(0.5 * window_s / max(spacing, 1e-9)))
    gap_before = np.concatenate([[np.inf], np.diff(t)]) > max_gap_s
    segment = np.cumsum(gap_before)
    block = np.floor((t - t[0]) / window_s).astype(np.int64)
    key = segment * (int(block.max()) + 1) + block
    starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    counts = np.diff(np.concatenate([starts, [t.size]]))
    psi = np.radians(hd)

    def mean(x: FloatArray) -> FloatArray:
        return np.add.reduceat(x, starts) / counts

    c, s = mean(np.cos(psi)), mean(np.sin(psi))
    keep = (counts >= need) & (np.hypot(c, s) >= MIN_HEADING_COHERENCE)
    return Averaged(
        mean(t)[keep],
        mean(raw)[keep],
        mean(ref)[keep],
        np.degrees(np.arctan2(s, c))[keep] % 360.0,
    )
