"""`emlogd calibrate` through main(argv): the lag line, the filter's reading noise."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivers.framing import nmea_checksum
from drivers.io.capture import CaptureReader, CaptureWriter
from drivers.records import KNOT_MPS
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


def _scaled_log(src: Path, dst: Path, port: str, factor: float) -> None:
    """``src`` with the speed of ``port``'s VHW (knots and km/h) times ``factor``."""
    reader = CaptureReader(src)
    with CaptureWriter(dst, reader.ports) as w:
        for r in reader:
            line = r.payload
            if r.port == port and line[3:6] == "VHW":
                f = line.split("*")[0].split(",")
                for i in (5, 7):
                    if f[i]:
                        f[i] = f"{float(f[i]) * factor:.2f}"
                body = ",".join(f)
                line = f"{body}*{nmea_checksum(body[1:].encode()):02X}"
            if r.binary:
                w.write_chunk(r.t, r.port, r.data)
            else:
                w.write_line(r.t, r.port, line.encode())


@pytest.mark.parametrize("factor", [1.0 / KNOT_MPS, KNOT_MPS])
def test_a_speed_in_the_wrong_unit_is_said(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path, factor: float
) -> None:
    """The EMlog's speed times 1.944 (knots taken for m/s) or 0.514 (the reverse): the fit
    is printed and stderr says the log reads that many times the reference, a unit
    mislabelled (the simulated log reads 27 % high: 2.48 and 0.65 times), and that the
    daemon refuses the fit. Both fits were printed without a word. The trial's own capture
    draws no such warning."""
    base = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main(["calibrate", str(trial_files["figure-8"]), *base]) == 0
    assert "warning" not in capsys.readouterr().err
    cap = tmp_path / "scaled.cap"
    _scaled_log(trial_files["figure-8"], cap, "emlog1", factor)
    assert main(["calibrate", str(cap), *base]) == 0
    err = capsys.readouterr().err
    assert "taken for m/s, or the reverse?" in err, err
    assert "the daemon refuses such a calibration" in err, err
