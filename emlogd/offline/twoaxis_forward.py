"""The forward speed of ``--axes 2`` (calibrate, evaluate, crossval, report) by the
daemon's rule: each reading's by whichever of the two-axis calibration's own
correction and the one-axis calibration's (turned back by α) has the smaller expected
error, weighed on the readings of the last 2 s up to it
(:class:`emlogd.pipeline.twoaxis_sup.ForwardChoice`, the daemon's own code), and the
one-axis calibration's wherever α is refused (a straight run: the two-axis fit's
forward parameters are then the longitudinal axis's alone, with the transverse scale
and bias held).

The reading's noise the choice weighs is measured as the daemon's learner measures
it: the pooled scatter of the raw forward readings about their means over blocks of
:data:`~emlogd.pipeline.twoaxis_learn.BLOCK_S`
(:meth:`~emlogd.pipeline.twoaxis_learn.TwoAxisLearner.noise_var`), here over the
whole capture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calib.models import FloatArray, Params, correct_array
from calib.twoaxis import TwoAxisParams
from emlogd.pipeline.twoaxis_learn import BLOCK_S, MIN_NOISE_DOF, ONE_AXIS_FORWARD
from emlogd.pipeline.twoaxis_sup import ForwardChoice, noise_gain

TWO_AXIS = "two_axis"
"""The forward speed by the two-axis calibration's own correction (and the choice per
reading where a one-axis calibration is known)."""
ONE_AXIS = "one_axis"
"""The forward speed by the one-axis calibration's, α refused."""


@dataclass(frozen=True, slots=True)
class ForwardRule:
    """Whose forward speed ``--axes 2`` reports, and why.

    Attributes:
        one_axis: the one-axis calibration of the same forward readings (``calibrate
            --current --uut-source VBW``); None: none known (a file written without
            it), the two-axis calibration's own throughout.
        alpha_refused: why α is refused ("" where it is determined).
    """

    one_axis: Params | None
    alpha_refused: str = ""

    @property
    def forward(self) -> str:
        """:data:`ONE_AXIS` where α is refused and a one-axis calibration is known,
        else :data:`TWO_AXIS`."""
        return ONE_AXIS if self.alpha_refused and self.one_axis is not None else TWO_AXIS

    @property
    def reason(self) -> str | None:
        """Why the forward speed is the one-axis calibration's (None: it is not)."""
        if self.forward != ONE_AXIS:
            return None
        return f"{ONE_AXIS_FORWARD}: the misalignment is refused ({self.alpha_refused})"

    def to_dict(self) -> dict[str, object]:
        """JSON keys: ``forward``, ``forward_reason`` and ``one_axis`` (the model's
        ``a``, ``m``, ``b`` with ``model``, or None)."""
        one = self.one_axis
        return {
            "forward": self.forward,
            "forward_reason": self.reason,
            "one_axis": None if one is None else {"model": one.model, **one.as_dict()},
        }


NO_ONE_AXIS = ForwardRule(None)
"""No one-axis calibration known: the two-axis calibration's own forward speed."""


def noise_var(t: FloatArray, raw_l: FloatArray) -> float | None:
    """The forward reading's noise variance, m²/s²: the pooled scatter of the readings
    about their block's mean over blocks of :data:`BLOCK_S` (None: under
    :data:`MIN_NOISE_DOF` degrees of freedom)."""
    ok = np.isfinite(t) & np.isfinite(raw_l)
    t, x = t[ok], raw_l[ok]
    if t.size == 0:
        return None
    _, idx, n = np.unique(np.floor((t - t[0]) / BLOCK_S), return_inverse=True, return_counts=True)
    means = np.bincount(idx, weights=x) / n
    ss = float(np.sum((x - means[idx]) ** 2))
    dof = int(np.sum(n - 1))
    return ss / dof if dof >= MIN_NOISE_DOF else None


def one_axis_forward(
    raw_l: FloatArray, raw_t: FloatArray, params: TwoAxisParams, one: Params
) -> FloatArray:
    """The one-axis calibration ``one``'s forward speed turned back by the two-axis
    calibration's α with its corrected athwart speed (the daemon's
    :meth:`~emlogd.pipeline.twoaxis_sup.Figures.hull_frame`), m/s."""
    ca, sa = math.cos(params.misalign_rad), math.sin(params.misalign_rad)
    ws = (raw_t - params.b_t_mps) / (1.0 + params.m_t)
    return np.asarray(correct_array(one, raw_l) * ca - ws * sa, dtype=np.float64)


def forward_speed(
    t: FloatArray,
    raw_l: FloatArray,
    raw_t: FloatArray,
    params: TwoAxisParams,
    rule: ForwardRule,
    var: float | None = None,
) -> FloatArray:
    """The forward speed through the water along the hull of each reading (in time
    order), m/s, by ``rule`` (module docstring); ``var`` the reading's noise variance
    (None: measured on these readings, :func:`noise_var`)."""
    own = params.correct(raw_l, raw_t)[0]
    one_p = rule.one_axis
    if one_p is None:
        return own
    one = one_axis_forward(raw_l, raw_t, params, one_p)
    if rule.forward == ONE_AXIS:
        return one
    if var is None:
        var = noise_var(t, raw_l)
    ca = math.cos(params.misalign_rad)
    us = correct_array(params.longitudinal, raw_l)
    one_s = correct_array(one_p, raw_l)
    out = np.array(own, dtype=np.float64, copy=True)
    choice = ForwardChoice()
    for i in range(out.size):
        own_gain = ca * noise_gain(params.longitudinal, float(us[i]))
        one_gain = ca * ca * noise_gain(one_p, float(one_s[i]))
        if choice.one_axis(float(t[i]), float(own[i]), own_gain, float(one[i]), one_gain, var):
            out[i] = one[i]
    return out
