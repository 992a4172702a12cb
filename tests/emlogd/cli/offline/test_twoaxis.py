"""`--axes 2` of calibrate, evaluate, crossval and report through main(argv)."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
from pathlib import Path
from typing import Any

import pytest

from emlogd.cli import main
from emlogd.offline.simulate import SimulationResult


@pytest.fixture(scope="module")
def misaligned(misaligned_trial: SimulationResult) -> SimulationResult:
    """A fifth of the trial, emlog2 turned 3° to starboard (its noise 0.01 m/s: the
    session's ``misaligned_trial``)."""
    return misaligned_trial


def _base(trial: SimulationResult, command: str, *files: int) -> list[str]:
    return [command, *(str(trial.files[i]) for i in files), "--uut", "emlog2", "--ref", "dvl"]


@pytest.fixture(scope="module")
def calibrated(
    misaligned: SimulationResult, tmp_path_factory: pytest.TempPathFactory
) -> tuple[dict[str, Any], Path]:
    """``calibrate --axes 2 --json --save`` on the figure-8, run once: its JSON and file."""
    saved = tmp_path_factory.mktemp("cli2cal") / "two.yaml"
    argv = [*_base(misaligned, "calibrate", 1), "--axes", "2", "--lag", "0.46", "--json"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*argv, "--save", str(saved)]) == 0
    return json.loads(buf.getvalue()), saved


def test_calibrate_two_axes_json(calibrated: tuple[dict[str, Any], Path]) -> None:
    """calibrate --axes 2 on the figure-8: the JSON carries misalign_deg ± σ, the
    transverse parameters and RMSE per axis."""
    doc, _ = calibrated
    assert doc["axes"] == 2
    assert doc["misalign_deg"] == pytest.approx(3.0, abs=0.3)
    assert doc["misalign_std_deg"] > 0.0
    assert {"m_t", "b_t"} <= set(doc["params"])
    assert doc["scores"]["rmse_t_cal"] < doc["scores"]["rmse_t_raw"]


def test_evaluate_two_axes_against_the_truth(
    misaligned: SimulationResult,
    calibrated: tuple[dict[str, Any], Path],
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The saved file evaluated against the truth scores both axes of each capture
    (the figure-8 and the straight run; every trajectory: tests/emlogd/offline)."""
    _, saved = calibrated
    argv = ["evaluate", *(str(misaligned.files[i]) for i in (1, 2)), "--params", str(saved)]
    assert main([*argv, "--axes", "2", "--truth", str(misaligned.outdir), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert len(rows) == 2
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


@pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None, reason="needs matplotlib")
def test_report_two_axes(
    misaligned: SimulationResult, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """report --axes 2: the figures (each axis's speeds, the filter's α, m_t and b_t
    with their sleeve, the RMSE per axis), α ± σ, m_t, b_t and the RMSE per axis of
    least squares and the filter; --json carries misalign_deg and the transverse
    parameters of both."""
    argv = [*_base(misaligned, "report", 1), "--axes", "2", "--lag", "0.46"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    names = {Path(line).name for line in out.splitlines() if line.endswith(".png")}
    assert names == {"speed2_2-figure8.png", "misalignment.png", "rmse2.png"}
    assert all((tmp_path / "a" / n).stat().st_size > 0 for n in names)
    assert "LS-EM3 misalignment +" in out and "KF-EM3 misalignment +" in out
    assert "transverse scale m_t" in out and "RMSE forward" in out
    assert main([*argv, "--out", str(tmp_path / "b"), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["axes"] == 2 and doc["misalign_deg"] == pytest.approx(3.0, abs=0.3)
    assert doc["kf"]["misalign_deg"] == pytest.approx(3.0, abs=0.3)
    assert {"m_t", "b_t"} <= set(doc["params"]) and {"m_t", "b_t"} <= set(doc["kf"]["params"])
    assert doc["rows"][0]["rmse_t_cal"] < doc["rows"][0]["rmse_t_raw"]
    assert len(doc["figures"]) == 3
    one_axis = [*_base(misaligned, "report", 1), "--lag", "0.46", "--out", str(tmp_path / "c")]
    assert main([*one_axis, "--json"]) != 0
    assert "--json is for --axes 2" in capsys.readouterr().err


def test_two_axes_need_the_bottom_track(
    misaligned: SimulationResult, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [*_base(misaligned, "calibrate", 1), "--axes", "2", "--lag", "0.5"]
    assert main([*argv, "--ref-field", "gnss"]) != 0
    assert "--ref-field bottom" in capsys.readouterr().err


@pytest.mark.parametrize("axes", ["0", "3", "2.5"])
def test_axes_takes_the_values_of_the_config_key(
    axes: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """--axes is checked like the config key ``axes`` (integer in [1, 2]): anything else
    is a usage error naming the key's range, before any file is read."""
    assert main(["calibrate", "x.cap", "--uut", "emlog2", "--ref", "dvl", "--axes", axes]) == 2
    assert "config key axes: integer in [1, 2]" in capsys.readouterr().err
