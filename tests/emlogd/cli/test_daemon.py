"""run, check-config and the control commands through main(argv)."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.cli import main


def test_check_config(capsys: pytest.CaptureFixture[str]) -> None:
    example = Path(__file__).resolve().parents[3] / "examples" / "emlogd.yaml"
    assert main(["check-config", str(example)]) == 0
    assert "ok" in capsys.readouterr().out


def test_control_commands_without_daemon(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["status", "--socket", str(tmp_path / "none.sock")]) == 1
    assert "is emlogd running" in capsys.readouterr().err
