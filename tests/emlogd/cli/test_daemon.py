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


def test_demo_with_a_relative_workdir(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """demo --workdir with a relative path runs (the daemon runs inside it) and keeps its state."""
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--workdir", "demo_wd", "--speed", "50"]) == 0
    captured = capsys.readouterr()
    assert "better" in captured.out and captured.err == ""
    assert (tmp_path / "demo_wd" / "state" / "state.yaml").exists()


@pytest.mark.parametrize("speed", ["0", "-2", "100"])
def test_demo_rejects_a_bad_speed(capsys: pytest.CaptureFixture[str], speed: str) -> None:
    """demo --speed outside 1..50 is a usage error: exit 2, one line on stderr."""
    assert main(["demo", "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--speed" in err
