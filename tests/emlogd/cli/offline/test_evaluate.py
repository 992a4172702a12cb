"""`emlogd evaluate` (and the calibration it applies) through main(argv): the IMO verdict."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main
from emlogd.offline.simulate import SimulationResult


def test_the_imo_verdict_in_calibrate_and_evaluate(
    capsys: pytest.CaptureFixture[str], trial: SimulationResult, tmp_path: Path
) -> None:
    """calibrate and evaluate report the IMO A.824(19) verdict raw and calibrated, in JSON
    and text, from calib.metrics.water_imo; evaluate --truth adds it against the truth."""
    fig8 = str(trial.files[1])
    params = tmp_path / "p.yaml"
    argv = ["calibrate", fig8, "--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main([*argv, "--save", str(params), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    imo = doc["imo"]
    assert set(imo) == {"raw", "cal"}
    for v in imo.values():
        assert set(v) == {"n", "within", "fraction", "meets"}
        assert v["n"] == doc["n_samples"] and v["fraction"] == v["within"] / v["n"]
    assert imo["cal"]["fraction"] > imo["raw"]["fraction"]
    assert main(argv) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("IMO A.824"))
    cal_pct = (
        f"{100.0 * imo['cal']['fraction']:.1f} % {'meets' if imo['cal']['meets'] else 'fails'}"
    )
    assert f"cal {cal_pct}" in line
    ev = ["evaluate", fig8, "--params", str(params), "--truth", str(trial.outdir)]
    assert main([*ev, "--json"]) == 0
    cap = json.loads(capsys.readouterr().out)["captures"][0]
    assert set(cap["imo"]) == {"raw", "cal"} and cap["imo"]["cal"]["n"] == cap["n_samples"]
    truth = cap["truth"]["imo"]
    assert set(truth) == {"raw", "corrected"}
    assert truth["corrected"]["fraction"] > truth["raw"]["fraction"]
    assert main(ev) == 0
    out = capsys.readouterr().out
    assert out.count("IMO raw") == 2 and out.count("IMO cal") == 2


@pytest.mark.parametrize("m", [-1.0, 5.0])
def test_a_calibration_outside_the_envelope(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path, m: float
) -> None:
    """A calibration file edited to m = -1 (a log that reads nothing: no inverse) or m = 5:
    stderr says the daemon refuses it; m = -1 is one error line, exit 1. m = -1 ended with
    ``internal error: DataError``, and m = 5 was scored without a word."""
    cap = str(trial_files["straight"])
    params = tmp_path / "p.yaml"
    base = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main(["calibrate", cap, *base, "--save", str(params)]) == 0
    text = params.read_text()
    start = text.index("      m: ")
    params.write_text(text[:start] + f"      m: {m}\n" + text[text.index("\n", start) + 1 :])
    capsys.readouterr()
    assert main(["evaluate", cap, "--params", str(params)]) == (1 if m < 0 else 0)
    err = capsys.readouterr().err
    assert "outside the envelope" in err and "the daemon refuses" in err, err
    assert "internal error" not in err
    if m < 0:
        assert f"emlogd evaluate: error: {params}: no corrected speed" in err, err


def test_captures_with_no_sample_to_score(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """Captures holding the reference's records only (the log's port silent), or their
    header only: one error line saying why nothing is scored, exit 1, in text and JSON;
    such a capture beside a good one is scored 0 with a warning naming it. Both were a
    table of dashes (or JSON of zero samples) and exit 0."""
    lines = trial_files["straight"].read_text().splitlines(keepends=True)[:20000]
    cap, ref_only, header = (tmp_path / f"{n}.cap" for n in ("good", "ref-only", "header"))
    cap.write_text("".join(lines))
    params = tmp_path / "p.yaml"
    base = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main(["calibrate", str(cap), *base, "--save", str(params)]) == 0
    ref_only.write_text("".join(ln for ln in lines if " emlog" not in ln or ln.startswith("#")))
    header.write_text("".join(ln for ln in lines if ln.startswith("#")))
    capsys.readouterr()
    for path in (ref_only, header):
        for extra in ([], ["--json"]):
            assert main(["evaluate", str(path), "--params", str(params), *extra]) == 1
            out = capsys.readouterr()
            assert "no VHW reading of the log arrived on port 'emlog1'" in out.err, out.err
            assert out.out == ""
    assert main(["evaluate", str(cap), str(header), "--params", str(params)]) == 0
    assert f"warning: {header}: no sample scored" in capsys.readouterr().err
