"""Excitation and identifiability of every unknown, in the water frame (paper section III-B).

What a calibration estimates are its *unknowns*: the error-model parameters (``a``,
``m``, ``b``) and, in the water frame, the sea current (``current``: north and east).
The paper shows (eqs. (14)–(17)) that for EM3 ``det(HᵀH) = N²·var(v)``: at constant
speed scale and bias cannot be separated. With a current the same holds between the
bias and the current: ``raw = (1+m)·(u_ground − c_N·cos ψ − c_E·sin ψ) + b`` makes the
columns of ``b`` and of the current collinear while the heading ψ stays put.

Every verdict here is judged **in the water frame**: the speed variation that
determines a scale is that of the speed through the water — the UUT's own readings —
never that of the reference alone (in a current, circling at constant speed makes the
*ground* speed swing while the speed through the water does not). The rules, applied
in order (:func:`judge`):

1. **Scale** (``m``, and ``a`` for EM4): not determinable while the speed through the
   water is nearly constant (its standard deviation below ``min_speed_std_mps``; for
   EM2, which has no bias, its RMS below ``min_speed_rms_mps``).
2. **Current**: not separable from the bias while the heading covers fewer than
   ``min_heading_sectors`` of 8 sectors of 45°. The **bias** is then not determinable
   either: the along-hull current and the bias are the same unknown on a straight
   line. A *nuisance offset* takes their sum, so the scale can still be learnt from
   speed changes, and neither is reported.
3. **Enough samples**: at least ``min_samples_per_param`` effective samples per
   unknown.
4. **Information**: the standard deviation of each remaining unknown from the
   information matrix (``σ²·(HᵀWH)⁻¹`` over the remaining unknowns and the nuisance
   offset) must be under its ``max_std_*``; the worst offender is dropped and the
   rest judged again. ``max_cond`` bounds the condition number.

The information matrix is built over five design columns at the operating point
(the speed through the water u and the heading ψ): ``[u², u, 1, cos ψ, sin ψ]`` —
``a``, ``m``, ``b`` (or the nuisance offset), ``c_N``, ``c_E`` (the current's columns
are ``−(1+m)·cos ψ`` and ``−(1+m)·sin ψ``; sign and the factor near 1 do not change
what is determinable).

:func:`identifiability` judges a batch window; :class:`ExcitationWindow` is the
fixed-memory online version (exponential forgetting, O(1) per sample). Both call
:func:`judge`, so the daemon and the offline commands apply one rule.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.models import CURRENT, FloatArray, Layout
from calib.verdicts import Verdict as Verdict
from calib.verdicts import Verdicts as Verdicts

N_SECTORS = 8
"""Heading sectors of 45° used to judge how much of the compass a window covers."""

SECTOR_DEG = 360.0 / N_SECTORS
"""The width of one heading sector, degrees."""

SECTOR_MIN_FRACTION = 0.03
"""A sector counts as covered when it holds at least this fraction of the window."""

_COL = {"a": (0,), "m": (1,), "b": (2,), CURRENT: (3, 4)}
"""Columns of the five-column information matrix ``[u², u, 1, cos ψ, sin ψ]``."""
_OFFSET = 2


@dataclass(frozen=True, slots=True)
class ExcitationRule:
    """Thresholds of the identifiability rule (see the module docstring).

    Attributes:
        min_samples_per_param: effective samples needed per unknown (≥ 1).
        min_speed_std_mps: least standard deviation of the speed through the water
            for a scale (EM3, EM4), m/s.
        min_speed_rms_mps: least RMS speed through the water for EM2's scale, m/s.
        min_heading_sectors: least number of 45° heading sectors covered for the
            current to be separable from the bias (of 8).
        max_cond: largest acceptable condition number of the information matrix.
        max_std_a_spm: largest standard deviation of a determined ``a``, s/m.
        max_std_m: largest standard deviation of a determined ``m``.
        max_std_b_mps: largest standard deviation of a determined ``b``, m/s.
        max_std_current_mps: largest standard deviation of a determined current
            component, m/s.
        max_scale_vif: largest factor by which estimating the current may multiply
            the scale's variance (its variance inflation): above it the speed through
            the water follows the heading, a scale error and a current leave the same
            signature, and whatever the model leaves out (a curvature, a current that
            changes) decides their split.

    Raises:
        ValueError: a threshold out of range.
    """

    min_samples_per_param: int = 10
    min_speed_std_mps: float = 0.1
    min_speed_rms_mps: float = 0.3
    min_heading_sectors: int = 3
    max_cond: float = 1e8
    max_std_a_spm: float = 0.01
    max_std_m: float = 0.02
    max_std_b_mps: float = 0.03
    max_std_current_mps: float = 0.05
    max_scale_vif: float = 5.0

    def __post_init__(self) -> None:
        if self.min_samples_per_param < 1:
            raise ValueError("min_samples_per_param must be at least 1")
        if not (self.min_speed_std_mps >= 0.0 and self.min_speed_rms_mps >= 0.0):
            raise ValueError("speed thresholds must be non-negative")
        if not 1 <= self.min_heading_sectors <= N_SECTORS:
            raise ValueError(f"min_heading_sectors must be within 1..{N_SECTORS}")
        if not self.max_cond > 1.0:
            raise ValueError("max_cond must exceed 1")
        if not self.max_scale_vif >= 1.0:
            raise ValueError("max_scale_vif must be at least 1")
        for name in ("max_std_a_spm", "max_std_m", "max_std_b_mps", "max_std_current_mps"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive")

    def max_std(self, unknown: str) -> float:
        """The largest standard deviation of a determined unknown, in its unit."""
        return {
            "a": self.max_std_a_spm,
            "m": self.max_std_m,
            "b": self.max_std_b_mps,
            CURRENT: self.max_std_current_mps,
        }[unknown]


DEFAULT_RULE = ExcitationRule()


@dataclass(frozen=True, slots=True)
class WindowStats:
    """What a window holds, for :func:`judge`.

    Attributes:
        n_samples: (effective) number of samples.
        info: ``HᵀWH`` over the five columns ``[u², u, 1, cos ψ, sin ψ]``, shape (5, 5).
        speed_mean_mps: mean speed through the water (the UUT's readings), m/s.
        speed_std_mps: its standard deviation, m/s.
        speed_rms_mps: its RMS, m/s.
        heading_sectors: 45° sectors covered (None without a heading).
    """

    n_samples: float
    info: FloatArray
    speed_mean_mps: float
    speed_std_mps: float
    speed_rms_mps: float
    heading_sectors: int | None


@dataclass(frozen=True, slots=True)
class Identifiability(Verdicts):
    """The verdict on every unknown of one window.

    Attributes:
        layout: the model and whether a current is estimated.
        verdicts: one per unknown, in :attr:`Layout.unknowns` order.
        stats: the window's figures.
        cond_info: condition number of the information matrix over the determined
            unknowns (``inf`` when none is).
        nuisance_offset: a free offset absorbed bias and along-hull current together.
    """

    layout: Layout
    verdicts: tuple[Verdict, ...]
    stats: WindowStats
    cond_info: float
    nuisance_offset: bool


def _columns(unknowns: Sequence[str], offset: bool) -> list[int]:
    cols = [c for u in unknowns for c in _COL[u]]
    if offset and _OFFSET not in cols:
        cols.append(_OFFSET)
    return sorted(cols)


def _scale_inflation(figures: _Figures, scale: Sequence[str], offset: bool) -> float:
    """By how much estimating the current multiplies a scale term's variance (≥ 1).

    The largest over the scale terms together and each alone (EM4's ``a`` without
    ``m`` is a scale too: if ``m`` is refused, ``a`` must not take its place).
    """
    worst = 1.0
    for group in [list(scale)] + [[k] for k in scale] * (len(scale) > 1):
        a = figures.stds(_columns(group, offset), 1.0)
        b = figures.stds(_columns([*group, CURRENT], offset), 1.0)
        for k in group:
            for c in _COL[k]:
                if math.isfinite(a[c]):
                    ratio = (b[c] / a[c]) ** 2 if math.isfinite(b[c]) and a[c] > 0 else math.inf
                    worst = max(worst, ratio)
    return worst


def _inv_diag(info: FloatArray, cols: list[int]) -> FloatArray | None:
    """The diagonal of the inverse of the information matrix over ``cols`` (None when
    singular).

    From one eigendecomposition of that matrix scaled to a unit diagonal:
    ``(M⁻¹)ᵢᵢ = Σₖ Vᵢₖ² / λₖ`` over its eigenpairs, divided by the scale².
    """
    sub = info[cols][:, cols]
    scale = np.sqrt(np.maximum(sub.diagonal(), 1e-300))
    eig, vec = np.linalg.eigh(sub / (scale[:, None] * scale))
    if not float(eig[0]) > 1e-12 * max(float(eig[-1]), 1e-300):
        return None
    inv_diag: FloatArray = (vec * vec) @ (1.0 / eig) / (scale * scale)
    return inv_diag


def judge(
    layout: Layout,
    stats: WindowStats,
    sigma2_mps2: float,
    rule: ExcitationRule = DEFAULT_RULE,
    *,
    std_factor: float = 1.0,
) -> Identifiability:
    """Apply the identifiability rules of the module docstring to one window.

    Args:
        layout: the model and whether the current is estimated.
        stats: the window's figures.
        sigma2_mps2: variance of one raw residual, (m/s)² (the fit's, or the
            sensor's nominal noise online).
        rule: the thresholds.
        std_factor: multiplies every ``max_std_*`` (an online filter accumulates
            information beyond its window, so a window whose own information is
            weak may still be learnt from; only structural degeneracy stops it).

    Returns:
        A verdict per unknown.
    """
    return _information(_structure(layout, stats, rule), sigma2_mps2, std_factor)


def structural(
    layout: Layout, stats: WindowStats, rule: ExcitationRule = DEFAULT_RULE
) -> tuple[dict[str, str], bool]:
    """Rules 1 and 2 and the scale's variance inflation, what no noise level changes: the
    unknowns refused, each with its reason, and whether a nuisance offset takes the bias
    and the along-hull current together."""
    s = _structure(layout, stats, rule)
    return s.refused, s.offset


@dataclass(frozen=True, slots=True)
class _Structure:
    """A window after the structural rules: what they refused, whether an offset takes
    bias and current, and the decompositions kept for the information rules."""

    layout: Layout
    stats: WindowStats
    rule: ExcitationRule
    refused: dict[str, str]
    offset: bool
    figures: _Figures


def _structure(layout: Layout, stats: WindowStats, rule: ExcitationRule) -> _Structure:
    """:func:`structural`'s verdicts with the decompositions they made."""
    figures = _Figures(stats.info)
    refused = _speed_rule(layout, stats, rule)
    offset = False
    if layout.current:
        offset = _heading_rule(layout, stats, rule, refused)
        if not offset:
            _inflation_rule(layout, figures, rule, refused)
    return _Structure(layout, stats, rule, refused, offset, figures)


def _speed_rule(layout: Layout, stats: WindowStats, rule: ExcitationRule) -> dict[str, str]:
    """Rule 1: the scale terms refused when the speed through the water does not vary
    (EM2: when it is too low), each with its reason."""
    refused: dict[str, str] = {}
    scale = [k for k in ("a", "m") if k in layout.unknowns]
    if layout.model == "EM2":
        if stats.speed_rms_mps < rule.min_speed_rms_mps:
            refused["m"] = (
                "scale not determinable: speed through water too low "
                f"(rms {stats.speed_rms_mps:.2f} m/s)"
            )
    elif scale and stats.speed_std_mps < rule.min_speed_std_mps:
        why = (
            "scale not determinable: speed through water nearly constant "
            f"(spread {stats.speed_std_mps:.2f} m/s)"
        )
        for k in scale:
            refused[k] = why
    return refused


def _heading_rule(
    layout: Layout, stats: WindowStats, rule: ExcitationRule, refused: dict[str, str]
) -> bool:
    """Rule 2: the current (and the bias with it) refused when the heading covers too few
    sectors; whether an offset then takes the two (``refused`` is extended)."""
    sectors = stats.heading_sectors
    if sectors is None:
        refused[CURRENT] = "current not determinable: no heading"
    elif sectors < rule.min_heading_sectors:
        refused[CURRENT] = (
            f"current not separable from bias: heading covered {sectors} of {N_SECTORS} sectors"
        )
    if CURRENT not in refused:
        return False
    if "b" in layout.unknowns:
        refused["b"] = (
            "bias not separable from the current: heading covered "
            f"{sectors if sectors is not None else 0} of {N_SECTORS} sectors"
        )
    return True


def _inflation_rule(
    layout: Layout, figures: _Figures, rule: ExcitationRule, refused: dict[str, str]
) -> None:
    """The scale terms left refused when estimating the current inflates their variance
    beyond ``rule.max_scale_vif`` (``refused`` is extended)."""
    free_scale = [k for k in ("a", "m") if k in layout.unknowns and k not in refused]
    if not free_scale:
        return
    inflation = _scale_inflation(figures, free_scale, "b" in layout.unknowns)
    if inflation > rule.max_scale_vif:
        why = (
            "scale not separable from the current: the speed through the water "
            f"follows the heading (the current multiplies its variance by {inflation:.1f})"
        )
        for k in free_scale:
            refused[k] = why


class _Figures:
    """The decompositions of one window's information matrix, kept while the window
    is judged against different bounds (the same columns give the same figures)."""

    __slots__ = ("_cond", "_inv", "info")

    def __init__(self, info: FloatArray) -> None:
        self.info = info
        self._inv: dict[tuple[int, ...], FloatArray | None] = {}
        self._cond: dict[tuple[int, ...], float] = {}

    def stds(self, cols: list[int], sigma2: float) -> dict[int, float]:
        """The standard deviation of each column's unknown from :func:`_inv_diag` and the
        residual variance ``sigma2`` (``inf`` for all when singular)."""
        key = tuple(cols)
        if key not in self._inv:
            self._inv[key] = _inv_diag(self.info, cols)
        inv_diag = self._inv[key]
        if inv_diag is None:
            return dict.fromkeys(cols, math.inf)
        return {c: math.sqrt(max(float(inv_diag[i]) * sigma2, 0.0)) for i, c in enumerate(cols)}

    def cond(self, cols: list[int]) -> float:
        """The condition number of the information matrix over these columns."""
        key = tuple(cols)
        found = self._cond.get(key)
        if found is None:
            eig = np.linalg.eigvalsh(self.info[cols][:, cols])
            found = float(eig[-1] / eig[0]) if float(eig[0]) > 0.0 else math.inf
            self._cond[key] = found
        return found


def _information(s: _Structure, sigma2_mps2: float, std_factor: float) -> Identifiability:
    """Rules 3 and 4 on what the structural rules left (``s`` is left as it is: one
    window may be judged against several bounds)."""
    layout, stats, rule, figures, offset = s.layout, s.stats, s.rule, s.figures, s.offset
    refused = dict(s.refused)
    unknowns = layout.unknowns
    free = [u for u in unknowns if u not in refused]
    stds: dict[str, float] = {}
    cond = math.inf
    n_cols = len(_columns(free, offset))
    if free and stats.n_samples < rule.min_samples_per_param * max(n_cols, 1):
        why = f"too few samples ({stats.n_samples:.0f} < {rule.min_samples_per_param * n_cols})"
        for u in free:
            refused[u] = why
        free = []
    while free:
        cols = _columns(free, offset)
        by_col = figures.stds(cols, sigma2_mps2)
        stds = {u: max(by_col[c] for c in _COL[u]) for u in free}
        ratios = {u: stds[u] / (rule.max_std(u) * std_factor) for u in free}
        worst = max(free, key=lambda u: ratios[u])
        if ratios[worst] <= 1.0:
            cond = figures.cond(cols)
            if cond <= rule.max_cond:
                break
        sd = stds[worst]
        refused[worst] = (
            f"{LABELS[worst]} not determinable: weak excitation "
            f"(standard error {sd:.3g} > {rule.max_std(worst) * std_factor:g}{UNITS[worst]})"
            if math.isfinite(sd) and ratios[worst] > 1.0
            else f"{LABELS[worst]} not determinable: information matrix singular"
            if not math.isfinite(sd)
            else f"{LABELS[worst]} not determinable: ill-conditioned (cond {cond:.3g})"
        )
        free.remove(worst)
        if worst == CURRENT and "b" in free:
            free.remove("b")
            refused["b"] = refused[CURRENT].replace("current", "bias", 1)
            offset = True
        if not free:
            cond = math.inf
    verdicts = tuple(
        Verdict(u, False, refused[u], None) if u in refused else Verdict(u, True, "", stds.get(u))
        for u in unknowns
    )
    return Identifiability(layout, verdicts, stats, cond, offset)


LABELS = {"a": "curvature", "m": "scale", "b": "bias", CURRENT: "current"}
"""Each unknown's name in a verdict's reason."""

UNITS = {"a": " s/m", "m": "", "b": " m/s", CURRENT: " m/s"}
"""Each unknown's unit in a verdict's reason."""


def heading_sectors(heading_deg: npt.ArrayLike, weights: npt.ArrayLike | None = None) -> int:
    """How many 45° sectors a heading series covers (each with ≥ 3 % of the weight).

    Args:
        heading_deg: headings in degrees, shape (N,).
        weights: optional sample weights, shape (N,).

    Returns:
        0 to 8.
    """
    h = np.asarray(heading_deg, dtype=np.float64).reshape(-1)
    w = np.ones_like(h) if weights is None else np.asarray(weights, dtype=np.float64)
    if h.size == 0:
        return 0
    idx = (np.floor(np.mod(h, 360.0) / SECTOR_DEG).astype(int)) % N_SECTORS
    return _covered(np.bincount(idx, weights=w, minlength=N_SECTORS).astype(np.float64)) or 0


def _covered(weights: FloatArray) -> int | None:
    """How many sectors hold at least :data:`SECTOR_MIN_FRACTION` of the weight of all
    (``weights``: one per sector); None when they hold none."""
    total = float(np.sum(weights))
    if not total > 0.0:
        return None
    return int(np.count_nonzero(weights >= SECTOR_MIN_FRACTION * total))


def design5(u_mps: npt.ArrayLike, heading_deg: npt.ArrayLike | None) -> FloatArray:
    """The five design columns ``[u², u, 1, cos ψ, sin ψ]``, shape (N, 5) (zeros without ψ)."""
    u = np.asarray(u_mps, dtype=np.float64).reshape(-1)
    out = np.zeros((u.size, 5))
    out[:, 0] = u * u
    out[:, 1] = u
    out[:, 2] = 1.0
    if heading_deg is not None:
        psi = np.radians(np.asarray(heading_deg, dtype=np.float64).reshape(-1))
        out[:, 3] = np.cos(psi)
        out[:, 4] = np.sin(psi)
    return out


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


def window_stats(
    u_water_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    heading_deg: npt.ArrayLike | None = None,
    weights: npt.ArrayLike | None = None,
) -> WindowStats:
    """The figures of a batch window.

    Args:
        u_water_mps: operating-point speed through the water, m/s, shape (N,).
        raw_mps: the UUT's readings, m/s, shape (N,) (their spread is the speed
            variation through the water that excites a scale).
        heading_deg: headings, degrees, shape (N,), or None.
        weights: optional sample weights, shape (N,).

    Raises:
        DataError: empty or non-finite series, bad weights.
    """
    u = np.asarray(u_water_mps, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    if u.size == 0 or u.shape != raw.shape:
        raise DataError("need a non-empty window with as many readings as speeds")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(raw))):
        raise DataError("speeds must be finite")
    w = check_weights(weights, u.size)
    D = design5(u, heading_deg)
    A = D if w is None else D * np.sqrt(w)[:, None]
    mean, std, rms = speed_stats(raw, w)
    sectors = None if heading_deg is None else heading_sectors(heading_deg, w)
    n_eff = float(u.size) if w is None else float(np.sum(w))
    return WindowStats(n_eff, A.T @ A, mean, std, rms, sectors)


def identifiability(
    layout: Layout,
    u_water_mps: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    sigma2_mps2: float,
    *,
    heading_deg: npt.ArrayLike | None = None,
    weights: npt.ArrayLike | None = None,
    rule: ExcitationRule = DEFAULT_RULE,
) -> Identifiability:
    """Judge a batch window (see :func:`judge` and :func:`window_stats`)."""
    return judge(
        layout, window_stats(u_water_mps, raw_mps, heading_deg, weights), sigma2_mps2, rule
    )


class ExcitationWindow:
    """Fixed-memory online identifiability (exponential forgetting), O(1) per sample.

    Keeps the forgotten sums of the five design columns' products, of the UUT's
    readings and of the heading sectors; :meth:`evaluate` rebuilds the window's
    figures and applies :func:`judge`. Call it at status rate.

    Args:
        layout: the filter's unknowns.
        half_life_samples: samples after which a sample's weight has halved
            (``inf`` for a growing window without forgetting).
        rule: identifiability thresholds.

    Raises:
        ValueError: a half-life that is not positive.
    """

    __slots__ = ("_info", "_judged", "_lam", "_r0", "_r1", "_r2", "_sectors", "layout", "rule")

    def __init__(
        self,
        layout: Layout,
        half_life_samples: float = math.inf,
        rule: ExcitationRule = DEFAULT_RULE,
    ) -> None:
        if not half_life_samples > 0.0:
            raise ValueError("half_life_samples must be positive")
        self.layout = layout
        self._lam = 0.5 ** (1.0 / half_life_samples) if math.isfinite(half_life_samples) else 1.0
        self.rule = rule
        self.reset()

    def reset(self) -> None:
        """Forget every sample."""
        self._info = [0.0] * 15
        self._r0 = self._r1 = self._r2 = 0.0
        self._sectors = [0.0] * N_SECTORS
        self._judged: _Structure | None = None

    def add(self, u_mps: float, raw_mps: float, heading_deg: float | None = None) -> None:
        """Add one sample: operating-point speed through the water, reading, heading."""
        lam = self._lam
        if heading_deg is None:
            c = s = 0.0
        else:
            psi = math.radians(heading_deg)
            c, s = math.cos(psi), math.sin(psi)
            sec = self._sectors
            for i in range(N_SECTORS):
                sec[i] *= lam
            sec[int((heading_deg % 360.0) // SECTOR_DEG) % N_SECTORS] += 1.0
        col = (u_mps * u_mps, u_mps, 1.0, c, s)
        info = self._info
        k = 0
        for i in range(5):
            ci = col[i]
            for j in range(i, 5):
                info[k] = lam * info[k] + ci * col[j]
                k += 1
        self._r0 = lam * self._r0 + 1.0
        self._r1 = lam * self._r1 + raw_mps
        self._r2 = lam * self._r2 + raw_mps * raw_mps
        self._judged = None

    @property
    def n_effective(self) -> float:
        """Effective number of samples."""
        return self._r0

    def stats(self) -> WindowStats:
        """The window's figures."""
        M = np.zeros((5, 5))
        k = 0
        for i in range(5):
            for j in range(i, 5):
                M[i, j] = M[j, i] = self._info[k]
                k += 1
        r0 = self._r0
        if r0 > 0.0:
            mean = self._r1 / r0
            std = math.sqrt(max(self._r2 / r0 - mean * mean, 0.0))
            rms = math.sqrt(max(self._r2 / r0, 0.0))
        else:
            mean = std = rms = 0.0
        return WindowStats(r0, M, mean, std, rms, _covered(np.array(self._sectors)))

    def evaluate(self, sigma2_mps2: float, *, std_factor: float = 1.0) -> Identifiability:
        """Judge the current window (:func:`judge`) with a nominal residual variance.

        The window's figures, the structural verdicts and the decompositions are kept
        until the next sample, so judging one window against two bounds builds them once.
        """
        if self._judged is None:
            self._judged = _structure(self.layout, self.stats(), self.rule)
        return _information(self._judged, sigma2_mps2, std_factor)
