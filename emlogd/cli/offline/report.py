"""``emlogd report``: PNG figures like the paper's."""

from __future__ import annotations

import argparse
import sys

from emlogd.cli.common import Subparsers, UsageError, progress, progress_done
from emlogd.cli.offline import twoaxis
from emlogd.cli.offline.args import (
    captures_arg,
    common_offline,
    json_arg,
    model_arg,
    pairing_args,
    uut_settings,
)
from emlogd.cli.offline.shared import load, warn_lag, warn_recs


def cmd_report(args: argparse.Namespace) -> int:
    """PNG figures like the paper's (needs the report extra)."""
    if args.axes == 2:
        return twoaxis.cmd_report(args)
    if args.json:
        raise UsageError("--json is for --axes 2 (one axis: the figures' paths on stdout)")
    from emlogd.offline.report import report

    settings = uut_settings(args)
    recs = load(args.captures, settings, args)
    notes: list[str] = []
    paths = report(
        recs, settings, args.out, lag=args.lag, progress=progress, on_lag_note=notes.append
    )
    progress_done()
    for note in notes:
        warn_lag(args.command, note)
    for path in paths:
        sys.stdout.write(f"{path}\n")
    warn_recs(args.command, recs)
    return 0


def add_parser(sub: Subparsers) -> None:
    """The ``report`` sub-command."""
    p = sub.add_parser(
        "report",
        help="PNG figures like the paper's (extra: emlogd[report])",
        description="Write figures to --out: speeds raw/calibrated/reference, KF convergence "
        "sleeve (±3σ), NIS with χ² bounds, the track map, cross-validation heat maps.",
    )
    captures_arg(p)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    pairing_args(p)
    model_arg(p)
    common_offline(p, json_doc=False)  # the figures are the output: their paths on stdout
    json_arg(p, help="with --axes 2: the calibrations, the scores and the figures' paths as JSON")
    twoaxis.axes_arg(p)
    p.set_defaults(handler=cmd_report)
