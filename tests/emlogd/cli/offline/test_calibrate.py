"""`emlogd calibrate` through main(argv): the lag line, the filter's reading noise."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main


def test_a_lag_not_measured_is_said_once_on_stderr(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path]
) -> None:
    """calibrate without --lag on a run the lag search cannot read (the straight): 0 s
    is used, the lag line says fallback, and stderr says why, once."""
    straight = str(trial_files["straight"])
    assert main(["calibrate", straight, "--uut", "emlog1", "--ref", "dvl"]) == 0
    out, err = capsys.readouterr()
    assert "lag          0.00 s (fallback" in out
    assert err.count("emlogd calibrate: warning: lag not measured") == 1
    assert "warning" not in out


def test_r_raw_sets_the_filters_reading_noise(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path]
) -> None:
    """calibrate --method kf --r-raw SIGMA: the filter weighs the innovations with SIGMA, so a
    reading noise 4 times the default's divides the NIS mean by more than 4 (sample by
    sample against a DVL the configured noises are kept: the noise scale is 1)."""
    base = ["calibrate", str(trial_files["figure-8"]), "--uut", "emlog1", "--ref", "dvl"]
    base += ["--lag", "3.3", "--method", "kf", "--current", "--json"]
    nis = {}
    for r_raw in (None, "0.2"):
        assert main(base + (["--r-raw", r_raw] if r_raw else [])) == 0
        doc = json.loads(capsys.readouterr().out)
        nis[r_raw] = doc["nis_mean"]
        assert doc["noise_scale"] == pytest.approx(1.0, abs=0.05)  # one step per re-acquisition
    assert nis["0.2"] < nis[None] / 4, nis
