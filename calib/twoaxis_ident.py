"""The identifiability rule of the two-axis model (:mod:`calib.twoaxis_model`).

**Identifiability** (:func:`judge_two_axis`), in order, in the words of
:mod:`calib.excitation` where the longitudinal rules are the same:

1. the longitudinal scale (``m``, and ``a`` for EM4) needs the speed through the
   water to vary (EM2: its RMS), as on one axis;
2. the current needs the heading to cover ``min_heading_sectors`` 45° sectors;
   without it the current, the longitudinal bias and the **transverse bias** are
   refused: on a steady heading each axis's bias and the current projected on it are
   one unknown, and a nuisance offset per axis takes their sum;
3. the **misalignment** needs the speed through the water to vary: its signature on
   the transverse axis is ``−(1 + m_t)·sin α·u``, which at constant u is a constant
   — the transverse bias again, and on one heading the current across the hull
   too (where the heading turns, the current turns with it in the hull frame and
   is told apart: the reason then names the bias alone). A straight run or
   circles at one throttle setting refuse it, with the reason;
4. the **transverse scale** needs the transverse speed through the water (the sway
   of turns) to vary apart from the forward speed by ``min_transverse_std_mps``
   (:func:`sway_apart_from_surge`); without it the misalignment is
   refused too: its athwart signature is ``(1 + m_t)·sin α·u``, so a transverse
   scale held where the log's differs by Δm would put ``Δm·α`` into α (a 3°
   misalignment of a log whose axes' scales differ by 0.11, learnt on a transit:
   3.41°);
5. enough samples (``min_samples_per_param`` per unknown), then the information:
   the standard deviation of each remaining unknown from the information matrix
   must be under its bound; the worst offender is refused and the rest judged
   again (a transverse scale refused so takes the misalignment with it). In
   steady circles and on transits the sway follows the surge: only the
   figure-8's alternating turns, whose sway swings without the surge, determine
   the transverse scale and with it the misalignment. Circles one way cannot,
   at any speed: on those of ``emlogd simulate --scale 0.5 --seed 1`` (3°/s to
   starboard at three throttle settings) ``w = −0.0315·u`` and the rest spreads
   less than 0.1 mm/s; with the transverse scale free, the athwart axis's
   information gives α a σ of 128° (its correlation with ``m_t`` −1.0000, the
   normalised information's condition 2.5·10⁸). Circles both ways flip the sign
   of ``k`` and determine both.

An unknown refused is held at its prior (the given parameters, else the ideal
sensor; zero current) and its σ is not reported.

An estimate outside the envelope (:data:`ENVELOPE`) is refused the same way.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calib import twoaxis_model
from calib.excitation import (
    DEFAULT_RULE,
    LABELS,
    N_SECTORS,
    UNITS,
    ExcitationRule,
    heading_sectors,
)
from calib.models import CURRENT, PARAM_NAMES, FloatArray, ModelName
from calib.twoaxis_model import ALPHA, B_T, M_T, MAX_MISALIGN_DEG, TIE_HELD_SCALE, TRANSVERSE_NAMES
from calib.verdicts import Verdict, Verdicts


@dataclass(frozen=True, slots=True)
class TwoAxisRule:
    """The thresholds of the two-axis identifiability rule (module docstring).

    Attributes:
        base: the one-axis rule: the longitudinal's thresholds, the heading sectors
            the current needs, the samples per unknown, the bounds of the
            longitudinal parameters and of the current.
        min_speed_std_misalign_mps: least spread of the speed through the water
            (forward) for the misalignment, m/s.
        min_transverse_std_mps: least spread of the transverse speed through the
            water apart from the forward speed (what a straight line in the
            forward speed leaves, :func:`sway_apart_from_surge`) for the
            transverse scale, m/s.
        max_std_misalign_deg: largest standard deviation of a determined α,
            degrees: above the figure-8's, whose σ is set by its length (0.14–0.15°
            for the 27 minutes of ``emlogd simulate``, seeds 1–6; about 0.2° for half
            of it), so that a trial whose noise draws a σ a little larger is not
            refused α where it determines it, and the daemon's window learns it
            before the whole figure-8 is in.
        max_std_m_t: largest standard deviation of a determined transverse scale.
        max_std_b_t_mps: largest standard deviation of a determined transverse bias, m/s.

    Raises:
        ValueError: a threshold out of range.
    """

    base: ExcitationRule = DEFAULT_RULE
    min_speed_std_misalign_mps: float = 0.1
    min_transverse_std_mps: float = 0.03
    max_std_misalign_deg: float = 0.25
    max_std_m_t: float = 0.05
    max_std_b_t_mps: float = 0.03

    def __post_init__(self) -> None:
        if not (self.min_speed_std_misalign_mps >= 0.0 and self.min_transverse_std_mps >= 0.0):
            raise ValueError("speed thresholds must be non-negative")
        for name in ("max_std_misalign_deg", "max_std_m_t", "max_std_b_t_mps"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive")

    def max_std(self, unknown: str) -> float:
        """The largest standard deviation of a determined unknown, in the unit its
        estimate is held in (α in rad)."""
        if unknown == ALPHA:
            return math.radians(self.max_std_misalign_deg)
        if unknown == M_T:
            return self.max_std_m_t
        if unknown == B_T:
            return self.max_std_b_t_mps
        return self.base.max_std(unknown)


DEFAULT_TWO_AXIS_RULE = TwoAxisRule()

_LABEL = {**LABELS, ALPHA: "misalignment", M_T: "transverse scale", B_T: "transverse bias"}
_UNIT = {**UNITS, ALPHA: "°", M_T: "", B_T: " m/s"}


TURNS_BOTH_WAYS = "turns to both sides (a figure-8) tell them apart"
"""What an operator can sail to determine the misalignment, in its refusal's reason."""
ONE_SWAY_RATIO = "one steady turn (one turn rate throughout, one way), or none"
"""Why the sway was a fixed fraction of the surge, in α's refusal: the sideslip of a
turn is set by its rate (``w = −0.6·rate·u`` in the simulator, whose circles turn at
one rate from their first sample to their last, at three throttle settings: no entry
or exit transient; the log's sway is the hull's, with no sensor position and so no
yaw-rate lever arm), so circles one way at any speed give one sway ratio and
``(1 + m_t)·(w/u − sin α)`` one slope for two unknowns."""


