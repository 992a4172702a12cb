"""Report figures (needs matplotlib, part of the test extra)."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.offline.jobs import load_captures
from emlogd.pipeline.core import UutSettings

pytest.importorskip("matplotlib")

from emlogd.offline.report import report


def test_report_writes_the_figures(trial_files: dict[str, Path], tmp_path: Path) -> None:
    settings = UutSettings(port="emlog1", reference_port="dvl")
    recs = load_captures([trial_files["figure-8"], trial_files["straight"]], settings)
    paths = report(recs, settings, tmp_path / "fig", lag=3.3, workers=1)
    names = sorted(p.name for p in paths)
    assert names == sorted(
        [
            "speed_2-figure8.png",
            "speed_3-straight.png",
            "convergence.png",
            "nis.png",
            "trajectory.png",
            "crossval.png",
        ]
    )
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert p.stat().st_size > 10_000
