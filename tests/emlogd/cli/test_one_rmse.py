"""One raw and one calibrated RMSE per capture and lag, whichever command prints it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main

ROOT = Path(__file__).resolve().parents[3]
CAPTURES = ROOT / "examples" / "captures"
TRANSIT = str(CAPTURES / "1-transit.cap.gz")
FIGURE8 = str(CAPTURES / "2-figure8.cap.gz")
PAIR = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]


@pytest.mark.parametrize("frame", [[], ["--current"]], ids=["ground", "water"])
def test_calibrate_evaluate_and_crossval_agree_on_the_raw_and_calibrated_rmse(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, frame: list[str]
) -> None:
    """calibrate's raw and calibrated RMSE on the transit, evaluate's with the saved
    file, and crossval's footer (per segment) and cells (LS-EM3 trained and tested on
    the transit) are one number each (calib.metrics.water_scores)."""
    params = tmp_path / "p.yaml"
    argv = ["calibrate", TRANSIT, *PAIR, *frame, "--save", str(params), "--json"]
    assert main(argv) == 0
    cal = json.loads(capsys.readouterr().out)
    assert main(["evaluate", TRANSIT, "--params", str(params), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)["captures"][0]
    argv = ["crossval", TRANSIT, FIGURE8, *PAIR, *frame, "--json", "--workers", "1"]
    assert main(argv) == 0
    cv = json.loads(capsys.readouterr().out)
    footer = next(s for s in cv["segments"] if s["name"] == "1-transit")
    cells = [e for e in cv["evaluations"] if e["test"] == "1-transit"]
    cell = next(e for e in cells if e["estimator"] == "LS-EM3" and e["train"] == "1-transit")
    raw = cal["rmse_raw"]
    assert ev["rmse_raw"] == pytest.approx(raw, rel=1e-9)
    assert footer["rmse_raw_mps"] == pytest.approx(raw, rel=1e-9)
    assert footer["n_samples"] == cell["n_samples"] == ev["n_samples"]
    assert all(e["rmse_raw_mps"] == pytest.approx(raw, rel=1e-9) for e in cells)
    assert ev["rmse_cal"] == pytest.approx(cal["rmse_cal"], rel=1e-9)
    assert cell["rmse_cal_mps"] == pytest.approx(cal["rmse_cal"], rel=1e-6)
