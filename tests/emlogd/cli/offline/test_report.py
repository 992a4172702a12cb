"""`emlogd report` through main(argv): its arguments."""

from __future__ import annotations

import pytest

from emlogd.cli import main


def test_report_needs_a_directory_and_has_no_json(capsys: pytest.CaptureFixture[str]) -> None:
    """report writes figures to --out and prints their paths: without --out, or with
    --json (it has no JSON document), it is a usage error, exit 2."""
    base = ["report", "x.cap", "--uut", "emlog1", "--ref", "dvl"]
    assert main(base) == 2
    assert "--out" in capsys.readouterr().err
    assert main([*base, "--out", "figs", "--json"]) == 2
    assert "unrecognized arguments: --json" in capsys.readouterr().err
