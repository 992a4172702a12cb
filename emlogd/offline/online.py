"""The daemon's online calibration run over recordings, and its trace.

``emlogd calibrate --method kf`` feeds the recorded samples of each capture, in the
order they arrived, to the daemon's own :class:`~emlogd.pipeline.uut.UutCalibration`,
so that it and ``emlogd replay`` give the same estimate for the same lag; ``--trace``
writes one CSV row per learnt-from reading (:data:`TRACE_COLUMNS`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from emlogd.offline.dataset import Recording
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import UutCalibration


def run_online(
    recs: Sequence[Recording],
    settings: UutSettings,
    lag_s: float,
    *,
    trace: Callable[[dict[str, object]], None] | None = None,
) -> UutCalibration:
    """The daemon's online calibration fed the recorded samples of each capture in order.

    The captures run back to back through one filter (the state carries over), the
    reference, heading and readings merged in time order as they arrived. ``trace``
    receives one row per learnt-from reading (``calibrate --trace``). The filter's
    noises are matched to the innovations' covariance (an honest σ and NIS; the daemon
    scales them by the slowly adapted noise scale its offers rest on), and a change the
    supervisor's detector saw withdraws the applied calibration without re-opening the
    learner (one model over the recordings; the daemon re-opens it so that its next
    offer rests on readings after the change). The lag is the lag report's, not checked
    again (:mod:`emlogd.pipeline.lagcheck` is the daemon's and replay's).
    """
    s = dataclasses.replace(settings, lag_s=lag_s, learn=True)
    heading = SampleRing(4096, 2.0, angular=True, cadence=True)
    cal = UutCalibration(
        s,
        None,
        lambda t: _heading(heading, t),
        lambda t, k, d: None,
        matched_noise=True,
        reopen_on_change=False,
        check_lag=False,
    )
    cal.tracer = trace
    for r in recs:
        heading.clear()
        events = sorted(
            [(float(t), 0, i) for i, t in enumerate(r.t_ref)]
            + [(float(t), 1, i) for i, t in enumerate(r.t_read)]
        )
        for t, kind, i in events:
            if kind == 0:
                h = float(r.heading[i])
                heading.add(t, h if math.isfinite(h) else None, math.isfinite(h))
                ok = bool(r.ok_ref[i])
                v = float(r.v_ref[i])
                cal.add_reference(t, v if ok else None, ok)
            else:
                cal.add_reading(t, float(r.raw[i]))
            cal.drain(t)
        cal.drain(r.t_end if math.isfinite(r.t_end) else 0.0, final=True)
    return cal


def _heading(ring: SampleRing, t: float) -> float | None:
    h = ring.at(t)
    return ring.nearest(t, 0.6) if h is None else h


TRACE_COLUMNS = (
    "t", "raw_mps", "ref_mps", "heading_deg", "emitted_mps", "corrected_mps",
    "a", "std_a", "m", "std_m", "b", "std_b",
    "current_north_mps", "std_current_north_mps", "current_east_mps", "std_current_east_mps",
    "current_determined", "nis", "state", "learning",
)  # fmt: skip
"""The columns of ``calibrate --trace`` (README)."""


class TraceWriter:
    """A CSV file of trace rows (no-op without a path)."""

    def __init__(self, path: str | Path | None) -> None:
        self.path = path
        self._f: Any = None
        self._w: Any = None

    def __enter__(self) -> TraceWriter:
        if self.path is not None:
            import csv

            self._f = open(self.path, "w", newline="", encoding="utf-8")
            self._w = csv.writer(self._f)
            self._w.writerow(TRACE_COLUMNS)
        return self

    def row(self, r: dict[str, object]) -> None:
        self._w.writerow(
            [
                "" if r.get(c) is None else f"{r[c]:.3f}" if c == "t" else _cell(r[c])
                for c in TRACE_COLUMNS
            ]
        )

    def __exit__(self, *exc: object) -> None:
        if self._f is not None:
            self._f.close()


def _cell(x: object) -> object:
    if isinstance(x, float):
        return f"{x:.6g}" if math.isfinite(x) else ""
    if isinstance(x, bool):
        return int(x)
    return x
