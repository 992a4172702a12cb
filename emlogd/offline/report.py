"""``emlogd report``: PNG figures like the paper's, from captures.

Needs the ``report`` extra (matplotlib); the daemon never imports this module.
Figures written to the output directory:

- ``speed_<capture>.png`` — raw, calibrated (frozen KF estimate) and reference
  speed over a window of each capture (the first :data:`WINDOW_S`, named on the plot);
- ``convergence.png`` — the KF scale factor and bias with their ±3σ sleeve over
  the concatenated captures;
- ``nis.png`` — NIS per sample, its running mean over :data:`NIS_WINDOW` samples with
  the 95 % bounds of such a mean, and the χ²(1) 97.5 % quantile;
- ``current.png`` — with current states, the estimated current (north, east) and
  its ±3σ sleeve over the concatenated captures;
- ``trajectory.png`` — East/North track of every capture, integrated from the
  reference's along-hull speed and the heading (sideslip left out);
- ``crossval.png`` — heat maps of the improvement of LS-EMx and KF-EMx trained on
  each capture and tested on each other one, the number in every cell (≥ 8 pt).

Legends sit outside the axes, so that they never hide data.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calib.crossval import CrossValResult
from calib.kalman import KfRun, run_kf
from calib.metrics import chi2_1_quantile, chi2_mean_bounds
from calib.models import FloatArray, correct_array
from emlogd.offline import ProgressFn
from emlogd.offline.dataset import Aligned, BoolArray, Recording
from emlogd.offline.jobs import OfflineError, crossval, find_lag
from emlogd.pipeline.settings import UutSettings

WINDOW_S = 600.0
"""Length of the speed-plot window, s (the start of each capture)."""

NIS_WINDOW = 60
"""Samples in the NIS plot's running mean."""

_OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8}
"""Legend placement: right of the axes, off the data."""


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
    on_lag_note: Callable[[str], None] | None = None,
) -> list[Path]:
    """Write the figures; return their paths.

    ``on_lag_note`` receives the lag's fallback note, when the lag was not measured
    (the command prints it once on stderr).

    Raises:
        OfflineError: matplotlib missing, or no aligned data.
    """
    plt = _pyplot()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    lag_report = find_lag(recs, settings, lag)
    if lag_report.note and on_lag_note is not None:
        on_lag_note(lag_report.note)
    pairs = [r.aligned(lag_report.lag_s) for r in recs]
    masks = [p.usable(heading=settings.current) for p in pairs]
    if not any(m.any() for m in masks):
        raise OfflineError("no aligned samples: nothing to plot")
    t, raw, ref, heading = (
        np.concatenate([getattr(p, k)[m] for p, m in zip(pairs, masks, strict=True)])
        for k in ("t", "raw", "ref", "heading")
    )
    run = run_kf(
        settings.model,
        t,
        raw,
        ref,
        settings.kf,
        heading_deg=heading if settings.current else None,
        current=settings.current,
    )
    fig = _Plots(
        plt, out, settings, run, t - t[0], f"lag {lag_report.lag_s:.2f} s ({lag_report.source})"
    )
    steps: list[tuple[str, float, Callable[[], list[Path]]]] = [
        ("speed plots", 0.2, lambda: fig.speeds(recs, pairs)),
        ("convergence", 0.35, fig.convergence),
        ("current", 0.45, fig.current),
        ("NIS", 0.55, fig.nis),
        ("trajectory", 0.65, lambda: fig.trajectory(recs)),
        ("cross-validation", 1.0, lambda: fig.crossval(recs, lag_report.lag_s, workers)),
    ]
    written: list[Path] = []
    for what, done, step in steps:
        written += step()
        if progress is not None:
            progress(f"report: {what}", done)
    return written


