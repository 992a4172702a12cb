"""The ``emlogd`` command's entry point (the console script and ``python -m emlogd``):
what must be done before the command line's modules are imported, which takes a second
or more (the offline commands bring numpy and the whole pipeline).

For ``emlogd run`` that is holding SIGHUP and the signals the daemon has no use for
(:func:`emlogd.daemon.signals.hold_early`): the daemon passes them on once its handlers
are installed. Their default action ended the process for as long as it was importing
and starting: a ``kill -HUP`` in the daemon's first second, a restart under systemd.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence


def command(argv: Sequence[str]) -> str | None:
    """The sub-command ``argv`` names: its first argument that is not an option (the
    command line's own options, ``--debug`` and ``--version``, take no value)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI (:func:`emlogd.cli.main`) on ``argv`` (default: the process's
    arguments), SIGHUP and the unused signals held first for ``run``."""
    args = sys.argv[1:] if argv is None else list(argv)
    if command(args) == "run":
        from emlogd.daemon.signals import hold_early

        hold_early()
    from emlogd.cli import main as cli_main

    return cli_main(args)
