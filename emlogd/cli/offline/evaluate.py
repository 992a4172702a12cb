"""``emlogd evaluate``: a saved calibration applied to captures."""

from __future__ import annotations

import argparse
import json
import sys

from calib.errors import DataError
from emlogd.cli.common import Subparsers, UsageError
from emlogd.cli.offline import twoaxis
from emlogd.cli.offline.args import (
    capture_args,
    captures_arg,
    json_arg,
    lag_arg,
    pairing_args,
    truth_arg,
    uut_settings,
    uut_source_arg,
    water_frame,
)
from emlogd.cli.offline.shared import (
    capture_skips,
    imo_cell,
    load,
    score_rec,
    truth_cells,
    truth_of,
    warn_envelope,
    warn_recs,
)
from emlogd.offline.headings import why_no_sample
from emlogd.offline.jobs import OfflineError, evaluate, load_params
from emlogd.offline.tables import fmt, render


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Apply a frozen calibration to captures: RMSE raw and calibrated per capture."""
    if args.axes == 2:
        return twoaxis.cmd_evaluate(args)
    cal, extra = load_params(args.params)
    settings = uut_settings(
        args,
        port=args.uut or cal.uut,
        reference_port=args.ref or cal.reference.get("port", "dvl"),
        reference_field=args.ref_field or cal.reference.get("field", "bottom"),
        model=cal.params.model,
        current=bool(args.current or cal.current),
        uut_source=args.uut_source or extra.get("uut_source") or "VHW",
    )
    lag_s = cal.lag_s if args.lag is None else args.lag
    if lag_s is None:
        raise UsageError(f"{args.params} has no lag: pass --lag SECONDS")
    truth = truth_of(args, [settings.port])
    recs = load(args.captures, settings, args)
    warn_envelope(args.command, cal.params, settings.envelope)
    try:
        rows = evaluate(recs, cal.params, settings, lag_s)
    except DataError as exc:  # a model that cannot be inverted (m = -1): no corrected speed
        raise OfflineError(f"{args.params}: no corrected speed to score ({exc})") from None
    if not any(r.n_samples for r in rows):  # nothing scored: no table of dashes, exit 0
        raise OfflineError(why_no_sample(recs, settings, lag_s))
    for r in rows:
        if not r.n_samples:
            sys.stderr.write(f"emlogd {args.command}: warning: {r.capture}: no sample scored\n")
    scores = [score_rec(truth, settings.port, r, cal.params) for r in recs]
    if args.json:
        doc = {
            "model": cal.params.model,
            "params": cal.params.as_dict(),
            "lag_s": lag_s,
            "uut": settings.port,
            "ref": settings.reference_port,
            "current_states": settings.current,
            "captures": [
                r.to_dict() | {"truth": None if sc is None else sc.to_dict()}
                for r, sc in zip(rows, scores, strict=True)
            ],
            "capture_skips": capture_skips(recs),
        }
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
        warn_recs(args.command, recs)
        return 0
    values = ", ".join(f"{k} = {v:+.5f}" for k, v in cal.params.as_dict().items())
    sys.stdout.write(
        f"{cal.params.model} ({values}) from {args.params}, "
        f"{settings.port} against {settings.reference_port}, lag {lag_s:.2f} s\n"
    )
    sys.stdout.write(
        render(
            ["capture", "samples", "RMSE raw", "RMSE cal", "improv. %", "IMO raw", "IMO cal"]
            + (["truth: raw", "cal", "floor", "IMO raw", "IMO cal"] if truth is not None else []),
            [
                [
                    r.capture,
                    str(r.n_samples),
                    fmt(r.rmse_raw, ".4f"),
                    fmt(r.rmse_cal, ".4f"),
                    fmt(r.improvement_pct, ".1f"),
                    imo_cell(r.imo_raw),
                    imo_cell(r.imo_cal),
                    *truth_cells(sc),
                ]
                for r, sc in zip(rows, scores, strict=True)
            ],
        )
    )
    warn_recs(args.command, recs)
    return 0


def add_parser(sub: Subparsers) -> None:
    """The ``evaluate`` sub-command."""
    p = sub.add_parser(
        "evaluate",
        help="apply frozen parameters to captures",
        description="Apply a parameters file (calibrate --save) to captures: RMSE raw, "
        "calibrated and the improvement per capture.",
    )
    captures_arg(p)
    p.add_argument("--params", required=True, metavar="PARAMS.yaml", help="parameters file")
    pairing_args(p, required=False)
    water_frame(p)
    uut_source_arg(p)
    lag_arg(p, auto=False)
    capture_args(p)
    json_arg(p)
    truth_arg(p, "raw and calibrated speeds")
    twoaxis.axes_arg(p)
    p.set_defaults(handler=cmd_evaluate)
