"""Offline commands: simulate, import, calibrate, evaluate, crossval, report, replay.

One module per command (its handler ``cmd_*``, its text output and ``add_parser``);
:mod:`.args` declares the options they share, :mod:`.shared` what they do alike once
parsed (reading captures, warnings, scoring against a simulated truth).
"""

from __future__ import annotations

from emlogd.cli.common import Subparsers
from emlogd.cli.offline import calibrate, crossval, evaluate, importing, replay, report, simulate

__all__ = ["add_parsers", "add_replay_parser"]


def add_parsers(sub: Subparsers) -> None:
    """The ``simulate``, ``import``, ``calibrate``, ``evaluate``, ``crossval`` and ``report`` sub-commands."""
    for command in (simulate, importing, calibrate, evaluate, crossval, report):
        command.add_parser(sub)


def add_replay_parser(sub: Subparsers) -> None:
    """The ``replay`` sub-command."""
    replay.add_parser(sub)
