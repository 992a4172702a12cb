"""The two-axis model learnt by least squares: a log that reports the forward and the
athwart speed, its misalignment, transverse scale and bias, and the sea current.

The model, its water frame and the state layout are :mod:`calib.twoaxis_model`'s; the
identifiability rule is :mod:`calib.twoaxis_ident`'s. Both are re-exported here, the
one module the callers import.

**Least squares** (:func:`fit_two_axis`): Gauss–Newton on both axes' residuals
stacked, each axis weighted by the inverse of its residual variance (estimated from
a first fit), over the unknowns the data determine. Standard errors are
``√diag((JᵀWJ)⁻¹)`` inflated by the larger of the two axes' residual correlation
factors (:func:`calib.metrics.correlation_factor`), as :mod:`calib.lsq` does.

**Kalman filter** (:func:`kf_two_axis`): the same unknowns as states (the current a
random walk, the sensor's parameters nearly constant), the two readings a vector
measurement with the reference's ground velocity taken as known (a DVL's millimetre
noise), linearised about the least-squares fit and then about its own previous pass;
the unknowns the window refuses are held at their prior as in least squares.

**Without the misalignment, no transverse figures** (:func:`hold_without_misalignment`).
Where α is refused, the transverse scale and bias are held at their prior too (the
ideal sensor's gain 1 and bias 0: the athwart reading passes as read), each with the
reason. The athwart reading is ``(1 + m_t)·(w − sin α·u) + b_t``: with α held, a
fitted scale and bias take the phantom leeway ``−sin α·u`` at the training data's
forward speeds and are wrong at any other (on the one-way circles of ``emlogd
simulate``, a scale tied to the forward axis's and a bias so fitted make the athwart
speed worse than raw on three of its five trajectories). Inside the fit they stay
free (the scale tied to the forward one, :data:`TIE_HELD_SCALE`), so that the
athwart axis still tells the current across the hull and the longitudinal fit keeps
that benefit.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.metrics import correlation_factor
from calib.models import CURRENT, PARAM_NAMES, FloatArray, ModelName, Params, check_model
from calib.twoaxis_ident import (
    DEFAULT_TWO_AXIS_RULE,
    ENVELOPE,
    TwoAxisIdent,
    TwoAxisRule,
    _outside,
    _ties,
    judge_two_axis,
    unknowns_of,
)
from calib.twoaxis_model import (
    _A,
    _AL,
    _B,
    _BT,
    _CE,
    _CN,
    _DL,
    _DT,
    _M,
    _MT,
    _N_FIXED,
    _PARAM_INDEX,
    ALPHA,
    B_T,
    M_T,
    MAX_MISALIGN_DEG,
    TIE_HELD_SCALE,
    TRANSVERSE_NAMES,
    Problem,
    TwoAxisParams,
    _free_indices,
    _index,
    _params_of,
    _x0,
    leeway_deg,
    water_velocity,
)
from calib.verdicts import Verdict

__all__ = [
    "ALPHA",
    "B_T",
    "DEFAULT_TWO_AXIS_RULE",
    "ENVELOPE",
    "MAX_MISALIGN_DEG",
    "MIN_KNOT_SHARE",
    "M_T",
    "TIE_HELD_SCALE",
    "TRANSVERSE_NAMES",
    "ModelState",
    "TwoAxisFit",
    "TwoAxisIdent",
    "TwoAxisParams",
    "TwoAxisRule",
    "TwoAxisSeries",
    "current_basis",
    "fit_current_two_axis",
    "fit_two_axis",
    "hold_without_misalignment",
    "judge_two_axis",
    "leeway_deg",
    "model_state",
    "unknowns_of",
    "water_velocity",
]

_MAX_ITER = 30


def _solve(problem: Problem, x0: FloatArray, free: list[int]) -> FloatArray:
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
    trace: FloatArray | None = field(default=None, compare=False)
    """The filter's α (rad), transverse scale and bias at each sample, then their σ,
    shape (N, 6) (nan: held; None: least squares)."""

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
class TwoAxisSeries:
    """Aligned two-axis series, checked: what every two-axis fit takes (build it with
    :meth:`of`).

    Attributes:
        ref_fwd: the reference's ground (or, without a current, water) speed forward
            along the hull, m/s, shape (N,), lag-aligned.
        ref_stb: its speed to starboard, m/s, shape (N,).
        raw_l: the longitudinal readings, m/s, shape (N,).
        raw_t: the transverse readings (positive to starboard), m/s, shape (N,).
        heading: headings at the reference's time, degrees, shape (N,).
    """

    ref_fwd: FloatArray
    ref_stb: FloatArray
    raw_l: FloatArray
    raw_t: FloatArray
    heading: FloatArray

    @classmethod
    def of(
        cls,
        ref_fwd_mps: npt.ArrayLike,
        ref_stb_mps: npt.ArrayLike,
        raw_l_mps: npt.ArrayLike,
        raw_t_mps: npt.ArrayLike,
        heading_deg: npt.ArrayLike,
    ) -> TwoAxisSeries:
        """The series as float arrays, checked.

        Raises:
            DataError: no samples, lengths that differ, or a value that is not finite.
        """
        arrays = [
            np.asarray(a, dtype=np.float64).reshape(-1)
            for a in (ref_fwd_mps, ref_stb_mps, raw_l_mps, raw_t_mps, heading_deg)
        ]
        n = arrays[0].size
        if n == 0:
            raise DataError("no samples")
        if any(a.size != n for a in arrays):
            raise DataError("references, readings and headings must have the same length")
        if not all(bool(np.all(np.isfinite(a))) for a in arrays):
            raise DataError("references, readings and headings must be finite")
        return cls(*arrays)

    @property
    def n(self) -> int:
        """The number of samples."""
        return int(self.ref_fwd.size)


def _prepare(
    name: ModelName,
    s: TwoAxisSeries,
    prior: TwoAxisParams | None,
    current: bool,
    t_s: npt.ArrayLike | None,
    current_knot_s: float | None,
) -> Problem:
    if prior is not None and prior.model != name:
        raise DataError(f"prior parameters are {prior.model}, the fit is {name}")
    basis = None
    if current and current_knot_s is not None:
        basis = current_basis(t_s, s.n, current_knot_s)
    return Problem(s.ref_fwd, s.ref_stb, s.raw_l, s.raw_t, np.radians(s.heading), basis)


MIN_KNOT_SHARE = 0.05
"""A knot whose samples weigh less than this share of the best-supported knot's is
left out (the time between two captures, a capture's last seconds): its current would
rest on a handful of samples. The samples near it take their neighbours' knots, each
row of the basis summing to 1 again."""


def current_basis(t_s: npt.ArrayLike | None, n: int, knot_s: float) -> FloatArray | None:
    """The hat functions of a current linear between knots ``knot_s`` apart from the
    first sample: shape (N, K), each row summing to 1 (None: the samples span less
    than one interval, one current). Knots without the samples to carry them are left
    out (:data:`MIN_KNOT_SHARE`).

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
    basis = np.maximum(0.0, 1.0 - np.abs(t[:, None] - knots[None, :]) / knot_s)
    weight = basis.sum(axis=0)
    keep = weight >= MIN_KNOT_SHARE * float(np.max(weight))
    basis = basis[:, keep]
    total = basis.sum(axis=1, keepdims=True)
    if basis.shape[1] <= 1 or not np.all(total > 0.0):
        return None
    return np.asarray(basis / total, dtype=np.float64)


HELD_WITHOUT_MISALIGNMENT = (
    "{label} held at {value}: without the misalignment it would take the sideways "
    "reading a misalignment makes (−sin α·u) at these forward speeds, and be wrong at "
    "any other"
)
"""The reason a transverse scale or bias is not learnt where α is refused
(:func:`hold_without_misalignment`)."""


def hold_without_misalignment(fit: TwoAxisFit, prior: TwoAxisParams | None = None) -> TwoAxisFit:
    """A fit whose α is refused with its transverse scale and bias held at the prior's
    (None: the ideal sensor's, ``m_t`` = ``b_t`` = 0), each refused with the reason
    (:data:`HELD_WITHOUT_MISALIGNMENT`, or the reason it had), its σ not reported; a
    fit that determined α, unchanged (module docstring)."""
    if ALPHA not in fit.ident.unidentifiable:
        return fit
    p = fit.params
    held = prior if prior is not None else TwoAxisParams(Params(p.model))
    values = {M_T: f"{held.m_t:+.3g}", B_T: f"{held.b_t_mps:+.3g} m/s"}
    labels = {M_T: "transverse scale", B_T: "transverse bias"}
    verdicts = tuple(
        Verdict(
            v.unknown,
            False,
            HELD_WITHOUT_MISALIGNMENT.format(label=labels[v.unknown], value=values[v.unknown]),
            None,
        )
        if v.unknown in labels and v.determined
        else v
        for v in fit.ident.verdicts
    )
    return replace(
        fit,
        params=TwoAxisParams(p.longitudinal, p.misalign_rad, held.m_t, held.b_t_mps),
        stderr=fit.stderr | {M_T: None, B_T: None},
        ident=replace(fit.ident, verdicts=verdicts),
    )


def fit_two_axis(
    model: str,
    s: TwoAxisSeries,
    *,
    current: bool = True,
    prior: TwoAxisParams | None = None,
    rule: TwoAxisRule = DEFAULT_TWO_AXIS_RULE,
    t_s: npt.ArrayLike | None = None,
    current_knot_s: float | None = None,
    hold: bool = True,
) -> TwoAxisFit:
    """Least squares of the two-axis model on aligned series (module docstring).

    Args:
        model: the longitudinal model, ``"EM1"`` … ``"EM4"``.
        s: the series (without ``current``, the reference is the water speed).
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
        hold: where α is refused, report the transverse scale and bias held at the
            prior (:func:`hold_without_misalignment`); False: as fitted, for a
            caller that holds them itself (the filter, which starts from this fit).

    Returns:
        The fit; never raises on poor excitation (see ``ident``).

    Raises:
        ModelError: unknown model.
        DataError: a prior of another model, or times unfit for ``current_knot_s``.
    """
    name = check_model(model)
    problem = _prepare(name, s, prior, current, t_s, current_knot_s)
    x0 = _x0(prior, problem.size())
    u, w = problem.water(x0)
    ident = judge_two_axis(name, u, w, s.raw_l, s.heading, current=current, rule=rule)
    x = x0
    outside: dict[str, str] = {}

    def rejudge(u: FloatArray, w: FloatArray, x: FloatArray) -> TwoAxisIdent:
        """Rules 1–5 at ``x``, the unknowns found ``outside`` the envelope refused."""
        return judge_two_axis(
            name,
            u,
            w,
            s.raw_l,
            s.heading,
            current=current,
            info_of=problem,
            x=x,
            rule=rule,
            outside=outside,
        )

    for _ in range(2 * len(ident.verdicts) + 2):
        problem.tie = _ties(name, ident)
        free = _free_indices(ident.determined, ident.nuisance_offset, problem.n_blocks)
        x = _solve(problem, x0, free)
        rl, rt = problem.residuals(x)
        dof = max(s.n - len(free) // 2, 1)
        problem.scale = np.array(
            [
                1.0 / max(math.sqrt(float(rl @ rl) / dof), 1e-6),
                1.0 / max(math.sqrt(float(rt @ rt) / dof), 1e-6),
            ]
        )
        u, w = problem.water(x)
        new = rejudge(u, w, x)
        done = new.determined == ident.determined
        ident = new
        if done:
            beyond = _outside(x, ident.determined)
            if not beyond:
                break
            outside |= beyond
            ident = rejudge(u, w, x)
    for _ in range(len(ident.verdicts) + 1):  # each pass refuses one more, or ends
        problem.tie = _ties(name, ident)
        free = _free_indices(ident.determined, ident.nuisance_offset, problem.n_blocks)
        x = _solve(problem, x0, free)
        beyond = _outside(x, ident.determined)
        if not beyond:
            break
        outside |= beyond
        ident = rejudge(u, w, x)
    rl, rt = problem.residuals(x)
    factor = max(correlation_factor(rl), correlation_factor(rt))
    std = np.full(x.size, math.nan)
    cov_full = np.zeros((x.size, x.size))
    if free and 2 * s.n > len(free):
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
    n = s.n
    fit = TwoAxisFit(
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
    return hold_without_misalignment(fit, prior) if hold else fit


class ModelState:
    """The two-axis model's state vector and measurement, sample by sample: what a
    filter (:mod:`calib.twoaxis_kf`) needs without the layout's indices.

    Attributes:
        n: samples.
        free: the state indices the verdicts leave free (the determined unknowns, and
            a nuisance offset per axis when the current is not separable).
    """

    def __init__(self, name: ModelName, s: TwoAxisSeries, ident: TwoAxisIdent) -> None:
        self.model = name
        self.n = s.n
        self.tie = _ties(name, ident)
        self.free = _free_indices(ident.determined, ident.nuisance_offset, 1)
        psi = np.radians(s.heading)
        self._gf, self._gs = s.ref_fwd.tolist(), s.ref_stb.tolist()
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
    def with_current(x: FloatArray, cn: float, ce: float) -> FloatArray:
        """``x`` with its current (north, east) set, m/s (in place; returned)."""
        x[_CN], x[_CE] = cn, ce
        return x

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


def model_state(model: str, s: TwoAxisSeries, ident: TwoAxisIdent) -> ModelState:
    """The state and measurement of a series under the verdicts ``ident``.

    Raises:
        ModelError: unknown model.
    """
    return ModelState(check_model(model), s, ident)


def fit_current_two_axis(
    params: TwoAxisParams,
    s: TwoAxisSeries,
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
        s: the series.
        t_s: sample times, s (needed with ``current_knot_s``).
        current_knot_s: the current linear between knots this far apart
            (:func:`current_basis`; None: one current).

    Returns:
        The current (north, east) at each sample, m/s, shape (N, 2).

    Raises:
        DataError: bad times.
    """
    basis = None
    if current_knot_s is not None:
        basis = current_basis(t_s, s.n, current_knot_s)
    problem = Problem(s.ref_fwd, s.ref_stb, s.raw_l, s.raw_t, np.radians(s.heading), basis)
    x0 = _x0(params, problem.size())
    x = _solve(problem, x0, _index(CURRENT, problem.n_blocks))
    cn, ce = problem.current_at(x)
    return np.column_stack([cn, ce])
