"""The command line through main(argv): outputs, JSON keys, exit codes, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import build_parser, main

CONFORMANCE = Path(__file__).resolve().parents[3] / ".." / "shared" / "conformance"


def test_help_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for cmd in (
        "dump", "record", "fake", "demo", "simulate", "calibrate", "evaluate", "crossval",
        "report", "run", "check-config", "replay", "status", "freeze", "learn", "reset",
    ):  # fmt: skip
        assert cmd in out
    assert build_parser().prog == "emlogd"


def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert main(["calibrate"]) == 2
    assert main(["dump", "x", "--protocol", "nope"]) == 2


def test_missing_file_is_one_line_exit_1(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["dump", str(tmp_path / "none.cap")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "emlogd dump: error:" in err and "Traceback" not in err


def test_bad_capture_names_file_and_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.cap"
    bad.write_text("# emlogd capture v1\n# port a nmea0183\n(1.0) a $X*00\n(0.5) a $Y*00\n")
    assert main(["calibrate", str(bad), "--uut", "a", "--ref", "a", "--ref-field", "speed"]) in (
        1,
        2,
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    bad2 = tmp_path / "bad2.cap"
    bad2.write_text("# emlogd capture v1\n# port a nmea0183\n(1.0) a $X*00\n(0.5) a $Y*00\n")
    assert main(["dump", str(bad2)]) == 1
    err = capsys.readouterr().err
    assert f"{bad2}:4:" in err and "backwards" in err


def test_dump_json_summary(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path]
) -> None:
    assert main(["dump", str(trial_files["straight"]), "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    first = json.loads(lines[0])
    assert set(first) == {"t", "port", "record"} and "type" in first["record"]
    summary = json.loads(lines[-1])["summary"]
    assert set(summary) == {"emlog1", "emlog2", "dvl", "gnss"}
    assert summary["dvl"]["protocol"] == "pd6" and summary["dvl"]["records"] > 0


@pytest.mark.parametrize(
    "name",
    [
        "nmea/gpsd_bundg_zeus_9.log",
        "nmea/signalk_gofree-merrimac.log",
        "nmea/signalk_plaka_first15000lines.log",
        "nmea/vdrplayer_Hakefjord.txt",
        "nmea/gpsd_humminbird-M37.log",
        "dvl/pd0/ooi_adcp_auv_51.pd0",
        "dvl/pd0/ooi_LB180210_3_corrupted.PD0",
        "dvl/ascii/trdi_pathfinder_guide_pd13_example.txt",
        "dvl/ascii/rowe_rti_unittest_prti_sentences.txt",
    ],
)
def test_dump_every_conformance_file(capsys: pytest.CaptureFixture[str], name: str) -> None:
    path = CONFORMANCE / name
    if not path.exists():
        pytest.skip("../shared/conformance is not present")
    args = ["dump", str(path)]
    if "prti" in name:
        args += ["--checksum-optional"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "records" in out.splitlines()[-2] or "rejected" in out


def test_check_config(capsys: pytest.CaptureFixture[str]) -> None:
    example = Path(__file__).resolve().parents[3] / "examples" / "emlogd.yaml"
    assert main(["check-config", str(example)]) == 0
    assert "ok" in capsys.readouterr().out


def test_calibrate_evaluate_crossval(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
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


def test_simulate_command(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["simulate", str(tmp_path / "sim"), "--scale", "0.01", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    assert "truth.yaml" in out and (tmp_path / "sim" / "2-figure8.cap").exists()
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0"]) == 2


def test_replay_command(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
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
    assert doc["ports"]["dvl"]["rejects"]["checksum"] >= 0
    assert state.exists() and out_nmea.stat().st_size > 0
    # replaying without learning applies the frozen parameters from the state file at once
    rc = main(["replay", str(trial_files["straight"]), "--config", str(cfg), "--state", str(state),
               "--no-learn", "--json"])  # fmt: skip
    assert rc == 0
    doc2 = json.loads(capsys.readouterr().out)
    assert doc2["uuts"]["emlog1"]["state"] == "frozen"
    assert doc2["uuts"]["emlog1"]["params"] == u["params"]
    assert doc2["uuts"]["emlog1"]["rmse_corrected"] < doc2["uuts"]["emlog1"]["rmse_raw"]


def test_control_commands_without_daemon(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["status", "--socket", str(tmp_path / "none.sock")]) == 1
    assert "is emlogd running" in capsys.readouterr().err


def test_fake_then_record_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`emlogd fake` (a subprocess) serves a capture; `emlogd record` captures it back."""
    import subprocess
    import sys
    import time

    from drivers.io.capture import CaptureReader, CaptureWriter

    src = tmp_path / "src.cap"
    lines = [b"$VWVHW,,T,,M,%d.00,N,,K*00" % k for k in range(50)]
    with CaptureWriter(src, {"emlog1": "nmea0183"}) as w:
        for k, line in enumerate(lines):
            w.write_line(1000.0 + k * 0.01, "emlog1", line)
    link = tmp_path / "links" / "emlog1"
    fake = subprocess.Popen(
        [sys.executable, "-m", "emlogd", "fake", str(src), "--link", str(link), "--speed", "5"],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 20
        while not link.exists():
            assert time.monotonic() < deadline and fake.poll() is None
            time.sleep(0.02)
        out = tmp_path / "rec.cap"
        rc = main(
            ["record", "--port", f"emlog1={link},baud=4800", "--out", str(out), "--duration", "3"]
        )
        assert rc == 0
    finally:
        fake.terminate()
        fake.wait(10)
    assert "wrote" in capsys.readouterr().err
    got = [r.payload.encode() for r in CaptureReader(out)]
    assert got == lines
    assert CaptureReader(out).ports == {"emlog1": "nmea0183"}
