"""The ``emlogd`` command's entry point (:mod:`emlogd.entry`); that it holds the
daemon's signals while ``emlogd run`` starts: ``tests/emlogd/daemon/test_redteam_fifteen.py``."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from emlogd.entry import command, main
from tests.emlogd.daemon.harness import PD0_CONFIG


@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["run", "--config", "c.yaml"], "run"),
        (["--debug", "run"], "run"),
        (["status", "--socket", "run"], "status"),
        (["--version"], None),
        ([], None),
    ],
)
def test_the_command_is_the_first_argument_not_an_option(argv: list[str], name: str) -> None:
    assert command(argv) == name


def test_another_command_holds_no_signal(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``check-config`` runs as the CLI runs it (exit 0) and leaves SIGHUP and SIGUSR1
    as they were: only ``run`` holds them (an offline command ends on them as before)."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(PD0_CONFIG)
    before = signal.getsignal(signal.SIGHUP), signal.getsignal(signal.SIGUSR1)
    assert main(["check-config", str(cfg)]) == 0
    assert "ok" in capsys.readouterr().out
    assert (signal.getsignal(signal.SIGHUP), signal.getsignal(signal.SIGUSR1)) == before
