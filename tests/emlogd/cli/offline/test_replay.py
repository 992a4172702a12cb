"""`emlogd replay` through main(argv): outputs, JSON keys, exit codes, hostile input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main


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


def _log2_config(tmp_path: Path) -> Path:
    """A config learning emlog1 against log2's VHW speed with no lag."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: log2, url: /dev/null, protocol: nmea0183, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: log2, reference_field: speed, lag: 0}\n"
    )
    return cfg


def _alternating_capture(tmp_path: Path, name: str, times: list[float], knots: list[float]) -> Path:
    """A capture of VHW sentences at ``times``, emlog1's and log2's in turn, reading
    ``knots``."""
    from drivers.nmea0183 import encode_vhw

    lines = ["# emlogd capture v1", "# port emlog1 nmea0183", "# port log2 nmea0183"]
    for k, (t, v) in enumerate(zip(times, knots, strict=True)):
        lines.append(f"({t:.6f}) {('emlog1', 'log2')[k % 2]} {encode_vhw(v)}")
    cap = tmp_path / name
    cap.write_text("\n".join(lines) + "\n")
    return cap


def test_reorder_window_option(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """`replay --reorder-window` sets how far records may be out of time order: by default ±50 ms
    of jitter loses nothing (records put back in order, counted as reordered), with 0 the same
    capture skips records as out_of_order; a negative window is a usage error."""
    import random

    rng = random.Random(3)
    times = [1_700_000_000.0 + 0.05 * k + rng.uniform(-0.05, 0.05) for k in range(400)]
    cap = _alternating_capture(tmp_path, "jitter.cap", times, [2.0] * 400)
    cfg = _log2_config(tmp_path)
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


def test_the_summary_has_a_two_axis_line_per_two_axis_uut() -> None:
    """``axes: 2``: a line with the UUT's two-axis state and why α is refused; none for a
    one-axis UUT."""
    from emlogd.cli.offline.replay import _two_axis_lines

    two = {"state": "learning", "refused": "misalignment not determinable"}
    lines = _two_axis_lines({"emlog1": {"state": "frozen"}, "emlog2": {"two_axis": two}})
    assert lines == [
        "emlog2 two axes: learning; latest window: misalignment refused: "
        "misalignment not determinable\n"
    ]


@pytest.mark.parametrize(
    ("sent", "warning"),
    [
        ("VBW", "emlog1: no VHW reading arrived, only VBW: nothing was learnt from them "
         "(set calibration[].uut_source: VBW"),
        ("none", "emlog1: no speed reading of the log (VHW, VBW) to use (none decoded)"),
        ("VHW", None),
    ],
)  # fmt: skip
def test_a_log_sending_another_sentence_than_configured_is_told(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, sent: str, warning: str | None
) -> None:
    """A log sending VBW alone, replayed with the default ``uut_source`` VHW: nothing is
    learnt, and a warning says which sentence came and which key to set; a log sending
    no speed sentence is told too; a VHW log is not warned about."""
    from drivers.nmea0183 import encode_vbw, encode_vhw

    lines = ["# emlogd capture v1", "# port emlog1 nmea0183", "# port log2 nmea0183"]
    for k in range(200):
        t = 1_700_000_000.0 + 0.5 * k
        s = encode_vbw(2.0, 0.0) if sent == "VBW" else encode_vhw(2.0)
        if sent != "none":
            lines.append(f"({t:.6f}) emlog1 {s}")
        lines.append(f"({t + 0.1:.6f}) log2 {encode_vhw(2.1)}")
    cap = tmp_path / "vbw.cap"
    cap.write_text("\n".join(lines) + "\n")
    cfg = _log2_config(tmp_path)
    assert main(["replay", str(cap), "--config", str(cfg), "--json"]) == 0
    err = capsys.readouterr().err
    if warning is None:
        assert "emlog1:" not in err, err
    else:
        assert warning in err, err


def test_a_clock_set_back_is_warned_and_its_records_replayed(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A capture whose logger's clock was set back an hour half-way: ``replay`` reads
    every record (the half after the step was skipped as ``out_of_order``), reports the
    step in ``capture_skips`` and warns naming its line."""
    times = [1_700_000_000.0 + 0.05 * k - (3600.0 if k >= 200 else 0.0) for k in range(400)]
    knots = [2.0 + 0.01 * (k % 3) for k in range(400)]
    cap = _alternating_capture(tmp_path, "stepped.cap", times, knots)
    cfg = _log2_config(tmp_path)
    argv = ["replay", str(cap), "--config", str(cfg), "--json", "--out", str(tmp_path / "o")]
    assert main(argv) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    skips = doc["capture_skips"][str(cap)]
    assert skips["skipped"] == 0 and [s["line"] for s in skips["steps"]] == [204]
    assert doc["ports"]["emlog1"]["records"] == 200
    assert f"{cap}:204: the time steps back 3599.950 s" in captured.err
