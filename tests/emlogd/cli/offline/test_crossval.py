"""`emlogd crossval` through main(argv), after calibrate and evaluate on the same trial."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main


def test_calibrate_evaluate_crossval(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """calibrate --json gives every documented key and > 60 % on the figure-8, the saved
    parameters improve the straight by > 50 %, the straight alone is not identifiable, and
    crossval writes 8 x 25 CSV rows."""
    fig8, straight = str(trial_files["figure-8"]), str(trial_files["straight"])
    params = tmp_path / "p.yaml"
    rc = main(
        [
            "calibrate",
            fig8,
            "--uut",
            "emlog1",
            "--ref",
            "dvl",
            "--lag",
            "3.3",
            "--save",
            str(params),
            "--json",
        ]
    )
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    for key in ("model", "method", "params", "stderr", "lag_s", "rmse_raw", "rmse_cal",
                "improvement_pct", "identifiable", "condition_number"):  # fmt: skip
        assert key in doc
    assert doc["improvement_pct"] > 60 and doc["identifiable"] is True
    assert main(["evaluate", straight, "--params", str(params), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["captures"][0]["improvement_pct"] > 50
    assert main(["calibrate", straight, "--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]) == 0
    assert "identifiable NO" in capsys.readouterr().out
    csv_path = tmp_path / "cv.csv"
    files = [str(p) for p in trial_files.values()]
    assert main(["crossval", *files, "--uut", "emlog1", "--ref", "dvl", "--lag", "3.3",
                 "--csv", str(csv_path), "--workers", "1"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "LS-EM3: calibrated RMSE" in out and "trained on 2-figure8, tested on 3-straight" in out
    assert "160 out-of-sample evaluations" in out
    assert len(csv_path.read_text().splitlines()) == 1 + 8 * 25


def test_a_capture_without_samples_is_named(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """A capture of its header only beside a trial's: one error line naming it, exit 1.
    It ended ``crossval`` (and ``report``) with ``internal error: DataError: segment
    'empty': need ≥ 2 finite, non-decreasing times``."""
    empty = tmp_path / "empty.cap"
    empty.write_text("# emlogd capture v1\n# port emlog1 nmea0183\n# port dvl pd6\n")
    argv = ["crossval", str(empty), str(trial_files["straight"]), "--uut", "emlog1"]
    assert main([*argv, "--ref", "dvl", "--lag", "3.3"]) == 1
    err = capsys.readouterr().err
    assert f"emlogd crossval: error: {empty}: fewer than 2 emlog1 samples" in err, err
    assert "internal error" not in err
