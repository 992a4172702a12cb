"""What the command groups share: progress only on a terminal, the default config path."""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from emlogd.cli import common
from emlogd.cli.common import config_path, progress, progress_done, progress_start
from emlogd.config import DEFAULT_PATH

ROOT = Path(__file__).resolve().parents[3]


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    """Progress redraws one line on a terminal stderr; to a pipe or file it writes nothing
    in a command's first PROGRESS_QUIET_S, then whole lines named by the command."""
    pipe = io.StringIO()
    monkeypatch.setattr("sys.stderr", pipe)
    progress_start("import")  # the command starts now (the process may be older)
    progress("reading", 0.5)
    progress_done()
    assert pipe.getvalue() == ""
    monkeypatch.setattr(common._state, "started", time.monotonic() - common.PROGRESS_QUIET_S)
    progress("reading", 0.5)
    assert pipe.getvalue().startswith("emlogd import: [")
    assert pipe.getvalue().endswith("] reading  50.0 %\n")
    tty = _Terminal()
    monkeypatch.setattr("sys.stderr", tty)
    progress("reading", 0.5)
    progress_done()
    assert tty.getvalue() == "\rreading  50.0 %\x1b[K\r\x1b[K"


def test_config_path_defaults_to_the_system_config() -> None:
    """--config wins; without it the daemon's default path is used."""
    assert config_path(argparse.Namespace(config="x.yaml")) == "x.yaml"
    assert config_path(argparse.Namespace(config=None)) == str(DEFAULT_PATH)
    assert config_path(argparse.Namespace()) == str(DEFAULT_PATH)


def close_std() -> None:
    """Close descriptors 0, 1 and 2 (in a child before its exec)."""
    for fd in (0, 1, 2):
        os.close(fd)


_PROBE = """
import os, sys
from emlogd.cli.common import open_std_streams
given = open_std_streams()
fd = os.open(sys.argv[1], os.O_WRONLY | os.O_CREAT)  # the next file opened
os.write(fd, f"{given} {fd} {sys.stdout is not None}".encode())
print("to /dev/null")
"""


def test_closed_standard_descriptors_are_given_dev_null(tmp_path: Path) -> None:
    """A process started with descriptors 0, 1 and 2 closed gets ``/dev/null`` on each
    and a stream on it: the next file it opens is not taken for its standard output, and
    a print goes nowhere without an error."""
    out = tmp_path / "probe.txt"
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, str(out)],
        preexec_fn=close_std,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        check=False,
        timeout=60,
    )
    assert done.returncode == 0
    assert out.read_text() == "['stdin', 'stdout', 'stderr'] 3 True"
