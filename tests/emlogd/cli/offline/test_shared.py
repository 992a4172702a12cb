"""What the offline commands share: malformed capture records counted and skipped, or fatal with --strict."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main


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
    capsys: pytest.CaptureFixture[str],
    trial_files: dict[str, Path],
    tmp_path: Path,
    two_port_config: Path,
) -> None:
    """replay, calibrate and evaluate count and skip bad records (with their lines); --strict fails."""
    bad = tmp_path / "bad.cap"
    _corrupt(trial_files["figure-8"], bad)
    expected = {
        "skipped": 3,
        "reasons": {"missing_payload": 1, "bad_time": 1, "non_ascii": 1},
        "reordered": 0,
        "steps": [],
        "first": [
            {"line": 1001, "error": "missing payload"},
            {"line": 2002, "error": "bad time '17497169x0.000000'"},
            {"line": 3003, "error": "non-ASCII bytes (payloads must be hex:)"},
        ],
    }
    cfg = two_port_config
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
