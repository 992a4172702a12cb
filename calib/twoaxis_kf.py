"""The two-axis model (:mod:`calib.twoaxis`) learnt by an extended Kalman filter.

The state holds the unknowns the window determines — the same verdicts as least
squares (:func:`calib.twoaxis.judge_two_axis` on the series), the others held at the
prior (a held transverse scale following the longitudinal one,
:data:`calib.twoaxis.TIE_HELD_SCALE`; where α is refused the transverse scale and
bias are reported held at the prior, :func:`calib.twoaxis.hold_without_misalignment`). The sensor's parameters are nearly constant
(:data:`KF_PARAM_Q_PER_S`), the current a random walk (:data:`KF_CURRENT_PSD_M2PS3`).
Each sample's two readings are one vector measurement; the reference's ground
velocity and the heading are taken as known (a DVL's millimetre noise is far below
the log's). The measurement is linearised about a **nominal** (the least-squares
fit of the same series, then the filter's own previous pass): its parameters and
its current at each sample, not the state being updated. Linearised about the
state itself (an extended filter), the first minutes — before the turns have told
the misalignment from the current — take the Jacobians at a wrong α and current,
the covariance shrinks along the wrong directions and the nearly constant
parameters keep the error: on the figure-8 of ``emlogd simulate --scale 0.5``
(seeds 1–6, an aligned sensor) the extended filter's α was 0.8–2.3° off on four
seeds of six (4 to 17 of its σ), the linearised one within 0.1° of least squares
on every seed. σ come from the final
covariance.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.models import PARAM_NAMES, FloatArray
from calib.twoaxis import (
    ALPHA,
    B_T,
    DEFAULT_TWO_AXIS_RULE,
    M_T,
    ModelState,
    TwoAxisFit,
    TwoAxisParams,
    TwoAxisRule,
    TwoAxisSeries,
    fit_two_axis,
    hold_without_misalignment,
    model_state,
)

KF_PARAM_Q_PER_S = 1e-10
"""Random walk of the sensor's parameters in the two-axis filter, per second (in the
unit² of each: the parameters change over weeks)."""
KF_CURRENT_PSD_M2PS3 = 1e-6
"""Spectral density of the current's random walk in the two-axis filter, m²/s³ (the
current changes over minutes: about 0.03 m/s in 15 min)."""
KF_P0 = {"a": 0.05**2, "m": 0.3**2, "b": 0.5**2, ALPHA: math.radians(10.0) ** 2}
"""The initial variance of each unknown in the two-axis filter (the others
:data:`KF_P0_OTHER`): about the physical envelope's half-width, so the prior does not
pull the estimate."""
KF_P0_OTHER = 0.5**2
KF_PASSES = 2
"""Passes over the series: the first linearised about the least-squares fit, each
next one about the previous pass's parameters and filtered current, starting again
from the initial covariance (:func:`_run`)."""
TRACE_NAMES = (ALPHA, M_T, B_T)
"""The unknowns whose filtered value and σ at each sample the fit's ``trace`` holds,
in its columns (α in rad), then their σ."""
MIN_NOISE_MPS = 1e-3
"""The least measurement noise the filter takes for an axis, m/s."""


def kf_two_axis(
    model: str,
    t_s: npt.ArrayLike,
    s: TwoAxisSeries,
    *,
    current: bool = True,
    prior: TwoAxisParams | None = None,
    rule: TwoAxisRule = DEFAULT_TWO_AXIS_RULE,
    noise_mps: tuple[float, float] | None = None,
    current_knot_s: float | None = None,
) -> TwoAxisFit:
    """The two-axis model learnt sample by sample (module docstring).

    Args:
        model: the longitudinal model.
        t_s: sample times, s, non-decreasing.
        s: the series.
        current: estimate the current.
        prior: the value of the unknowns the window does not determine (the
            least-squares fit, the first nominal, holds them there too).
        rule: the identifiability thresholds.
        noise_mps: each axis's measurement noise (1σ), m/s (None: the residuals of
            the least-squares fit on the same series).
        current_knot_s: the least-squares fit that gives the verdicts and the noise
            takes a current linear between knots this far apart
            (:func:`calib.twoaxis.fit_two_axis`); the filter's own current wanders.

    Returns:
        The filter's final state as a fit (``method`` ``"KF"``).

    Raises:
        ModelError: unknown model.
        DataError: bad times.
    """
    ls = fit_two_axis(
        model,
        s,
        current=current,
        prior=prior,
        rule=rule,
        t_s=t_s,
        current_knot_s=current_knot_s,
        hold=False,
    )
    st = model_state(model, s, ls.ident)
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    n = st.n
    if t.size != n or not np.all(np.isfinite(t)):
        raise DataError("times must be finite and as long as the speeds")
    if n > 1 and not np.all(np.diff(t) >= 0.0):
        raise DataError("times must not decrease")
    sig = noise_mps if noise_mps is not None else (ls.rmse_l_mps, ls.rmse_t_mps)
    r = np.diag([max(sig[0], MIN_NOISE_MPS) ** 2, max(sig[1], MIN_NOISE_MPS) ** 2])
    x = st.x0(ls.params)
    cur = np.zeros((n, 2)) if ls.current_series is None else ls.current_series
    trace = np.full((n, 2 * len(TRACE_NAMES)), math.nan)
    for _ in range(KF_PASSES):
        x, p, res, cur = _run(st, t, x, cur, r, trace)
    std = np.full(x.size, math.nan)
    std[st.free] = np.sqrt(np.maximum(np.diag(p), 0.0))
    params = st.params(x)
    determined = set(ls.ident.determined)
    stderr: dict[str, float | None] = {
        pn: (float(std[st.index(pn)]) if pn in determined else None)
        for pn in PARAM_NAMES[params.model]
    }
    stderr["misalign_deg"] = (
        math.degrees(float(std[st.index(ALPHA)])) if ALPHA in determined else None
    )
    stderr[M_T] = float(std[st.index(M_T)]) if M_T in determined else None
    stderr[B_T] = float(std[st.index(B_T)]) if B_T in determined else None
    has_current = current and "current" in determined
    cn, ce = st.current(x)
    cs = st.current_std(std)
    rl, rt = res[:, 0], res[:, 1]
    fit = TwoAxisFit(
        params=params,
        stderr=stderr,
        current_mps=(cn, ce) if has_current else None,
        current_std_mps=cs if has_current else None,
        rmse_l_mps=math.sqrt(float(rl @ rl) / n),
        rmse_t_mps=math.sqrt(float(rt @ rt) / n),
        n_samples=n,
        ident=ls.ident,
        correlation=1.0,
        method="KF",
        current_series=cur if has_current else None,
        trace=trace,
    )
    return hold_without_misalignment(fit, prior)


def _run(
    st: ModelState,
    t: FloatArray,
    x_nom: FloatArray,
    cur_nom: FloatArray,
    r: FloatArray,
    trace: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """One pass of the filter linearised about a nominal (:data:`KF_PASSES`): the
    parameters ``x_nom`` and the current ``cur_nom`` (N, 2) at each sample. It starts
    from the nominal's parameters with the initial covariance (:data:`KF_P0`) and
    returns the final state, its covariance over ``st.free``, each sample's
    innovation (N, 2) and filtered current (N, 2); ``trace`` (N, 6) takes each
    sample's :data:`TRACE_NAMES` and their σ (nan: held)."""
    x = x_nom.copy()
    x = st.with_current(x, float(cur_nom[0, 0]), float(cur_nom[0, 1])) if st.n else x
    free = st.free
    k = len(free)
    p = np.diag([KF_P0.get(st.name_of(i), KF_P0_OTHER) for i in free])
    q_rate = np.array(
        [KF_CURRENT_PSD_M2PS3 if st.is_current(i) else KF_PARAM_Q_PER_S for i in free]
    )
    eye = np.eye(k)
    n = st.n
    res = np.empty((n, 2))
    cur = np.empty((n, 2))
    nom = x_nom.copy()
    traced = [
        (c, i, free.index(i)) for c, u in enumerate(TRACE_NAMES) if (i := st.index(u)) in free
    ]
    for j in range(n):
        if j and k:
            p[np.diag_indices(k)] += q_rate * float(t[j] - t[j - 1])
        nom = st.with_current(nom, float(cur_nom[j, 0]), float(cur_nom[j, 1]))
        innov, h = st.step(nom, j)
        hf = h[:, free]
        innov = innov - hf @ (x[free] - nom[free])
        res[j] = innov
        if k:
            s_mat = hf @ p @ hf.T + r
            gain = np.linalg.solve(s_mat, hf @ p).T
            x[free] += gain @ innov
            ikh = eye - gain @ hf
            p = ikh @ p @ ikh.T + gain @ r @ gain.T
        cur[j] = st.current(x)
        for c, i, f in traced:
            trace[j, c] = x[i]
            trace[j, len(TRACE_NAMES) + c] = math.sqrt(max(float(p[f, f]), 0.0))
    return x, p, res, cur
