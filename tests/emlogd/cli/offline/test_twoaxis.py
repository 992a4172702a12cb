"""`--axes 2` of calibrate, evaluate and crossval through main(argv)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main
from emlogd.offline.simulate import EMLOG1, EMLOG2, SimulationResult, simulate, with_sensor


@pytest.fixture(scope="module")
def misaligned(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """A fifth of the trial, emlog2 turned 3° to starboard (its noise 0.01 m/s)."""
    sensor = with_sensor(EMLOG2, {"misalign": 3.0, "mt": -0.08, "bt": 0.04, "noise": 0.01})
    return simulate(tmp_path_factory.mktemp("cli2"), seed=3, scale=0.2, emlogs=(EMLOG1, sensor))


def _base(trial: SimulationResult, command: str, *files: int) -> list[str]:
    return [command, *(str(trial.files[i]) for i in files), "--uut", "emlog2", "--ref", "dvl"]


def test_calibrate_evaluate_two_axes(
    misaligned: SimulationResult, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """calibrate --axes 2 on the figure-8: the JSON carries misalign_deg ± σ, the
    transverse parameters and RMSE per axis; the saved file evaluated against the
    truth scores both axes of every capture."""
    saved = tmp_path / "two.yaml"
    argv = [*_base(misaligned, "calibrate", 1), "--axes", "2", "--lag", "0.46", "--json"]
    assert main([*argv, "--save", str(saved)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["axes"] == 2
    assert doc["misalign_deg"] == pytest.approx(3.0, abs=0.3)
    assert doc["misalign_std_deg"] > 0.0
    assert {"m_t", "b_t"} <= set(doc["params"])
    assert doc["scores"]["rmse_t_cal"] < doc["scores"]["rmse_t_raw"]
    argv = ["evaluate", *(str(f) for f in misaligned.files), "--params", str(saved)]
    assert main([*argv, "--axes", "2", "--truth", str(misaligned.outdir), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert len(rows) == 5
    for r in rows:
        t = r["truth"]
        assert t["rmse_t_cal"] <= 1.1 * t["rmse_t_floor"], r["capture"]
    assert main([*argv, "--axes", "2"]) == 0
    assert "misalignment +" in capsys.readouterr().out


def test_crossval_two_axes(
    misaligned: SimulationResult, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [*_base(misaligned, "crossval", 1, 2), "--axes", "2", "--lag", "0.46"]
    assert main([*argv, "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [(r["train"], r["test"]) for r in rows] == [
        ("2-figure8", "3-straight"),
        ("3-straight", "2-figure8"),
    ]
    assert rows[1]["misalign_std_deg"] is None and "misalignment" in rows[1]["reason"]
    assert main(argv) == 0
    assert "alpha°" in capsys.readouterr().out


def test_two_axes_need_the_bottom_track(
    misaligned: SimulationResult, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [*_base(misaligned, "calibrate", 1), "--axes", "2", "--lag", "0.5"]
    assert main([*argv, "--ref-field", "gnss"]) != 0
    assert "--ref-field bottom" in capsys.readouterr().err
