"""The figures of a two-axis calibration (needs matplotlib, part of the test extra)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("matplotlib")

from emlogd.offline import report as report_module
from emlogd.offline.twoaxis import record_two_axis
from emlogd.offline.twoaxis_report import _wrap, report_two_axis


def test_straight_run_names_the_held_misalignment(
    trial_files: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On the straight run α is refused: the convergence figure draws it held, with the
    reason, instead of a sleeve; the speeds and the RMSE figures are written and the
    JSON carries both fits."""
    texts: dict[str, list[str]] = {}
    save = report_module._save

    def keep(fig: Any, path: Path, plt: Any) -> Path:
        texts[path.name] = [t.get_text() for ax in fig.axes for t in ax.texts]
        return save(fig, path, plt)

    monkeypatch.setattr(report_module, "_save", keep)
    rec = record_two_axis(trial_files["straight"], "emlog2", "dvl")
    rep = report_two_axis([rec], "EM3", 0.46, tmp_path)
    assert [p.name for p in rep.figures] == [
        "speed2_3-straight.png",
        "misalignment.png",
        "rmse2.png",
    ]
    assert all(p.stat().st_size > 0 for p in rep.figures)
    assert "alpha" in rep.ls.fit.ident.unidentifiable
    held = " ".join(texts["misalignment.png"]).replace("\n", " ")
    assert "misalignment not separable" in held
    doc = rep.to_dict()
    assert doc["misalign_std_deg"] is None and rep.kf.fit.misalign_std_deg is None
    rows = doc["rows"]
    assert isinstance(rows, list) and len(rows) == 1
    assert doc["figures"] == [str(p) for p in rep.figures]


def test_wrap_breaks_long_reasons() -> None:
    assert _wrap("a b c", width=3) == "a b\nc"
    assert _wrap("") == ""
