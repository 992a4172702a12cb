"""``emlogd calibrate``: an error model of one EMlog fitted against a reference."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import get_args

from emlogd.cli.common import Subparsers, UsageError, key_arg
from emlogd.cli.offline import twoaxis
from emlogd.cli.offline.args import (
    captures_arg,
    common_offline,
    model_arg,
    pairing_args,
    uut_settings,
    window_arg,
)
from emlogd.cli.offline.shared import (
    capture_skips,
    check_writable,
    imo_cell,
    load,
    warn_envelope,
    warn_lag,
    warn_recs,
)
from emlogd.offline.jobs import CalibrationResult, Method, calibrate, save_params
from emlogd.offline.tables import fmt
from emlogd.pipeline.settings import UutSettings


def _heading_text(h: dict[str, object]) -> str:
    """One line: the heading's variation and where it came from, and the course check."""
    var, source = h.get("variation_deg"), h.get("variation_source")
    text = "heading      " + (
        f"variation {var:+.2f}° ({source})" if isinstance(var, float) else "true (no variation)"
    )
    check = h.get("check")
    if isinstance(check, dict):
        off = check.get("offset_deg")
        text += (
            f", {off:+.1f}° from the course on straight legs"
            if isinstance(off, float)
            else ", offset from the course not decided (too few straight legs or sectors)"
        )
    refused = h.get("refused_magnetic")
    if isinstance(refused, int) and refused:
        text += f", {refused} magnetic headings refused (no variation yet)"
    return text


def _calibration_text(res: CalibrationResult) -> str:
    se = res.param_std
    held = set(res.ident.unidentifiable)
    # least squares holds an undetermined unknown at its prior; the filter may have
    # learnt it where a window determined it, though the data as a whole do not
    why = (
        "not determined: held at its prior"
        if res.method == "ls"
        else "not determined by these data as a whole: learnt only where a window was"
    )
    params = "\n".join(
        f"  {k:<2} = {v:+.5f} ± {fmt(se.get(k), '.5f')}" + (f"   ({why})" if k in held else "")
        for k, v in res.params.as_dict().items()
    )
    lag = res.lag
    lag_txt = f"{lag.lag_s:.2f} s ({lag.source}"
    if lag.per_capture:
        lag_txt += "; " + ", ".join(
            f"{k} {e.lag_s:.2f}±{fmt(e.std_s, '.2f')} s r={e.peak_corr:.2f}"
            for k, e in lag.per_capture.items()
        )
    lag_txt += ")"
    s = res.settings
    out = [
        f"{res.method.upper()}-{res.params.model}{' + current' if s.current else ''}: "
        f"{s.port} against {s.reference_port} ({s.reference_field}), {res.n_samples} samples"
        + (f" (fit on {res.average_s:g}-s means)" if res.average_s > 0 else ""),
        f"lag          {lag_txt}",
        "parameters (± standard error):",
        params,
    ]
    if res.current_mps is not None:
        cs = res.current_std_mps or (math.nan, math.nan)
        out.append(
            f"current      north {res.current_mps[0]:+.3f} ± {fmt(cs[0], '.3f')} m/s, "
            f"east {res.current_mps[1]:+.3f} ± {fmt(cs[1], '.3f')} m/s"
        )
    elif s.current:
        out.append("current      not determined")
    out += [_heading_text(h) for h in res.heading.values()]
    out += [
        f"identifiable {'yes' if res.identifiable else 'NO: ' + res.reason}",
        f"condition    {fmt(res.ident.cond_info, '.3g')}",
        f"RMSE raw     {fmt(res.rmse_raw, '.4f')} m/s",
        f"RMSE cal     {fmt(res.rmse_cal, '.4f')} m/s",
        f"improvement  {fmt(res.improvement_pct, '.1f')} %",
        f"IMO A.824    raw {imo_cell(res.imo_raw)}, cal {imo_cell(res.imo_cal)} "
        "(within max(2 % of the speed, 0.2 kn); meets: ≥ 95 % of the samples)",
    ]
    if res.nis_mean is not None:
        out.append(
            f"NIS          mean {fmt(res.nis_mean, '.2f')}, "
            f"{fmt(100.0 * (res.nis_frac_inside or math.nan), '.1f')} % inside the 95 % bounds"
            + (
                f", the noises × {res.noise_scale:.3g} of those configured"
                if res.noise_scale is not None
                else ""
            )
        )
    return "\n".join(out) + "\n"


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Estimate an error model of one EMlog against a reference from captures."""
    if args.axes == 2:
        return twoaxis.cmd_calibrate(args)
    settings = uut_settings(args)
    if args.average is not None and args.method != "ls":
        raise UsageError("--average applies to --method ls")
    if args.trace is not None and args.method != "kf":
        raise UsageError("--trace follows the Kalman filter: use it with --method kf")
    for opt, path in (("--save", args.save), ("--trace", args.trace)):
        if path:
            check_writable(opt, path)
    recs = load(args.captures, settings, args)
    res = calibrate(
        recs, settings, args.method, lag=args.lag, trace=args.trace, average_s=args.average
    )
    warn_lag(args.command, res.lag.note)
    warn_envelope(args.command, res.estimate.params, res.settings.envelope)
    if args.json:
        sys.stdout.write(
            json.dumps({**res.to_dict(), "capture_skips": capture_skips(recs)}, indent=2) + "\n"
        )
    else:
        sys.stdout.write(_calibration_text(res))
    warn_recs(args.command, recs)
    if args.save:
        try:
            save_params(args.save, res)
        except OSError as exc:  # the fit is printed above: only the file is lost
            raise OSError(
                f"cannot write {args.save}: {exc.strerror or exc} (the fit is printed above)"
            ) from None
        if not args.json:
            sys.stdout.write(f"saved        {args.save}\n")
    return 0


def add_parser(sub: Subparsers) -> None:
    """The ``calibrate`` sub-command."""
    p = sub.add_parser(
        "calibrate",
        help="fit an error model of one EMlog against a reference",
        description="Estimate the lag, fit EM1..EM4 by least squares or the Kalman filter, "
        "print parameters ± standard errors, identifiability, RMSE raw and calibrated.",
    )
    captures_arg(p)
    pairing_args(p)
    model_arg(p)
    p.add_argument(
        "--method",
        choices=get_args(Method),
        default="ls",
        help="ls (default): least squares over every sample the daemon learns from (no "
        "stalled reading); kf: the daemon's Kalman filter, sample by sample",
    )
    p.add_argument("--save", metavar="PARAMS.yaml", help="write the calibration file")
    p.add_argument(
        "--trace",
        metavar="FILE.csv",
        help="with --method kf: one CSV row per sample (parameters, current, σ, NIS, state)",
    )
    p.add_argument(
        "--average",
        type=window_arg,
        metavar="SECONDS",
        help="with --method ls: fit block means over SECONDS (default 20 for a gnss "
        "reference, whose noise would shrink the scale; else 0: every sample)",
    )
    p.add_argument(
        "--r-raw",
        type=key_arg(UutSettings, "r_raw_mps"),
        metavar="M/S",
        help="the log's reading noise, 1σ (the config key r_raw_mps; default: the Airmar "
        "spec's 0.1 kn); the filter's NIS is near 1 only with the log's true noise",
    )
    common_offline(p)
    twoaxis.axes_arg(p)
    p.set_defaults(handler=cmd_calibrate)
