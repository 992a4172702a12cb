"""`emlogd import` through main(argv): the options each input format takes."""

from __future__ import annotations

from pathlib import Path
from typing import get_args

import pytest

from emlogd.cli import build_parser, main
from emlogd.offline.importbase import ImportFormat


def test_a_utc_offset_beyond_the_time_zones_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """--utc-offset takes hours within ±14 (the time zones' span): 15 exits 2 naming the
    range, 14 is taken (and the command goes on to the missing file: exit 1)."""
    argv = ["import", str(tmp_path / "x.csv"), "--format", "csv", "--out", str(tmp_path / "o.cap")]
    assert main([*argv, "--utc-offset", "15"]) == 2
    assert "expected hours in [-14, 14]" in capsys.readouterr().err
    assert main([*argv, "--utc-offset", "14"]) == 1


@pytest.mark.parametrize(
    ("fmt", "option", "message"),
    [
        ("nmea", ["--map", "time=T,stw=S"], "--map applies to --format csv only"),
        ("nmea", ["--utc-offset", "1"], "--utc-offset applies to --format csv only"),
        ("json", ["--preset", "expedition"], "--preset applies to --format csv only"),
        ("json", ["--date", "2025-06-27"], "--date does not apply to --format json"),
        ("n2k", ["--date", "2025-06-27"], "--date does not apply to --format n2k"),
    ],
)
def test_an_option_of_the_other_format_is_refused(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, fmt: str, option: list[str], message: str
) -> None:
    """An option of the other input format is a usage error (exit 2) that names it, before
    any file is read."""
    argv = ["import", str(tmp_path / "missing"), "--format", fmt, "--out", str(tmp_path / "o")]
    assert main([*argv, *option]) == 2
    assert message in capsys.readouterr().err


def test_json_lines_import(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """--format json reads a canboat analyzer log and reports its lines."""
    src = tmp_path / "n2k.json"
    src.write_text(
        '{"timestamp":"2025-06-27T10:40:00Z","pgn":128259,"fields":{"Speed Water Referenced":2}}\n'
    )
    argv = ["import", str(src), "--format", "json", "--out", str(tmp_path / "o.cap")]
    assert main(argv) == 0
    assert "1 sentences on port nmea (0.0 min) from 1 lines" in capsys.readouterr().out


@pytest.mark.parametrize("fmt", get_args(ImportFormat))
def test_every_import_format_is_a_choice_that_runs(
    fmt: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """--format offers each member of ImportFormat and nothing else, and each reaches its
    importer (a missing file: exit 1 naming it, not a usage error)."""
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    fmt_action = next(
        a
        for a in sub.choices["import"]._actions  # type: ignore[index]
        if a.dest == "format"
    )
    assert list(fmt_action.choices) == list(get_args(ImportFormat))
    missing = tmp_path / "missing.log"
    assert main(["import", str(missing), "--format", fmt, "--out", str(tmp_path / "o.cap")]) == 1
    assert "missing.log" in capsys.readouterr().err
