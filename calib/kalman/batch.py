"""KF-EMx over recorded arrays: the offline use of :class:`~calib.kalman.filters.KfCalibrator`.

:func:`run_kf` feeds aligned series (raw reading, reference, optional heading) to the
per-sample filter in order, every unknown free to learn, as the paper runs its
KF-EMx over a trajectory, and returns the final estimate with per-sample
histories (the convergence sleeve and the NIS of the paper's figures).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from calib.errors import DataError
from calib.estimate import Estimate, Estimated
from calib.kalman.filters import KfCalibrator, KfConfig
from calib.models import FloatArray


@dataclass(frozen=True, eq=False)
class KfRun(Estimated):
    """Result of running KF-EMx over a recorded series.

    Attributes:
        estimate: the final estimate (what cross-validation freezes): θ̂ and its
            standard deviations, the current (north, east) in m/s and its standard
            deviations (None without current states).
        covariance: final P, shape (n, n).
        speed_mps: speed state after each sample, shape (N,) (empty without history).
        theta: parameter estimate after each sample, shape (N, p) (empty without history).
        theta_std: its standard deviation from P, shape (N, p) (the convergence sleeve).
        current: current estimate after each sample, shape (N, 2) (empty without
            history or current).
        current_std: its standard deviation, shape (N, 2).
        y: raw innovation per sample, m/s, shape (N,) (nan where no raw reading).
        S: innovation variance per sample, (m/s)², shape (N,).
        nis: NIS per sample, shape (N,) (nan where no raw reading or no reference).
    """

    estimate: Estimate
    covariance: FloatArray
    speed_mps: FloatArray
    theta: FloatArray
    theta_std: FloatArray
    current: FloatArray
    current_std: FloatArray
    y: FloatArray
    S: FloatArray
    nis: FloatArray


def run_kf(
    model: str,
    t_s: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    ref_mps: npt.ArrayLike,
    config: KfConfig | None = None,
    *,
    heading_deg: npt.ArrayLike | None = None,
    current: bool = False,
    history: bool = True,
    calibrator: KfCalibrator | None = None,
    learn: bool | Collection[str] = True,
) -> KfRun:
    """Run KF-EMx over aligned arrays with the per-sample filter.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        t_s: sample times in s, shape (N,), non-decreasing.
        raw_mps: raw EMlog speeds in m/s, shape (N,); nan = no reading.
        ref_mps: lag-aligned reference speeds in m/s, shape (N,); nan = outage.
        config: tuning (default :class:`KfConfig`).
        heading_deg: heading at the reference's time, degrees, shape (N,); nan =
            unknown (needed with ``current``).
        current: estimate the sea current.
        history: keep per-sample histories (False: only final values and
            innovations, faster for cross-validation).
        calibrator: continue an existing filter instead of a fresh one.
        learn: the unknowns that may move (True: all; see :meth:`KfCalibrator.update`);
            the others stay at their prior.

    Returns:
        The final estimate and the per-sample series.

    Raises:
        DataError: arrays of different lengths, decreasing times, or a current
            without headings.
        ModelError: unknown model.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    if not t.shape == raw.shape == ref.shape:
        raise DataError(f"t, raw, ref differ in length: {t.size}, {raw.size}, {ref.size}")
    kf = calibrator if calibrator is not None else KfCalibrator(model, config, current=current)
    lay = kf.layout
    if lay.current:
        if heading_deg is None:
            raise DataError("a filter with current states needs the heading")
        hd = np.radians(np.asarray(heading_deg, dtype=np.float64).reshape(-1))
        if hd.shape != t.shape:
            raise DataError(f"heading has {hd.size} samples, t has {t.size}")
        cos_h, sin_h = np.cos(hd).tolist(), np.sin(hd).tolist()
    else:
        cos_h = sin_h = [math.nan] * t.size
    dts = np.diff(t, prepend=t[0] if t.size else 0.0)
    if not np.all(dts >= 0.0):
        raise DataError("times must be non-decreasing")
    n = t.size
    p = len(lay.params)
    ys = [math.nan] * n
    ss = [math.nan] * n
    nis = [math.nan] * n
    speeds: list[float] = []
    hist: list[tuple[float, ...]] = []
    hist_var: list[tuple[float, ...]] = []
    for k, (dt, zr, zv, c, s) in enumerate(
        zip(dts.tolist(), raw.tolist(), ref.tolist(), cos_h, sin_h, strict=True)
    ):
        cs = (c, s) if c == c else None  # nan: heading unknown
        res = kf.update(
            zr if zr == zr else None, zv if zv == zv else None, dt, heading_cs=cs, learn=learn
        )
        if res.raw is not None:
            ys[k] = res.raw.y
            ss[k] = res.raw.S
            if res.learnt:
                nis[k] = res.raw.nis
        if history:
            x = kf.x
            P = kf.covariance()
            speeds.append(x[0])
            hist.append(x[1:])
            hist_var.append(tuple(P[i][i] for i in range(1, lay.n)))
    m = lay.n - 1
    if history:
        arr = np.array(hist, dtype=np.float64).reshape(n, m)
        std = np.sqrt(np.array(hist_var, dtype=np.float64).reshape(n, m))
        theta, theta_std = arr[:, :p], std[:, :p]
        cur, cur_std = (arr[:, p:], std[:, p:]) if lay.current else (np.empty((0, 2)),) * 2
        speed = np.array(speeds, dtype=np.float64)
    else:
        theta = theta_std = np.empty((0, p))
        cur = cur_std = np.empty((0, 2))
        speed = np.empty(0)
    return KfRun(
        estimate=Estimate(kf.params, kf.param_std, kf.current_mps, kf.current_std_mps),
        covariance=np.array(kf.covariance()),
        speed_mps=speed,
        theta=theta,
        theta_std=theta_std,
        current=cur,
        current_std=cur_std,
        y=np.array(ys),
        S=np.array(ss),
        nis=np.array(nis),
    )
