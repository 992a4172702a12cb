"""`emlogd simulate` through main(argv)."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.cli import main


def test_simulate_command(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """simulate writes the trial captures and names truth.yaml; --scale 0 exits 2."""
    assert main(["simulate", str(tmp_path / "sim"), "--scale", "0.01", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "truth.yaml" in out and (tmp_path / "sim" / "2-figure8.cap").exists()
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0"]) == 2
