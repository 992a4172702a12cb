"""``emlogd report``: PNG figures like the paper's, from captures.

Needs the ``report`` extra (matplotlib); the daemon never imports this module.
Figures written to the output directory:

- ``speed_<capture>.png`` — raw, calibrated (frozen KF estimate) and reference
  speed over a window of each capture;
- ``convergence.png`` — the KF scale factor and bias with their ±3σ sleeve over
  the concatenated captures;
- ``nis.png`` — NIS per sample, its running mean, and the χ²(1) 95 % bounds;
- ``trajectory.png`` — East/North track of every capture, integrated from the
  reference's ship-frame velocity and heading;
- ``crossval.png`` — heat maps of the improvement of LS-EMx and KF-EMx trained on
  each capture and tested on each other one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from calib.crossval import CrossValResult
from calib.kalman import run_kf
from calib.metrics import chi2_1_quantile, chi2_mean_bounds
from calib.models import correct_array
from emlogd.offline.dataset import CaptureData
from emlogd.offline.jobs import OfflineError, Pairing, aligned, crossval, find_lag

ProgressFn = Callable[[str, float], None]

WINDOW_S = 600.0
"""Length of the speed-plot window, s (the start of each capture)."""


def _pyplot() -> Any:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise OfflineError("emlogd report needs matplotlib: pip install 'emlogd[report]'") from None
    return plt


def report(
    datas: Sequence[CaptureData],
    pairing: Pairing,
    outdir: str | Path,
    *,
    model: str = "EM3",
    lag: float | None = None,
    progress: ProgressFn | None = None,
    workers: int | None = None,
) -> list[Path]:
    """Write the figures; return their paths.

    Raises:
        OfflineError: matplotlib missing, or no aligned data.
    """
    plt = _pyplot()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    lag_report = find_lag(datas, pairing, lag)
    pairs = aligned(datas, pairing, lag_report.lag_s)
    if not any(len(p) for p in pairs):
        raise OfflineError("no aligned samples: nothing to plot")
    t = np.concatenate([p.t for p in pairs])
    raw = np.concatenate([p.raw for p in pairs])
    ref = np.concatenate([p.ref for p in pairs])
    run = run_kf(model, t, raw, ref)
    written: list[Path] = []
    title_pair = f"{pairing.uut} vs {pairing.ref} ({pairing.ref_field})"

    # 1. speeds over a window of each capture
    for d, p in zip(datas, pairs, strict=True):
        if not len(p):
            continue
        sel = p.t - p.t[0] <= WINDOW_S
        fig, ax = plt.subplots(figsize=(10, 4))
        tt = p.t[sel] - p.t[0]
        ax.plot(tt, p.raw[sel], lw=0.8, label=f"{pairing.uut} raw")
        ax.plot(tt, correct_array(run.params, p.raw[sel]), lw=0.8, label=f"calibrated (KF-{model})")
        ax.plot(tt, p.ref[sel], lw=0.8, label=f"{pairing.ref} reference")
        ax.set_xlabel("time since start of capture (s)")
        ax.set_ylabel("longitudinal speed (m/s)")
        ax.set_title(f"{d.name}: {title_pair}, lag {lag_report.lag_s:.2f} s")
        ax.legend(loc="best")
        ax.grid(True, alpha=0.3)
        written.append(_save(fig, out / f"speed_{d.name}.png", plt))
    if progress is not None:
        progress("report: speed plots", 0.2)

    # 2. convergence sleeve
    names = list(run.params.as_dict())
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 2.6 * len(names)), sharex=True)
    axes = np.atleast_1d(axes)
    tt = t - t[0]
    for i, (ax, name) in enumerate(zip(axes, names, strict=True)):
        est = run.theta[:, i]
        sd = run.theta_std[:, i]
        ax.plot(tt, est, lw=0.9, label=f"{name} estimate")
        ax.fill_between(tt, est - 3 * sd, est + 3 * sd, alpha=0.3, label="±3σ")
        ax.set_ylabel({"a": "a (s/m)", "m": "m (-)", "b": "b (m/s)"}[name])
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right")
        span = np.nanpercentile(est[len(est) // 10 :], [1, 99]) if len(est) > 10 else None
        if span is not None and np.all(np.isfinite(span)):
            pad = max(0.05, float(span[1] - span[0]))
            ax.set_ylim(float(span[0]) - pad, float(span[1]) + pad)
    axes[-1].set_xlabel("time since first sample (s, captures back to back)")
    axes[0].set_title(f"KF-{model} convergence: {title_pair}")
    written.append(_save(fig, out / "convergence.png", plt))
    if progress is not None:
        progress("report: convergence", 0.4)

    # 3. NIS
    nis = run.nis
    ok = np.isfinite(nis)
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.semilogy(tt[ok], np.maximum(nis[ok], 1e-6), ".", ms=1.5, alpha=0.4, label="NIS")
    win = 60
    if ok.sum() > win:
        running = np.convolve(nis[ok], np.ones(win) / win, mode="valid")
        ax.semilogy(tt[ok][win - 1 :], running, lw=1.2, label=f"mean of {win}")
        lo, hi = chi2_mean_bounds(win)
        ax.axhline(lo, color="k", ls=":", lw=0.8, label=f"95 % bounds of a {win}-mean")
        ax.axhline(hi, color="k", ls=":", lw=0.8)
    ax.axhline(chi2_1_quantile(0.975), color="r", ls="--", lw=0.8, label="χ²(1) 97.5 %")
    ax.set_xlabel("time since first sample (s)")
    ax.set_ylabel("NIS (-)")
    ax.set_title(f"KF-{model} normalised innovation squared: {title_pair}")
    ax.legend(loc="upper right")
    ax.grid(True, alpha=0.3)
    written.append(_save(fig, out / "nis.png", plt))
    if progress is not None:
        progress("report: NIS", 0.5)

    # 4. trajectory map
    fig, ax = plt.subplots(figsize=(7, 7))
    drawn = False
    for d in datas:
        track = _track(d, pairing.ref)
        if track is None:
            continue
        e, n = track
        ax.plot(e, n, lw=0.8, label=d.name)
        ax.plot(e[:1], n[:1], "ko", ms=3)
        drawn = True
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"Track over ground from {pairing.ref} (each capture from its own start)")
    if drawn:
        ax.legend(loc="best")
    ax.grid(True, alpha=0.3)
    written.append(_save(fig, out / "trajectory.png", plt))
    if progress is not None:
        progress("report: trajectory", 0.6)

    # 5. cross-validation heat maps
    if len(datas) >= 2:
        result, _ = crossval(datas, pairing, lag=lag_report.lag_s, workers=workers)
        written.append(_heatmaps(result, out / "crossval.png", plt))
    if progress is not None:
        progress("report: cross-validation", 1.0)
    return written


def _track(d: CaptureData, port: str) -> tuple[Any, Any] | None:
    series = [s for (p, _), s in d.series.items() if p == port and s.kind == "sog"]
    if not series:
        return None
    s = series[0]
    heading = s.heading
    ok = s.valid & np.isfinite(s.longitudinal) & np.isfinite(heading)
    if ok.sum() < 2:
        return None
    t = s.t[ok]
    lon = s.longitudinal[ok]
    tr = np.where(np.isfinite(s.transverse[ok]), s.transverse[ok], 0.0)
    psi = np.radians(heading[ok])
    ve = lon * np.sin(psi) + tr * np.cos(psi)
    vn = lon * np.cos(psi) - tr * np.sin(psi)
    dt = np.diff(t, prepend=t[0])
    dt = np.where(dt > 2.0, 0.0, dt)  # do not integrate across bottom-lock gaps
    return np.cumsum(ve * dt), np.cumsum(vn * dt)


def _heatmaps(result: CrossValResult, path: Path, plt: Any) -> Path:
    names = [s.name for s in result.segments]
    ests = list(result.estimators)
    cols = 4
    rows = math.ceil(len(ests) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.6 * rows), squeeze=False)
    im = None
    for ax, est in zip(axes.flat, ests, strict=False):
        m = np.array([[e.improvement_pct for e in row] for row in result.matrix(est)])
        im = ax.imshow(np.clip(m, -100, 100), cmap="RdYlGn", vmin=-100, vmax=100)
        ax.set_xticks(range(len(names)), names, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(names)), names, fontsize=7)
        ax.set_title(est, fontsize=9)
        for i in range(len(names)):
            for j in range(len(names)):
                if np.isfinite(m[i, j]):
                    ax.text(j, i, f"{m[i, j]:.0f}", ha="center", va="center", fontsize=6)
        ax.set_xlabel("test", fontsize=7)
        ax.set_ylabel("train", fontsize=7)
    for ax in list(axes.flat)[len(ests) :]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.6, label="RMSE improvement (%)")
    fig.suptitle("Cross-validation: improvement over raw (train row × test column)")
    return _save(fig, path, plt)


def _save(fig: Any, path: Path, plt: Any) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
