"""``emlogd crossval``: every estimator trained on each capture, tested on the others."""

from __future__ import annotations

import argparse
import json
import sys
import time

from emlogd.cli.common import Subparsers, UsageError, progress, progress_done
from emlogd.cli.offline import twoaxis
from emlogd.cli.offline.args import captures_arg, common_offline, pairing_args, uut_settings
from emlogd.cli.offline.shared import capture_skips, load, warn_lag, warn_recs
from emlogd.offline.jobs import crossval
from emlogd.offline.tables import table2, table3


def _table2_pair(names: list[str], spec: str | None) -> tuple[str, str]:
    if spec:
        train, sep, test = spec.partition(",")
        if not sep or train not in names or test not in names:
            raise UsageError(f"--table2 TRAIN,TEST with names from {', '.join(names)}")
        return train, test
    fig = next((n for n in names if "figure" in n), names[0])
    straight = next((n for n in names if "straight" in n and n != fig), None)
    return fig, straight or next(n for n in names if n != fig)


def _workers_arg(value: str) -> int:
    """crossval --workers: a whole number of processes, at least one."""
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 1, not {value!r}")
    return n


def cmd_crossval(args: argparse.Namespace) -> int:
    """Cross-validate every estimator over the captures (the paper's Tables II and III)."""
    if args.axes == 2:
        return twoaxis.cmd_crossval(args)
    settings = uut_settings(args)
    recs = load(args.captures, settings, args)
    t0 = time.perf_counter()

    def onprogress(done: int, total: int, what: str) -> None:
        progress(f"crossval: {what}", done / total)

    result, lag = crossval(recs, settings, lag=args.lag, workers=args.workers, progress=onprogress)
    progress_done()
    warn_lag(args.command, lag.note)
    elapsed = time.perf_counter() - t0
    if args.csv:
        import csv

        rows = result.csv_rows()
        with open(args.csv, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    if args.json:
        doc = {
            "lag": lag.as_dict(),
            "uut": settings.port,
            "ref": settings.reference_port,
            "current_states": settings.current,
            **result.to_dict(),
            "capture_skips": capture_skips(recs),
        }
        sys.stdout.write(json.dumps(doc) + "\n")
        warn_recs(args.command, recs)
        return 0
    names = [s.name for s in result.segments]
    train, test = _table2_pair(names, args.table2)
    estimators = args.estimator or ["LS-EM3"]
    for est in estimators:
        if est not in result.estimators:
            raise UsageError(f"--estimator {est}: choose from {', '.join(result.estimators)}")
        sys.stdout.write(table3(result, est) + "\n")
    sys.stdout.write(table2(result, train, test))
    sys.stdout.write(
        f"\n{result.n_out_of_sample} out-of-sample evaluations, lag {lag.lag_s:.2f} s, "
        f"{elapsed:.1f} s\n"
    )
    warn_recs(args.command, recs)
    return 0


def add_parser(sub: Subparsers) -> None:
    """The ``crossval`` sub-command."""
    p = sub.add_parser(
        "crossval",
        help="cross-validate every estimator over captures (Tables II and III)",
        description="Train LS-EM1..4 and KF-EM1..4 on each capture, evaluate on every other; "
        "print the paper's Table III layout (per estimator) and Table II layout (one pair).",
    )
    captures_arg(p, "capture v1 files (≥ 2)")
    pairing_args(p)
    common_offline(p)
    p.add_argument("--csv", metavar="FILE", help="write every evaluation as CSV")
    p.add_argument(
        "--estimator",
        action="append",
        metavar="NAME",
        help="Table III for this estimator (repeatable; default LS-EM3)",
    )
    p.add_argument(
        "--table2", metavar="TRAIN,TEST", help="Table II pair (default figure-8, straight)"
    )
    p.add_argument(
        "--workers",
        type=_workers_arg,
        default=None,
        metavar="N",
        help="processes, at least 1, at most one per core and per job (default: all cores)",
    )
    twoaxis.axes_arg(p)
    p.set_defaults(handler=cmd_crossval)