def _alpha_with_scale(why_scale: str) -> str:
    """α's reason when the transverse scale is refused (``why_scale``): its athwart
    signature ``(1 + m_t)·sin α·u`` is one more scale on the forward speed, in words an
    operator reads in the status."""
    return (
        "misalignment not determinable: a misalignment and a transverse scale error "
        f"both read as sideways speed in proportion to the forward speed ({why_scale}); "
        f"{TURNS_BOTH_WAYS}"
    )


def unknowns_of(model: ModelName, current: bool) -> tuple[str, ...]:
    """The unknowns of a two-axis calibration: the longitudinal parameters, α, the
    transverse scale and bias, then the current."""
    return (*PARAM_NAMES[model], *TRANSVERSE_NAMES, *((CURRENT,) if current else ()))


@dataclass(frozen=True, slots=True)
class TwoAxisIdent(Verdicts):
    """The verdict on every unknown of a two-axis window.

    Attributes:
        model: the longitudinal model.
        current: whether a current is estimated.
        verdicts: one per unknown, in :func:`unknowns_of` order.
        nuisance_offset: an offset per axis took the biases and the current together.
        speed_std_mps: spread of the forward speed through the water, m/s.
        transverse_std_mps: spread of the transverse speed through the water, m/s.
        heading_sectors: 45° sectors covered.
        n_samples: samples per axis.
    """

    model: ModelName
    current: bool
    verdicts: tuple[Verdict, ...]
    nuisance_offset: bool
    speed_std_mps: float
    transverse_std_mps: float
    heading_sectors: int
    n_samples: int


def _spread(x: FloatArray) -> float:
    return float(np.std(x)) if x.size else 0.0


