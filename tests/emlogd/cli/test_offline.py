"""The offline commands through main(argv): outputs, JSON keys, exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import build_parser, main
from emlogd.cli.offline import _settings
from emlogd.offline.simulate import SimulationResult
from emlogd.pipeline.settings import UutSettings


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


def test_simulate_command(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """simulate writes the trial captures and names truth.yaml; --scale 0 exits 2."""
    assert main(["simulate", str(tmp_path / "sim"), "--scale", "0.01", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "truth.yaml" in out and (tmp_path / "sim" / "2-figure8.cap").exists()
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0"]) == 2


def test_replay_command(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """replay --json reports UUT and port figures and writes the state and NMEA output; a --no-learn
    replay from that state applies the frozen parameters at once and beats raw."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: dvl, lag: 3.3, max_param_std: {m: 0.05, b: 0.08},"
        " persist_interval_s: 1}\n"
    )
    out_nmea = tmp_path / "out.nmea"
    state = tmp_path / "state.yaml"
    files = [str(trial_files["transit"]), str(trial_files["figure-8"])]
    rc = main(
        [
            "replay",
            *files,
            "--config",
            str(cfg),
            "--out",
            str(out_nmea),
            "--state",
            str(state),
            "--json",
        ]
    )
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc) >= {"uuts", "ports"}
    u = doc["uuts"]["emlog1"]
    assert set(u) >= {"rmse_raw", "rmse_corrected", "params", "state", "freezes"}
    rejects = doc["ports"]["dvl"]["rejects"]
    # every reason is reported, a zero too (PD6 has no checksum); the injected faults are counted
    assert rejects["checksum"] == 0 and rejects["framing"] > 0
    assert state.exists() and out_nmea.stat().st_size > 0
    # replaying without learning applies the frozen parameters from the state file at once
    rc = main(["replay", str(trial_files["straight"]), "--config", str(cfg), "--state", str(state),
               "--no-learn", "--json"])  # fmt: skip
    assert rc == 0
    doc2 = json.loads(capsys.readouterr().out)
    assert doc2["uuts"]["emlog1"]["state"] == "frozen"
    assert doc2["uuts"]["emlog1"]["params"] == u["params"]
    assert doc2["uuts"]["emlog1"]["rmse_corrected"] < doc2["uuts"]["emlog1"]["rmse_raw"]