@dataclass(frozen=True, slots=True)
class _Plots:
    """The figures of one report: the filter's run over the concatenated captures and
    the words every title shares."""

    plt: Any
    out: Path
    settings: UutSettings
    run: KfRun
    tt: FloatArray
    """Time since the first sample, s (the captures back to back)."""
    lag_txt: str

    @property
    def title_pair(self) -> str:
        s = self.settings
        return f"{s.port} vs {s.reference_port} ({s.reference_field})"

    @property
    def frame(self) -> str:
        return " + current" if self.settings.current else ""

    def speeds(self, recs: Sequence[Recording], pairs: Sequence[Aligned]) -> list[Path]:
        """1. The speeds over a window at the start of each capture."""
        written = []
        for r, p in zip(recs, pairs, strict=True):
            ok = p.usable()
            if ok.any():
                written.append(self._speed(r.name, p, ok))
        return written

    def _speed(self, name: str, p: Aligned, ok: BoolArray) -> Path:
        s, plt = self.settings, self.plt
        t0 = p.t[ok][0]
        sel = ok & (p.t - t0 <= WINDOW_S)
        total = float(p.t[ok][-1] - t0)
        shown = float(p.t[sel][-1] - t0)
        window = (
            f"the whole capture, {total:.0f} s"
            if shown >= total
            else f"window 0–{WINDOW_S:.0f} s of {total:.0f} s"
        )
        fig, ax = plt.subplots(figsize=(10, 4))
        tt = p.t[sel] - t0
        ax.plot(tt, p.raw[sel], lw=0.8, label=f"{s.port} raw")
        calibrated = correct_array(self.run.params, p.raw[sel])
        ax.plot(tt, calibrated, lw=0.8, label=f"calibrated (KF-{s.model})")
        ax.plot(tt, p.ref[sel], lw=0.8, label=f"{s.reference_port} reference")
        ax.set_xlabel("time since start of capture (s)")
        ax.set_ylabel(f"{s.component} speed (m/s)")
        ax.set_title(f"{name} ({window}): {self.title_pair}, {self.lag_txt}")
        ax.legend(**_OUTSIDE)
        ax.grid(True, alpha=0.3)
        return _save(fig, self.out / f"speed_{name}.png", plt)

    def convergence(self) -> list[Path]:
        """2. The convergence sleeve of every parameter."""
        names = list(self.run.params.as_dict())
        fig, axes = self.plt.subplots(len(names), 1, figsize=(10, 2.6 * len(names)), sharex=True)
        axes = np.atleast_1d(axes)
        labels = {"a": "a (s/m)", "m": "m (-)", "b": "b (m/s)"}
        for i, (ax, name) in enumerate(zip(axes, names, strict=True)):
            est = self.run.theta[:, i]
            self._sleeve(ax, est, self.run.theta_std[:, i], f"{name} estimate", labels[name])
        axes[-1].set_xlabel("time since first sample (s, captures back to back)")
        axes[0].set_title(f"KF-{self.settings.model}{self.frame} convergence: {self.title_pair}")
        return [_save(fig, self.out / "convergence.png", self.plt)]

    def current(self) -> list[Path]:
        """3. The current over time (with current states)."""
        run = self.run
        if not (self.settings.current and run.current.size):
            return []
        fig, axes = self.plt.subplots(2, 1, figsize=(10, 5.2), sharex=True)
        for i, (ax, name) in enumerate(zip(axes, ("north", "east"), strict=True)):
            est = run.current[:, i]
            self._sleeve(ax, est, run.current_std[:, i], f"current {name}", f"{name} (m/s)")
        axes[-1].set_xlabel("time since first sample (s, captures back to back)")
        axes[0].set_title(
            f"KF-{self.settings.model} + current: the estimated current, {self.title_pair}"
        )
        return [_save(fig, self.out / "current.png", self.plt)]

    def _sleeve(self, ax: Any, est: FloatArray, sd: FloatArray, label: str, ylabel: str) -> None:
        """An estimate over time with its ±3σ sleeve."""
        ax.plot(self.tt, est, lw=0.9, label=label)
        ax.fill_between(self.tt, est - 3 * sd, est + 3 * sd, alpha=0.3, label="±3σ")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(**_OUTSIDE)
        _robust_ylim(ax, est)

    def nis(self) -> list[Path]:
        """4. The NIS per sample, its running mean and their bounds."""
        nis, tt = self.run.nis, self.tt
        ok = np.isfinite(nis)
        fig, ax = self.plt.subplots(figsize=(10, 4))
        ax.semilogy(tt[ok], np.maximum(nis[ok], 1e-6), ".", ms=1.5, alpha=0.4, label="NIS")
        win = NIS_WINDOW
        if ok.sum() > win:
            running = np.convolve(nis[ok], np.ones(win) / win, mode="valid")
            ax.semilogy(
                tt[ok][win - 1 :], running, lw=1.2, label=f"running mean, {win}-sample window"
            )
            lo, hi = chi2_mean_bounds(win)
            ax.axhline(lo, color="k", ls=":", lw=0.8, label=f"95 % bounds of a {win}-mean")
            ax.axhline(hi, color="k", ls=":", lw=0.8)
        ax.axhline(chi2_1_quantile(0.975), color="r", ls="--", lw=0.8, label="χ²(1) 97.5 %")
        ax.set_xlabel("time since first sample (s, captures back to back)")
        ax.set_ylabel("NIS (-)")
        ax.set_title(
            f"KF-{self.settings.model}{self.frame} normalised innovation squared: {self.title_pair}"
        )
        ax.legend(**_OUTSIDE)
        ax.grid(True, alpha=0.3)
        return [_save(fig, self.out / "nis.png", self.plt)]

    def trajectory(self, recs: Sequence[Recording]) -> list[Path]:
        """5. The track over ground of every capture."""
        fig, ax = self.plt.subplots(figsize=(7, 7))
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
        ax.set_title(
            f"Track over ground from {self.settings.reference_port} (each from its own start)"
        )
        if drawn:
            ax.legend(**_OUTSIDE)
        ax.grid(True, alpha=0.3)
        return [_save(fig, self.out / "trajectory.png", self.plt)]

    def crossval(self, recs: Sequence[Recording], lag_s: float, workers: int | None) -> list[Path]:
        """6. The cross-validation heat maps (with two captures or more)."""
        if len(recs) < 2:
            return []
        result, _ = crossval(recs, self.settings, lag=lag_s, workers=workers)
        return [_heatmaps(result, self.out / "crossval.png", self.plt)]


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


