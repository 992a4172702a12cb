"""``emlogd report --axes 2``: the figures of a two-axis calibration, from captures.

Needs the ``report`` extra (matplotlib), as :mod:`emlogd.offline.report`. The
calibration is :func:`emlogd.offline.twoaxis.calibrate_two_axis`'s, by least squares
and by the filter on every capture together. Figures written to the output
directory:

- ``speed2_<capture>.png`` — forward and athwart speed through the water over a
  window at the start of each capture (:data:`emlogd.offline.report.WINDOW_S`): the
  raw readings, the readings corrected by the least-squares fit, and the reference
  less the current fitted to that capture with the fit's parameters;
- ``misalignment.png`` — the filter's misalignment, transverse scale and bias over
  the concatenated captures with their ±3σ sleeve (an unknown the data do not
  determine is named as held, with the reason);
- ``rmse2.png`` — RMSE per capture and axis, raw and corrected by the least-squares
  fit, in the water frame of :func:`emlogd.offline.twoaxis.score`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calib.models import FloatArray, Params
from calib.twoaxis import fit_current_two_axis, water_velocity
from emlogd.offline import report as figures
from emlogd.offline.twoaxis import (
    TwoAxisRecording,
    TwoAxisResult,
    TwoAxisRow,
    calibrate_two_axis,
    evaluate_two_axis,
)
from emlogd.pipeline.twoaxis_learn import CURRENT_KNOT_S

_TRACE_LABELS = (
    ("misalign_deg", "α (°)"),
    ("m_t", "m_t (-)"),
    ("b_t", "b_t (m/s)"),
)
"""The filter's traced unknowns (:data:`calib.twoaxis_kf.TRACE_NAMES`) as plotted."""


@dataclass(frozen=True, slots=True)
class TwoAxisReport:
    """What ``report --axes 2`` wrote and found.

    Attributes:
        ls: the least-squares calibration of every capture together.
        kf: the filter's.
        rows: the least-squares parameters applied to each capture.
        figures: the PNG files written.
    """

    ls: TwoAxisResult
    kf: TwoAxisResult
    rows: tuple[TwoAxisRow, ...]
    figures: tuple[Path, ...]

    def to_dict(self) -> dict[str, object]:
        """JSON keys (README: ``report --axes 2 --json``): the least-squares
        calibration as ``calibrate --axes 2 --json`` gives it, the filter's under
        ``kf``, each capture's scores under ``rows`` and the figures' paths."""
        return {
            **self.ls.to_dict(),
            "kf": self.kf.fit.to_dict(),
            "rows": [r.to_dict() for r in self.rows],
            "figures": [str(p) for p in self.figures],
        }


def report_two_axis(
    recs: Sequence[TwoAxisRecording],
    model: str,
    lag_s: float,
    outdir: str | Path,
    *,
    lag_source: str = "given",
    reference: str = "dvl",
    one_axis: Params | None = None,
) -> TwoAxisReport:
    """Calibrate both axes by least squares and by the filter, and write the figures;
    ``one_axis`` the one-axis calibration of the same readings, the forward speed
    weighed against it (:func:`emlogd.offline.twoaxis.forward_rule`).

    Raises:
        OfflineError: matplotlib missing, no aligned sample, a bad model.
    """
    plt = figures._pyplot()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    ls, kf = (
        calibrate_two_axis(
            recs, model, m, lag_s, lag_source=lag_source, reference=reference, one_axis=one_axis
        )
        for m in ("ls", "kf")
    )
    rows = tuple(evaluate_two_axis(recs, ls.fit.params, lag_s, ls.rule))
    lag_txt = f"lag {lag_s:.2f} s ({lag_source})"
    written = [p for r in recs if (p := _speeds(plt, out, r, ls, lag_txt)) is not None]
    written.append(_convergence(plt, out, kf))
    written.append(_rmse(plt, out, recs, rows, ls))
    return TwoAxisReport(ls, kf, rows, tuple(written))


def _speeds(
    plt: Any, out: Path, rec: TwoAxisRecording, res: TwoAxisResult, lag_txt: str
) -> Path | None:
    """The forward and athwart speeds over the first window of one capture."""
    a = rec.aligned(res.lag_s)
    if len(a) == 0:
        return None
    params = res.fit.params
    cur = fit_current_two_axis(params, a.series(), t_s=a.t, current_knot_s=CURRENT_KNOT_S)
    u, w = water_velocity(a.ref_fwd, a.ref_stb, a.heading, cur)
    cu, cw = params.correct(a.raw_l, a.raw_t)
    tt = a.t - a.t[0]
    sel = tt <= figures.WINDOW_S
    total = float(tt[-1])
    window = (
        f"the whole capture, {total:.0f} s"
        if total <= figures.WINDOW_S
        else f"window 0–{figures.WINDOW_S:.0f} s of {total:.0f} s"
    )
    fig, axes = plt.subplots(2, 1, figsize=(10, 6.4), sharex=True)
    for ax, raw, cal, ref, what in (
        (axes[0], a.raw_l, cu, u, "forward"),
        (axes[1], a.raw_t, cw, w, "athwart (+ starboard)"),
    ):
        ax.plot(tt[sel], raw[sel], lw=0.8, label=f"{rec.uut} raw")
        ax.plot(tt[sel], cal[sel], lw=0.8, label=f"corrected (LS-{params.model}, two axes)")
        ax.plot(tt[sel], ref[sel], lw=0.8, label=f"{res.reference} less the current")
        ax.set_ylabel(f"{what} (m/s)")
        ax.grid(True, alpha=0.3)
        ax.legend(**figures._OUTSIDE)
    axes[-1].set_xlabel("time since start of capture (s)")
    axes[0].set_title(
        f"{rec.name} ({window}): {rec.uut} vs {res.reference} (bottom), α "
        f"{params.misalign_deg:+.2f}°, {lag_txt}"
    )
    return figures._save(fig, out / f"speed2_{rec.name}.png", plt)