@pytest.mark.parametrize("speed", ["0", "-1"])
def test_replay_rejects_a_speed_that_is_not_positive(
    capsys: pytest.CaptureFixture[str], speed: str
) -> None:
    """replay --speed 0 or -1 is a usage error: exit 2, one line on stderr."""
    assert main(["replay", "x.cap", "--config", "c.yaml", "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--speed" in err and "Traceback" not in err


def _corrupt(src: Path, dst: Path) -> dict[int, bytes]:
    """Copy a capture, spoiling three records: an empty payload, a bad time, a non-ASCII byte."""
    lines = src.read_bytes().split(b"\n")
    spoilt = {
        1001: b"(1749716900.000000) emlog1 ",
        2002: b"(17497169x0.000000) emlog1 $VWVHW,,T,,M,3.50,N,6.48,K*6A",
        3003: lines[3002].replace(b",", b"\xb0", 1),
    }
    for n, line in spoilt.items():
        lines[n - 1] = line
    dst.write_bytes(b"\n".join(lines))
    return spoilt


def test_malformed_records_are_skipped_or_strict(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """replay, calibrate and evaluate count and skip bad records (with their lines); --strict fails."""
    bad = tmp_path / "bad.cap"
    _corrupt(trial_files["figure-8"], bad)
    expected = {
        "skipped": 3,
        "reasons": {"missing_payload": 1, "bad_time": 1, "non_ascii": 1},
        "reordered": 0,
        "first": [
            {"line": 1001, "error": "missing payload"},
            {"line": 2002, "error": "bad time '17497169x0.000000'"},
            {"line": 3003, "error": "non-ASCII bytes (payloads must be hex:)"},
        ],
    }
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: dvl, lag: 3.3}\n"
    )
    assert main(["replay", str(bad), "--config", str(cfg), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["capture_skips"] == {str(bad): expected}
    assert captured.err == (
        f"emlogd replay: warning: {bad}: ports emlog2, gnss not in {cfg}: their records are "
        "skipped\n"
        f"emlogd replay: warning: {bad}: 3 malformed records skipped "
        "(first at line 1001: missing payload); --strict fails instead\n"
    )
    params = tmp_path / "p.yaml"
    pair = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main(["calibrate", str(bad), *pair, "--save", str(params), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["capture_skips"] == {str(bad): expected}
    assert main(["evaluate", str(bad), "--params", str(params), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["capture_skips"] == {str(bad): expected}
    for argv in (
        ["replay", str(bad), "--config", str(cfg), "--strict", "--json"],
        ["calibrate", str(bad), *pair, "--strict"],
        ["evaluate", str(bad), "--params", str(params), "--strict"],
    ):
        assert main(argv) == 1
        captured = capsys.readouterr()
        # (replay also names the capture's ports its config lacks, before reading)
        assert captured.err.endswith(f"emlogd {argv[0]}: error: {bad}:1001: missing payload\n")
        assert captured.err.count("error") == 1
        assert captured.out == ""


@pytest.mark.parametrize("command", ["calibrate", "evaluate", "crossval"])
def test_an_offline_job_takes_the_declared_defaults(command: str) -> None:
    """Options left out give exactly the pipeline's declared UUT settings (no second copy)."""
    argv = [command, "x.cap", "--uut", "log", "--ref", "dvl"]
    if command == "evaluate":
        argv += ["--params", "p.json"]
    args = build_parser().parse_args(argv)
    assert _settings(args) == UutSettings(port="log", reference_port="dvl")


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


HOSTILE_HDG = b"$HCHDG,10.0,1e308,E,1e308,E*73"
"""The red team's sentence: a valid checksum, a deviation and a variation whose sum overflows."""


def test_the_hostile_hdg_sentence_is_counted_by_replay_and_calibrate(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """The overflowing HDG sentence on the GNSS port of a capture, forty times, is counted by
    `replay` as forty out_of_range rejects of that port, and neither `replay` nor `calibrate` stops:
    both end 0 with the results of the same capture without it."""
    src = trial_files["figure-8"]
    lines = src.read_bytes().split(b"\n")
    out: list[bytes] = []
    n = 0
    for k, line in enumerate(lines):
        out.append(line)
        if k > 10 and k % 500 == 0 and line.startswith(b"(") and n < 40:
            out.append(line.split(b" ", 1)[0] + b" gnss " + HOSTILE_HDG)
            n += 1
    assert n == 40
    bad = tmp_path / "hostile.cap"
    bad.write_bytes(b"\n".join(out))
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}\n"
        "  - {name: gnss, url: /dev/null, protocol: nmea0183, role: aux}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: dvl, lag: 3.3}\n"
    )
    docs = []
    for cap in (src, bad):
        assert main(["replay", str(cap), "--config", str(cfg), "--json"]) == 0
        docs.append(json.loads(capsys.readouterr().out))
    clean, hostile = docs
    assert hostile["ports"]["gnss"]["rejects"]["out_of_range"] == 40
    assert hostile["ports"]["gnss"]["rejects"]["internal"] == 0
    assert hostile["uuts"]["emlog1"]["params"] == clean["uuts"]["emlog1"]["params"]
    assert hostile["records"] == clean["records"] + 40
    pair = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3", "--json"]
    fits = []
    for cap in (src, bad):
        assert main(["calibrate", str(cap), *pair]) == 0
        fits.append(json.loads(capsys.readouterr().out))
    assert fits[0]["params"] and fits[1]["params"] == fits[0]["params"]


def test_reorder_window_option(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """`replay --reorder-window` sets how far records may be out of time order: by default ±50 ms
    of jitter loses nothing (records put back in order, counted as reordered), with 0 the same
    capture skips records as out_of_order; a negative window is a usage error."""
    import random

    from drivers.nmea0183 import encode_vhw

    rng = random.Random(3)
    lines = ["# emlogd capture v1", "# port emlog1 nmea0183", "# port log2 nmea0183"]
    for k in range(400):
        t = 1_700_000_000.0 + 0.05 * k + rng.uniform(-0.05, 0.05)
        lines.append(f"({t:.6f}) {('emlog1', 'log2')[k % 2]} {encode_vhw(2.0)}")
    cap = tmp_path / "jitter.cap"
    cap.write_text("\n".join(lines) + "\n")
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: log2, url: /dev/null, protocol: nmea0183, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: log2, reference_field: speed, lag: 0}\n"
    )
    base = ["replay", str(cap), "--config", str(cfg), "--json", "--out", str(tmp_path / "o")]
    assert main(base) == 0
    skips = json.loads(capsys.readouterr().out)["capture_skips"][str(cap)]
    assert skips["skipped"] == 0 and skips["reordered"] > 0
    assert main([*base, "--reorder-window", "0"]) == 0
    captured = capsys.readouterr()
    skips = json.loads(captured.out)["capture_skips"][str(cap)]
    assert skips["reasons"]["out_of_order"] > 0 and "--strict fails instead" in captured.err
    assert main([*base, "--reorder-window", "-1"]) == 2
    assert "expected seconds ≥ 0" in capsys.readouterr().err


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