def judge_two_axis(
    model: ModelName,
    u_mps: FloatArray,
    w_mps: FloatArray,
    raw_l_mps: FloatArray,
    heading_deg: FloatArray,
    *,
    current: bool,
    info_of: twoaxis_model.Problem | None = None,
    x: FloatArray | None = None,
    rule: TwoAxisRule = DEFAULT_TWO_AXIS_RULE,
    outside: dict[str, str] | None = None,
) -> TwoAxisIdent:
    """The two-axis identifiability rule on one window (module docstring, rules 1–5).

    Args:
        model: the longitudinal model.
        u_mps: forward speed through the water (at the current estimate), m/s.
        w_mps: transverse speed through the water, m/s.
        raw_l_mps: the longitudinal readings (the spread of rule 1 is theirs, as on
            one axis), m/s.
        heading_deg: headings, degrees.
        current: whether the current is an unknown.
        info_of: the weighted problem whose information matrix rule 5 reads (None:
            rules 1–4 only).
        x: the point at which rule 5 takes the Jacobian.
        rule: the thresholds.
        outside: unknowns refused beforehand, with the reason (an estimate outside
            the envelope, :data:`ENVELOPE`).
    """
    unknowns = unknowns_of(model, current)
    refused: dict[str, str] = dict(outside or {})
    std_u, std_w = _spread(u_mps), _spread(w_mps)
    _scale_rule(model, unknowns, raw_l_mps, rule.base, refused)
    sectors = heading_sectors(heading_deg) if heading_deg.size else 0
    offset = _current_rule(current, sectors, unknowns, rule.base, refused)
    _misalign_rules(u_mps, w_mps, std_u, rule, refused)
    free = [k for k in unknowns if k not in refused]
    n = int(u_mps.size)
    stds: dict[str, float] = {}
    n_blocks = info_of.n_blocks if info_of is not None else 1
    n_cols = len(twoaxis_model._free_indices(free, offset, n_blocks))
    if free and 2 * n < rule.base.min_samples_per_param * n_cols:
        why = f"too few samples ({2 * n} < {rule.base.min_samples_per_param * n_cols})"
        for k in free:
            refused[k] = why
        free = []
    if info_of is not None and x is not None and free:
        stds, offset = _information(info_of.jacobian(x), free, offset, n_blocks, rule, refused)
    verdicts = tuple(
        Verdict(k, False, refused[k], None) if k in refused else Verdict(k, True, "", stds.get(k))
        for k in unknowns
    )
    return TwoAxisIdent(model, current, verdicts, offset, std_u, std_w, sectors, n)


def _scale_rule(
    model: ModelName,
    unknowns: Sequence[str],
    raw_l: FloatArray,
    base: ExcitationRule,
    refused: dict[str, str],
) -> None:
    """Rule 1: the longitudinal scale needs the speed to vary (EM2: its RMS)."""
    scale = [k for k in ("a", "m") if k in unknowns]
    if model == "EM2":
        rms = float(np.sqrt(np.mean(raw_l * raw_l))) if raw_l.size else 0.0
        if rms < base.min_speed_rms_mps:
            refused["m"] = (
                f"scale not determinable: speed through water too low (rms {rms:.2f} m/s)"
            )
        return
    spread = _spread(raw_l)
    if scale and spread < base.min_speed_std_mps:
        why = (
            f"scale not determinable: speed through water nearly constant (spread {spread:.2f} m/s)"
        )
        for k in scale:
            refused[k] = why


def _current_rule(
    current: bool,
    sectors: int,
    unknowns: Sequence[str],
    base: ExcitationRule,
    refused: dict[str, str],
) -> bool:
    """Rule 2: the current needs the heading's sectors; refused (or refused before),
    both biases go with it. Returns whether a nuisance offset per axis is fitted."""
    if current and sectors < base.min_heading_sectors:
        refused[CURRENT] = (
            f"current not separable from bias: heading covered {sectors} of {N_SECTORS} sectors"
        )
    if CURRENT not in refused:
        return False
    for k, label in (("b", "bias"), (B_T, "transverse bias")):
        if k in unknowns:
            refused[k] = (
                f"{label} not separable from the current: heading covered "
                f"{sectors} of {N_SECTORS} sectors"
            )
    return True


