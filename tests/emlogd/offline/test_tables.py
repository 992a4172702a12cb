"""Text tables: alignment, missing numbers, the paper's Table II/III layouts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.crossval import cross_validate
from calib.models import Params, forward_array
from emlogd.offline.tables import fmt, render, table2, table3


def test_fmt_prints_dash_for_missing() -> None:
    """fmt prints '-' for None, NaN and infinity, and otherwise the number in the given format
    (three decimals by default)."""
    assert fmt(None) == "-"
    assert fmt(math.nan) == "-"
    assert fmt(math.inf) == "-"
    assert fmt(1.23456) == "1.235"
    assert fmt(12.5, ".0f") == "12"


def test_render_aligns_columns() -> None:
    """render left-aligns the first column and right-aligns the others to their widest cell, and
    refuses a row with the wrong number of cells."""
    text = render(["name", "x"], [["a", "1.0"], ["longer", "10.25"]])
    lines = text.splitlines()
    assert lines[0] == "name        x"
    assert lines[2] == "a         1.0"
    assert lines[3] == "longer  10.25"
    with pytest.raises(ValueError, match="cells"):
        render(["a", "b"], [["only one"]])


def _result() -> object:
    rng = np.random.default_rng(3)
    truth = Params("EM3", m=0.1, b_mps=0.2)
    segs = []
    for name, period in (("figure8", 45.0), ("straight", 1e9), ("circles", 60.0)):
        t = np.arange(600.0)
        v = 1.6 + (0.4 * np.sin(2 * np.pi * t / period) if period < 1e8 else 0.0 * t)
        raw = forward_array(truth, v) + rng.normal(0, 0.03, t.size)
        segs.append((name, t, raw, v + rng.normal(0, 0.01, t.size)))
    return cross_validate(segs, ["LS-EM3", "KF-EM3"])


def test_table3_and_table2_layouts() -> None:
    """Table III has the train/test header, one row per segment with the in-sample cell starred and
    a raw RMSE line, and Table II names its pair and has one row per estimator with its
    parameters."""
    res = _result()
    t3 = table3(res, "LS-EM3")  # type: ignore[arg-type]
    lines = t3.splitlines()
    assert lines[0].startswith("LS-EM3")
    assert lines[1].split() == ["train", "\\", "test", "figure8", "straight", "circles", "overall"]
    body = lines[3:6]
    assert [row.split()[0] for row in body] == ["figure8", "straight", "circles"]
    assert body[0].count("*") == 1  # the in-sample diagonal is marked
    assert lines[6].startswith("raw RMSE")
    t2 = table2(res, "figure8", "straight")  # type: ignore[arg-type]
    assert "trained on figure8, tested on straight" in t2
    rows = t2.splitlines()[3:]
    assert [r.split()[0] for r in rows] == ["LS-EM3", "KF-EM3"]
    assert "m=+0.1" in rows[0]