def _cell_text(v: float) -> str:
    """An improvement for a heat-map cell: at most 5 characters (-41014 → -41k)."""
    if not math.isfinite(v):
        return "n/a"
    if abs(v) >= 999.5:
        return f"{v / 1000.0:.0f}k" if abs(v) >= 9999.5 else f"{v / 1000.0:.1f}k"
    return f"{v:.0f}"


def _heatmaps(result: CrossValResult, path: Path, plt: Any) -> Path:
    names = [s.name for s in result.segments]
    n = len(names)
    ests = list(result.estimators)
    cols = min(4, len(ests))
    rows = math.ceil(len(ests) / cols)
    # a cell at least 0.5 in wide: five characters at 8 pt fit inside
    side = max(3.2, 0.5 * n + 1.2)
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(side * cols + 1.6, side * rows + 1.0),
        squeeze=False,
        sharex=True,
        sharey=True,
        layout="constrained",
    )
    cmap = plt.get_cmap("RdYlGn").with_extremes(bad="0.85")
    im = None
    for k, (ax, est) in enumerate(zip(axes.flat, ests, strict=False)):
        m = np.array([[e.improvement_pct for e in row] for row in result.matrix(est)])
        im = ax.imshow(np.ma.masked_invalid(np.clip(m, -100, 100)), cmap=cmap, vmin=-100, vmax=100)
        ax.set_title(est, fontsize=10)
        for i in range(n):
            for j in range(n):
                v = float(m[i, j])
                dark = math.isfinite(v) and abs(v) > 70
                ax.text(
                    j,
                    i,
                    _cell_text(v),
                    ha="center",
                    va="center",
                    fontsize=8,
                    color="white" if dark else "black",
                    fontweight="bold" if i == j else "normal",
                )
        ax.set_xticks(range(n), names, rotation=45, ha="right", fontsize=8)
        ax.set_yticks(range(n), names, fontsize=8)
        ax.tick_params(labelbottom=k // cols == rows - 1 or k + cols >= len(ests))
        ax.tick_params(labelleft=k % cols == 0)
        if k % cols == 0:
            ax.set_ylabel("trained on", fontsize=9)
        if k // cols == rows - 1 or k + cols >= len(ests):
            ax.set_xlabel("tested on", fontsize=9)
    for ax in list(axes.flat)[len(ests) :]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.7, label="RMSE improvement over raw (%, clipped ±100)")
    fig.suptitle(
        "Cross-validation: improvement over raw, % (row: trained on, column: tested on; "
        "diagonal in bold: in sample; k = ×1000; n/a: not fitted)",
        fontsize=10,
    )
    return _save(fig, path, plt)


def _save(fig: Any, path: Path, plt: Any) -> Path:
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
