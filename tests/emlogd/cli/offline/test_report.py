"""`emlogd report` through main(argv): its arguments."""

from __future__ import annotations

import pytest

from emlogd.cli import main


def test_report_needs_a_directory_and_json_needs_two_axes(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """report writes figures to --out and prints their paths: without --out, or with
    --json on one axis (its output is the figures' paths), it is a usage error, exit 2."""
    base = ["report", "x.cap", "--uut", "emlog1", "--ref", "dvl"]
    assert main(base) == 2
    assert "--out" in capsys.readouterr().err
    assert main([*base, "--out", "figs", "--json"]) == 2
    assert "--json is for --axes 2" in capsys.readouterr().err
