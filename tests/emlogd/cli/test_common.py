"""What the command groups share: progress only on a terminal, the default config path."""

from __future__ import annotations

import argparse
import io

import pytest

from emlogd.cli.common import config_path, progress, progress_done
from emlogd.config import DEFAULT_PATH


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_only_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    """Progress redraws one line on a terminal stderr and writes nothing to a pipe or file."""
    pipe = io.StringIO()
    monkeypatch.setattr("sys.stderr", pipe)
    progress("reading", 0.5)
    progress_done()
    assert pipe.getvalue() == ""
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
