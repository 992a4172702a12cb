"""``emlogd report``: PNG figures like the paper's, from captures.

Needs the ``report`` extra (matplotlib); the daemon never imports this module.
Figures written to the output directory:

- ``speed_<capture>.png`` — raw, calibrated (frozen KF estimate) and reference
  speed over a window of each capture;
- ``convergence.png`` — the KF scale factor and bias with their ±3σ sleeve over
  the concatenated captures;
- ``nis.png`` — NIS per sample, its running mean, and the χ²(1) 95 % bounds;
- ``current.png`` — with current states, the estimated current (north, east) and
  its ±3σ sleeve over the concatenated captures;
- ``trajectory.png`` — East/North track of every capture, integrated from the
  reference's along-hull speed and the heading (sideslip left out);
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
from emlogd.offline.dataset import Recording
from emlogd.offline.jobs import OfflineError, crossval, find_lag
from emlogd.pipeline.core import UutSettings

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
    recs: Sequence[Recording],
    settings: UutSettings,
    outdir: str | Path,
    *,
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
    model = settings.model
    lag_report = find_lag(recs, settings, lag)
    pairs = [r.aligned(lag_report.lag_s) for r in recs]
    masks = [p.usable(heading=settings.current) for p in pairs]
    if not any(m.any() for m in masks):
        raise OfflineError("no aligned samples: nothing to plot")
    t = np.concatenate([p.t[m] for p, m in zip(pairs, masks, strict=True)])
    raw = np.concatenate([p.raw[m] for p, m in zip(pairs, masks, strict=True)])
    ref = np.concatenate([p.ref[m] for p, m in zip(pairs, masks, strict=True)])
    heading = np.concatenate([p.heading[m] for p, m in zip(pairs, masks, strict=True)])
    run = run_kf(
        model,
        t,
        raw,
        ref,
        settings.kf,
        heading_deg=heading if settings.current else None,
        current=settings.current,
    )
    written: list[Path] = []
    frame = " + current" if settings.current else ""
    title_pair = f"{settings.port} vs {settings.reference_port} ({settings.reference_field})"

    # 1. speeds over a window at the start of each capture
    for r, p in zip(recs, pairs, strict=True):
        ok = p.usable()
        if not ok.any():
            continue
        t0 = p.t[ok][0]
        sel = ok & (p.t - t0 <= WINDOW_S)
        fig, ax = plt.subplots(figsize=(10, 4))
        tt = p.t[sel] - t0
        ax.plot(tt, p.raw[sel], lw=0.8, label=f"{settings.port} raw")
        ax.plot(tt, correct_array(run.params, p.raw[sel]), lw=0.8, label=f"calibrated (KF-{model})")
        ax.plot(tt, p.ref[sel], lw=0.8, label=f"{settings.reference_port} reference")
        ax.set_xlabel(f"time since start of capture (s; the first {WINDOW_S:.0f} s shown)")
        ax.set_ylabel("longitudinal speed (m/s)")
        ax.set_title(f"{r.name}: {title_pair}, lag {lag_report.lag_s:.2f} s")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        ax.grid(True, alpha=0.3)
        written.append(_save(fig, out / f"speed_{r.name}.png", plt))
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
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        _robust_ylim(ax, est)
    axes[-1].set_xlabel("time since first sample (s, captures back to back)")
    axes[0].set_title(f"KF-{model}{frame} convergence: {title_pair}")
    written.append(_save(fig, out / "convergence.png", plt))
    if progress is not None:
        progress("report: convergence", 0.35)

    # 3. the current over time
    if settings.current and run.current.size:
        fig, axes = plt.subplots(2, 1, figsize=(10, 5.2), sharex=True)
        for i, (ax, name) in enumerate(zip(axes, ("north", "east"), strict=True)):
            est = run.current[:, i]
            sd = run.current_std[:, i]
            ax.plot(tt, est, lw=0.9, label=f"current {name}")
            ax.fill_between(tt, est - 3 * sd, est + 3 * sd, alpha=0.3, label="±3σ")
            ax.set_ylabel(f"{name} (m/s)")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
            _robust_ylim(ax, est)
        axes[-1].set_xlabel("time since first sample (s, captures back to back)")
        axes[0].set_title(f"KF-{model} + current: the estimated current, {title_pair}")
        written.append(_save(fig, out / "current.png", plt))
    if progress is not None:
        progress("report: current", 0.45)

    # 4. NIS
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
    ax.set_title(f"KF-{model}{frame} normalised innovation squared: {title_pair}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.grid(True, alpha=0.3)
    written.append(_save(fig, out / "nis.png", plt))
    if progress is not None:
        progress("report: NIS", 0.55)

    # 5. trajectory map
    fig, ax = plt.subplots(figsize=(7, 7))
    drawn = False
    for r in recs:
        track = _track(r)
        if track is None:
            continue
        e, n = track
        ax.plot(e, n, lw=0.8, label=r.name)
        ax.plot(e[:1], n[:1], "ko", ms=3)
        drawn = True
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"Track over ground from {settings.reference_port} (each from its own start)")
    if drawn:
        ax.legend(loc="best")
    ax.grid(True, alpha=0.3)
    written.append(_save(fig, out / "trajectory.png", plt))
    if progress is not None:
        progress("report: trajectory", 0.65)

    # 6. cross-validation heat maps
    if len(recs) >= 2:
        result, _ = crossval(recs, settings, lag=lag_report.lag_s, workers=workers)
        written.append(_heatmaps(result, out / "crossval.png", plt))
    if progress is not None:
        progress("report: cross-validation", 1.0)
    return written


def _robust_ylim(ax: Any, est: Any) -> None:
    span = np.nanpercentile(est[len(est) // 10 :], [1, 99]) if len(est) > 10 else None
    if span is not None and np.all(np.isfinite(span)):
        pad = max(0.05, float(span[1] - span[0]))
        ax.set_ylim(float(span[0]) - pad, float(span[1]) + pad)


def _track(r: Recording) -> tuple[Any, Any] | None:
    ok = r.ok_ref & np.isfinite(r.v_ref) & np.isfinite(r.heading)
    if ok.sum() < 2:
        return None
    t = r.t_ref[ok]
    lon = r.v_ref[ok]
    psi = np.radians(r.heading[ok])
    dt = np.diff(t, prepend=t[0])
    dt = np.where(dt > 2.0, 0.0, dt)  # do not integrate across reference outages
    return np.cumsum(lon * np.sin(psi) * dt), np.cumsum(lon * np.cos(psi) * dt)


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