def sway_apart_from_surge(u_mps: FloatArray, w_mps: FloatArray) -> tuple[float, float, float]:
    """The sway as a straight line in the surge, ``w ≈ c + k·u``, and the spread of
    what the line leaves: ``(c, k, spread)`` in m/s, 1, m/s. The transverse scale and
    the misalignment are told apart by this rest: where the sway follows the surge
    (steady circles one way, ``w = −0.6·rate·u`` in the simulator), the athwart
    reading ``(1 + m_t)·(w − sin α·u) + b_t`` is ``(1 + m_t)·(k − sin α)·u`` plus a
    constant, one slope for two unknowns."""
    n = int(u_mps.size)
    if n < 3:
        return 0.0, 0.0, 0.0
    design = np.column_stack([np.ones(n), u_mps])
    coef, *_ = np.linalg.lstsq(design, w_mps, rcond=None)
    rest = w_mps - design @ coef
    return float(coef[0]), float(coef[1]), float(np.std(rest))


RUNS_AT_SPEEDS = "runs at different speeds tell them apart"
"""What an operator can sail to separate the misalignment from the offsets, in its
refusal's reason at one speed."""


def _alpha_at_one_speed(spread_mps: float, with_current: bool) -> str:
    """α's reason at one speed (rule 3): the sideways reading a misalignment makes,
    ``−sin α·u``, is then a constant, as the transverse bias is, and on one heading
    (``with_current``: the current refused for the heading's sectors) as the current
    across the hull is too; where the heading turned (circles one way at one
    throttle) the current turns with it in the hull frame and is told apart, so the
    reason names the bias alone."""
    if with_current:
        return (
            "misalignment not separable from the transverse bias and the current: "
            f"speed through water nearly constant (spread {spread_mps:.2f} m/s) on one "
            "heading, so the sideways reading a misalignment makes, the transverse bias "
            "and the current across the hull are one steady offset; turns and "
            f"{RUNS_AT_SPEEDS}"
        )
    return (
        "misalignment not separable from the transverse bias: speed through water "
        f"nearly constant (spread {spread_mps:.2f} m/s), so the sideways reading a "
        "misalignment makes is one steady offset, as the bias is (the current, turning "
        f"with the heading, is told apart); {RUNS_AT_SPEEDS}"
    )


def _misalign_rules(
    u: FloatArray, w: FloatArray, std_u: float, rule: TwoAxisRule, refused: dict[str, str]
) -> None:
    """Rules 3 and 4: the misalignment needs the forward speed to vary, the
    transverse scale the sway apart from the surge; without the transverse scale, no
    misalignment."""
    if std_u < rule.min_speed_std_misalign_mps:
        refused[ALPHA] = _alpha_at_one_speed(std_u, CURRENT in refused)
    c, k, rest = sway_apart_from_surge(u, w)
    if rest < rule.min_transverse_std_mps:
        refused[M_T] = (
            "transverse scale not determinable: the sway follows the surge "
            f"(w = {c:+.3f} {k:+.4f}·u m/s, the rest spreads {rest:.3f} m/s), so the "
            "athwart reading gives one slope (1 + m_t)·(w/u − sin α)"
        )
        if ALPHA not in refused:
            refused[ALPHA] = _alpha_with_scale(
                "here the sideways speed through the water is a fixed fraction of the "
                f"forward speed, {k:+.3f} of it at every speed: {ONE_SWAY_RATIO}"
            )
    if M_T in refused and ALPHA not in refused:
        refused[ALPHA] = _alpha_with_scale(refused[M_T])


