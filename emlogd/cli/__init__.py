"""The ``emlogd`` command line: one entry point, one sub-command per job.

``main(argv)`` is embeddable and testable (nothing assigns ``sys.argv``). Exit
codes: 0 success, 1 runtime error (one clear line on stderr, a traceback only
with ``--debug``), 2 usage error. This package is the only place allowed to print.
The commands live in one module per group: :mod:`.devices` (dump, record, fake),
:mod:`.offline` (simulate, import, calibrate, evaluate, crossval, report, replay),
:mod:`.daemon` (run, check-config, the control commands, demo); :mod:`.common`
holds what they share.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
from collections.abc import Sequence

from drivers import EmlogdError
from emlogd import __version__
from emlogd.cli import daemon, devices, offline
from emlogd.cli.common import (
    Handler,
    Parser,
    UsageError,
    open_std_streams,
    progress_done,
    progress_start,
)

__all__ = ["UsageError", "build_parser", "main"]


def _one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (a multi-line message joined with '; ')."""
    return re.sub(r"\s*\n\s*", "; ", str(exc).strip())


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (exposed for tests and documentation)."""
    parser = Parser(
        prog="emlogd",
        description="EMlog calibration daemon and offline tools.",
    )
    parser.add_argument("--version", action="version", version=f"emlogd {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show tracebacks instead of one-line errors"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    devices.add_parsers(sub)
    daemon.add_demo_parser(sub)
    offline.add_parsers(sub)
    daemon.add_parsers(sub)
    offline.add_replay_parser(sub)
    daemon.add_control_parsers(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code."""
    open_std_streams()  # started with them closed: /dev/null, not the next file opened
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else 2
    handler: Handler = args.handler
    progress_start(args.command)
    with contextlib.suppress(AttributeError, ValueError):  # a replaced stdout (tests)
        # piped, each line goes out as it is written (a reader sees the work as it happens)
        sys.stdout.reconfigure(line_buffering=True)  # type: ignore[union-attr]
    try:
        return handler(args)
    except UsageError as exc:
        if args.debug:
            raise
        sys.stderr.write(f"emlogd {args.command}: error: {_one_line(exc)}\n")
        return 2
    except (EmlogdError, OSError) as exc:
        if args.debug:
            raise
        if isinstance(exc, BrokenPipeError):
            return 0
        sys.stderr.write(f"emlogd {args.command}: error: {_one_line(exc)}\n")
        return 1
    except KeyboardInterrupt:
        progress_done()
        return 130
    except Exception as exc:  # a bug: still one line, the traceback with --debug
        if args.debug:
            raise
        progress_done()
        sys.stderr.write(
            f"emlogd {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} "
            "(--debug shows the traceback)\n"
        )
        return 1
    finally:
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            # the reader went away (emlogd dump | head): silence the interpreter's own complaint
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
