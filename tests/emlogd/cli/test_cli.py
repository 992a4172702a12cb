"""The command line through main(argv): the parser, exit codes and one-line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.cli import build_parser, main


def test_help_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    """--help exits 0 and names every subcommand; the parser's prog is 'emlogd'."""
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for cmd in (
        "dump", "record", "fake", "demo", "simulate", "calibrate", "evaluate", "crossval",
        "report", "run", "check-config", "replay", "status", "freeze", "learn", "reset",
    ):  # fmt: skip
        assert cmd in out
    assert build_parser().prog == "emlogd"


def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    """No command, a missing required argument and a bad --protocol choice each exit 2."""
    assert main([]) == 2
    assert main(["calibrate"]) == 2
    assert main(["dump", "x", "--protocol", "nope"]) == 2


def test_missing_file_is_one_line_exit_1(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """dump of a missing file exits 1 with one 'emlogd dump: error:' line and no traceback."""
    assert main(["dump", str(tmp_path / "none.cap")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "emlogd dump: error:" in err and "Traceback" not in err


def test_bad_capture_names_file_and_line(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A capture whose time goes backwards beyond the reorder window fails calibrate with one
    stderr line, and dump exits 1 naming FILE:5 and the time out of order."""
    bad = tmp_path / "bad.cap"
    bad.write_text("# emlogd capture v1\n# port a nmea0183\n(1.0) a $X*00\n(0.5) a $Y*00\n")
    assert main(["calibrate", str(bad), "--uut", "a", "--ref", "a", "--ref-field", "speed"]) in (
        1,
        2,
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    bad2 = tmp_path / "bad2.cap"
    bad2.write_text(
        "# emlogd capture v1\n# port a nmea0183\n(1.0) a $X*00\n(1.1) a $Z*00\n(0.5) a $Y*00\n"
    )
    assert main(["dump", str(bad2)]) == 1
    err = capsys.readouterr().err
    assert f"{bad2}:5:" in err and "0.500000 more than 0.2 s before 1.100000" in err


@pytest.mark.parametrize(
    "argv",
    [[], ["calibrate"], ["dump", "x", "--protocol", "nope"], ["nope"], ["replay", "--fast"]],
)
def test_usage_errors_are_one_line(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    """A command line argparse refuses gives exit 2 and one line on stderr (no usage block)."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error:" in err and "--help" in err


def test_unexpected_exception_is_one_line(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An exception no handler expected is one line with its type (exit 1); --debug raises it."""

    def boom(args: object) -> int:
        raise ValueError("first\nsecond")

    monkeypatch.setattr("emlogd.cli.daemon.cmd_check_config", boom)
    assert main(["check-config", "x.yaml"]) == 1
    err = capsys.readouterr().err
    assert err == (
        "emlogd check-config: internal error: ValueError: first; second "
        "(--debug shows the traceback)\n"
    )
    with pytest.raises(ValueError):
        main(["--debug", "check-config", "x.yaml"])
