"""The ``emlogd`` command's entry point (:mod:`emlogd.entry`); that it holds the
daemon's signals while ``emlogd run`` starts: ``tests/emlogd/daemon/test_redteam_fifteen.py``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
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


HOLD_PROBE = """
import signal, sys

class Probe:
    def find_spec(self, name, path, target=None):
        if name == "emlogd.cli":  # the command line's heavy imports about to start
            held = signal.getsignal(signal.SIGHUP) not in (signal.SIG_DFL, signal.SIG_IGN)
            print("held" if held else "not held", flush=True)
            raise SystemExit(0)
        return None

sys.meta_path.insert(0, Probe())
from emlogd.entry import main
main(sys.argv[1:])
"""


@pytest.mark.parametrize(("argv", "said"), [(["run"], "held"), (["check-config"], "not held")])
def test_run_holds_sighup_before_the_command_line_is_imported(argv: list[str], said: str) -> None:
    """In a fresh interpreter, when ``emlogd.cli`` (numpy, the whole pipeline: a second
    of a start) is about to be imported, ``emlogd run`` already catches SIGHUP; another
    command does not."""
    repo = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-c", HOLD_PROBE, *argv],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, PYTHONPATH=str(repo)),
        check=False,
    )
    assert out.stdout.strip() == said, out.stderr[-2000:]
