"""Aligned text tables for the CLI (the paper's Table II and Table III layouts).

Pure formatting: lists of rows in, a string out. Non-finite numbers print as ``-``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from calib.crossval import CrossValResult


def fmt(x: float | None, spec: str = ".3f") -> str:
    """A number, or ``-`` when missing or not finite."""
    if x is None or not math.isfinite(x):
        return "-"
    return format(x, spec)


def render(header: Sequence[str], rows: Sequence[Sequence[str]], *, left: int = 1) -> str:
    """An aligned table: the first ``left`` columns left-aligned, the rest right-aligned."""
    cols = len(header)
    widths = [len(h) for h in header]
    for row in rows:
        if len(row) != cols:
            raise ValueError(f"row has {len(row)} cells, header has {cols}")
        widths = [max(w, len(c)) for w, c in zip(widths, row, strict=True)]

    def line(cells: Sequence[str]) -> str:
        out = [
            c.ljust(w) if i < left else c.rjust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ]
        return "  ".join(out).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(header), rule, *(line(r) for r in rows)]) + "\n"


def table3(result: CrossValResult, estimator: str) -> str:
    """Table III layout for one estimator: training rows × test columns, then overall.

    Each cell is the calibrated RMSE in m/s with the improvement % in brackets; the
    in-sample diagonal is marked ``*``. The overall column pools every test segment
    but the training one.
    """
    names = [s.name for s in result.segments]
    header = ["train \\ test", *names, "overall"]
    rows = []
    overall = {r.train: r for r in result.overall(estimator)}
    for train_row in result.matrix(estimator):
        train = train_row[0].train
        cells = [train]
        for e in train_row:
            mark = "*" if e.in_sample else ""
            cells.append(f"{fmt(e.rmse_cal_mps)} ({fmt(e.improvement_pct, '.0f')}%){mark}")
        o = overall[train]
        cells.append(f"{fmt(o.rmse_cal_mps)} ({fmt(o.improvement_pct, '.0f')}%)")
        rows.append(cells)
    raw = ["raw RMSE", *(fmt(s.rmse_raw_mps) for s in result.segments), ""]
    return f"{estimator}: calibrated RMSE m/s (improvement)\n" + render(header, [*rows, raw])


def table2(result: CrossValResult, train: str, test: str) -> str:
    """Table II layout: every estimator trained on ``train``, evaluated on ``test``."""
    rows = []
    for est in result.estimators:
        e = result.evaluation(est, train, test)
        p = result.params(est, train)
        params = ", ".join(f"{k}={v:+.4f}" for k, v in p.as_dict().items())
        rows.append(
            [est, params, fmt(e.rmse_raw_mps), fmt(e.rmse_cal_mps), fmt(e.improvement_pct, ".1f")]
        )
    header = ["estimator", "parameters", "RMSE raw", "RMSE cal", "improv. %"]
    return f"trained on {train}, tested on {test}\n" + render(header, rows, left=2)