def _convergence(plt: Any, out: Path, kf: TwoAxisResult) -> Path:
    """The filter's α, m_t and b_t over the samples with their ±3σ sleeve."""
    fit = kf.fit
    trace = fit.trace if fit.trace is not None else np.full((fit.n_samples, 6), math.nan)
    k = len(_TRACE_LABELS)
    fig, axes = plt.subplots(k, 1, figsize=(10, 2.6 * k), sharex=True)
    samples = np.arange(trace.shape[0])
    held = {v.unknown: v.reason for v in fit.ident.verdicts if not v.determined}
    for c, (ax, (key, label)) in enumerate(zip(axes, _TRACE_LABELS, strict=True)):
        est, sd = trace[:, c], trace[:, k + c]
        if key == "misalign_deg":
            est, sd = np.degrees(est), np.degrees(sd)
        unknown = "alpha" if key == "misalign_deg" else key
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        if unknown in held or not np.any(np.isfinite(est)):
            value = fit.params.as_dict()[key]
            ax.axhline(value, lw=0.9, label=f"held at {value:+.4g}")
            ax.text(0.01, 0.5, _wrap(held.get(unknown, "")), transform=ax.transAxes, fontsize=8)
            ax.legend(**figures._OUTSIDE)
            continue
        ax.plot(samples, est, lw=0.9, label=f"{key} estimate")
        ax.fill_between(samples, est - 3 * sd, est + 3 * sd, alpha=0.3, label="±3σ")
        ax.legend(**figures._OUTSIDE)
        _ylim(ax, est, sd)
    axes[-1].set_xlabel("sample (captures back to back)")
    axes[0].set_title(
        f"KF-{fit.params.model} two axes + current: {kf.uut} vs {kf.reference} (bottom)"
    )
    return figures._save(fig, out / "misalignment.png", plt)


def _wrap(text: str, width: int = 90) -> str:
    words, lines, line = text.split(), [], ""
    for word in words:
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    return "\n".join([*lines, line]) if line else "\n".join(lines)


def _ylim(ax: Any, est: FloatArray, sd: FloatArray) -> None:
    """Limits that show the settled estimate and its sleeve, not the first samples'."""
    tail = slice(len(est) // 10, None)
    lo = np.nanmin(est[tail] - 3 * sd[tail]) if len(est) > 10 else math.nan
    hi = np.nanmax(est[tail] + 3 * sd[tail]) if len(est) > 10 else math.nan
    if math.isfinite(lo) and math.isfinite(hi):
        pad = 0.1 * max(hi - lo, 1e-6)
        ax.set_ylim(float(lo) - pad, float(hi) + pad)


def _rmse(
    plt: Any,
    out: Path,
    recs: Sequence[TwoAxisRecording],
    rows: Sequence[TwoAxisRow],
    ls: TwoAxisResult,
) -> Path:
    """Bars: RMSE per capture and axis, raw and corrected."""
    names = [r.name for r in recs]
    x = np.arange(len(names))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=False)
    for ax, axis, raw_key, cal_key in (
        (axes[0], "forward", "rmse_l_raw", "rmse_l_cal"),
        (axes[1], "athwart", "rmse_t_raw", "rmse_t_cal"),
    ):
        raw = [getattr(r.scores, raw_key) for r in rows]
        cal = [getattr(r.scores, cal_key) for r in rows]
        ax.bar(x - 0.2, raw, 0.4, label="raw")
        ax.bar(x + 0.2, cal, 0.4, label=f"corrected (LS-{ls.fit.params.model})")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(f"{axis} RMSE (m/s)")
        ax.set_title(f"{axis}, in the water frame")
        ax.grid(True, axis="y", alpha=0.3)
    axes[1].legend(**figures._OUTSIDE)
    fig.suptitle(
        f"Two axes, α {ls.fit.misalign_deg:+.2f}°: RMSE per capture against "
        f"{ls.reference} less each capture's fitted current",
        fontsize=10,
    )
    return figures._save(fig, out / "rmse2.png", plt)