def _information(
    jac: FloatArray,
    free: list[str],
    offset: bool,
    n_blocks: int,
    rule: TwoAxisRule,
    refused: dict[str, str],
) -> tuple[dict[str, float], bool]:
    """Rule 5 on the ``free`` unknowns (refusing into ``refused``): each one's σ from
    the information matrix under its bound, the worst refused and the rest judged
    again. Returns the σ of those left and whether a nuisance offset is fitted."""
    stds: dict[str, float] = {}
    while free:
        stds = _stds(jac, free, offset, n_blocks)
        ratios = {k: stds[k] / rule.max_std(k) for k in free}
        worst = max(free, key=lambda k: ratios[k])
        if ratios[worst] <= 1.0:
            break
        refused[worst] = _weak(worst, stds[worst], rule)
        free.remove(worst)
        if worst == M_T and ALPHA in free:
            free.remove(ALPHA)
            refused[ALPHA] = _alpha_with_scale(refused[M_T])
        if worst == CURRENT:
            offset = True
            for k in ("b", B_T):
                if k in free:
                    free.remove(k)
                    refused[k] = refused[CURRENT].replace("current", _LABEL[k], 1)
    return stds, offset


def _stds(jac: FloatArray, free: list[str], offset: bool, n_blocks: int) -> dict[str, float]:
    """Each free unknown's σ from the information matrix (the larger component's for
    the current)."""
    cols = twoaxis_model._free_indices(free, offset, n_blocks)
    info = jac[:, cols].T @ jac[:, cols]
    try:
        diag = np.sqrt(np.maximum(np.diag(np.linalg.inv(info)), 0.0))
    except np.linalg.LinAlgError:
        diag = np.full(len(cols), math.inf)
    where = {c: i for i, c in enumerate(cols)}
    return {k: max(float(diag[where[i]]) for i in twoaxis_model._index(k, n_blocks)) for k in free}


def _weak(unknown: str, sd: float, rule: TwoAxisRule) -> str:
    """The reason an unknown's σ refuses it."""
    if not math.isfinite(sd):
        return f"{_LABEL[unknown]} not determinable: information matrix singular"
    bound = rule.max_std(unknown)
    if unknown == ALPHA:
        sd, bound = math.degrees(sd), math.degrees(bound)
    return (
        f"{_LABEL[unknown]} not determinable: weak excitation "
        f"(standard error {sd:.3g} > {bound:g}{_UNIT[unknown]})"
    )


ENVELOPE: dict[str, float] = {"a": 0.1, "m": 0.5, "b": 1.0, M_T: 0.5, B_T: 1.0}
"""The largest magnitude of each parameter a two-axis fit may report (the one-axis
envelope's |a| ≤ 0.1 s/m, |m| ≤ 0.5, |b| ≤ 1 m/s, the same for the transverse scale
and bias; α: :data:`MAX_MISALIGN_DEG`). An estimate beyond it — a transverse gain
driven to zero where a current the model cannot follow leaves that axis nothing
to explain — is refused with the reason and the rest fitted again."""


def _outside(x: FloatArray, determined: Sequence[str]) -> dict[str, str]:
    """The determined unknown furthest beyond the envelope (relative to its bound),
    with the reason; empty when every one lies inside. One at a time: a curvature
    and a scale that trade against each other leave the scale inside once the
    curvature is held."""
    worst, ratio = "", 1.0
    for k in determined:
        if k == ALPHA or k in ENVELOPE:
            bound = math.radians(MAX_MISALIGN_DEG) if k == ALPHA else ENVELOPE[k]
            r = abs(float(x[twoaxis_model._PARAM_INDEX[k]])) / bound
            if r > ratio:
                worst, ratio = k, r
    if not worst:
        return {}
    value = float(x[twoaxis_model._PARAM_INDEX[worst]])
    if worst == ALPHA:
        return {
            ALPHA: f"misalignment outside the envelope ({math.degrees(value):.1f}°, "
            f"at most ±{MAX_MISALIGN_DEG:g}°)"
        }
    return {
        worst: f"{_LABEL[worst]} outside the envelope ({value:.3g}"
        f"{_UNIT[worst]}, at most ±{ENVELOPE[worst]:g}{_UNIT[worst]})"
    }


def _ties(model: ModelName, ident: TwoAxisIdent) -> bool:
    """Whether the held transverse scale follows the longitudinal one."""
    return TIE_HELD_SCALE and "m" in PARAM_NAMES[model] and M_T in ident.unidentifiable
