"""``--axes 2`` of ``calibrate``, ``evaluate``, ``crossval`` and ``report``: both axes
of a log sending VBW, against a DVL's two-axis bottom track
(:mod:`emlogd.offline.twoaxis`)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Literal

from calib.models import Params
from emlogd.cli.common import UsageError, key_arg
from emlogd.cli.offline.args import uut_settings
from emlogd.cli.offline.shared import check_writable, load, warn_lag
from emlogd.offline import twoaxis
from emlogd.offline.jobs import OfflineError, calibrate, find_lag
from emlogd.offline.simtruth import read_truth
from emlogd.offline.tables import fmt, render
from emlogd.offline.twoaxis_forward import ForwardRule
from emlogd.pipeline.settings import UutSettings

AXES_HELP = (
    "2: both axes of a log sending VBW against the DVL's bottom track (--ref-field "
    "bottom): the misalignment, the transverse scale and bias, RMSE per axis"
)


def axes_arg(p: argparse.ArgumentParser) -> None:
    """``--axes 1|2`` (default 1)."""
    p.add_argument(
        "--axes",
        type=key_arg(UutSettings, "axes", allow_auto=False),
        default=1,
        metavar="{1,2}",
        help=AXES_HELP,
    )


def _records(args: argparse.Namespace, uut: str, ref: str) -> list[twoaxis.TwoAxisRecording]:
    field = getattr(args, "ref_field", None) or "bottom"
    if field != "bottom":
        raise UsageError("--axes 2 needs the DVL's bottom track: --ref-field bottom")
    return [twoaxis.record_two_axis(p, uut, ref) for p in args.captures]


def _lag(args: argparse.Namespace) -> tuple[float, str]:
    """The lag: given, else measured on the longitudinal axis as one-axis ``calibrate``
    does (:func:`emlogd.offline.jobs.find_lag`)."""
    settings = uut_settings(args, uut_source="VBW", current=True)
    if args.lag is not None:
        return float(args.lag), "given"
    report = find_lag(load(args.captures, settings, args), settings, None)
    warn_lag(args.command, report.note)
    return report.lag_s, report.source


def _one_axis(args: argparse.Namespace, paths: list[str], lag_s: float) -> Params | None:
    """The one-axis calibration of the same forward readings (``calibrate --current
    --uut-source VBW --method ls`` with the lag given), kept beside the two-axis one and
    weighed against it for the forward speed; None, with a note, where it cannot be
    fitted."""
    settings = uut_settings(args, uut_source="VBW", current=True)
    try:
        return calibrate(load(paths, settings, args), settings, "ls", lag=lag_s).estimate.params
    except OfflineError as exc:
        sys.stderr.write(f"emlogd {args.command}: no one-axis calibration beside: {exc}\n")
        return None


def _forward_text(rule: ForwardRule) -> str:
    """Whose forward speed is reported, and why."""
    if rule.reason is not None:
        return rule.reason
    if rule.one_axis is None:
        return "the two-axis calibration's (no one-axis calibration beside it)"
    return (
        "each reading's by the two-axis or the one-axis calibration, whichever has the "
        "smaller expected error (the daemon's rule)"
    )


def _scores_row(name: str, s: twoaxis.AxisScores) -> list[str]:
    return [
        name,
        str(s.n_samples),
        fmt(s.rmse_l_raw, ".4f"),
        fmt(s.rmse_l_cal, ".4f"),
        fmt(s.rmse_t_raw, ".4f"),
        fmt(s.rmse_t_cal, ".4f"),
        fmt(s.leeway_rms_deg, ".2f"),
    ]


SCORE_HEADER = ["capture", "N", "fwd raw", "fwd cal", "athw raw", "athw cal", "leeway°"]


def _summary(res: twoaxis.TwoAxisResult) -> list[str]:
    """α ± σ (or why it is held), the transverse parameters and the RMSE per axis."""
    f = res.fit
    se = f.stderr
    alpha = (
        f"{f.misalign_deg:+.3f} ± {fmt(f.misalign_std_deg, '.3f')}°"
        if f.misalign_std_deg is not None
        else f"{f.misalign_deg:+.3f}° (held: {f.ident.verdict('alpha').reason})"
    )
    return [
        f"{f.method}-{f.params.model} misalignment {alpha}",
        f"  transverse scale m_t {f.params.m_t:+.4f} ± {fmt(se.get('m_t'), '.4f')}, "
        f"bias b_t {f.params.b_t_mps:+.4f} ± {fmt(se.get('b_t'), '.4f')} m/s",
        f"  RMSE forward {res.scores.rmse_l_raw:.4f} raw, {res.scores.rmse_l_cal:.4f} "
        f"corrected; athwart {res.scores.rmse_t_raw:.4f} raw, {res.scores.rmse_t_cal:.4f} "
        "corrected (m/s, water frame)",
    ]


def cmd_report(args: argparse.Namespace) -> int:
    """``report --axes 2``: the figures' paths, then α ± σ, m_t, b_t and the RMSE per
    axis of least squares and the filter (:mod:`emlogd.offline.twoaxis_report`)."""
    from emlogd.offline.twoaxis_report import report_two_axis

    lag_s, source = _lag(args)
    recs = _records(args, args.uut, args.ref)
    model = getattr(args, "model", None) or "EM3"
    one = _one_axis(args, args.captures, lag_s)
    rep = report_two_axis(
        recs, model, lag_s, args.out, lag_source=source, reference=args.ref, one_axis=one
    )
    if args.json:
        sys.stdout.write(json.dumps(rep.to_dict(), indent=2) + "\n")
        return 0
    lines = [str(p) for p in rep.figures]
    lines.append(
        f"two axes: {rep.ls.uut} against {rep.ls.reference} (bottom), lag "
        f"{rep.ls.lag_s:.2f} s ({rep.ls.lag_source}), {rep.ls.fit.n_samples} samples"
    )
    lines += _summary(rep.ls) + _summary(rep.kf)
    sys.stdout.write("\n".join(lines) + "\n")
    sys.stdout.write(render(SCORE_HEADER, [_scores_row(r.capture, r.scores) for r in rep.rows]))
    return 0


def _text(res: twoaxis.TwoAxisResult) -> str:
    f = res.fit
    se = f.stderr
    held = set(f.ident.unidentifiable)
    names = {"misalign_deg": "alpha"}
    lines = [
        f"{f.method}-{f.params.model} two axes + current: {res.uut} against "
        f"{res.reference} (bottom), {f.n_samples} samples",
        f"lag          {res.lag_s:.2f} s ({res.lag_source})",
        "parameters (± standard error):",
    ]
    for k, v in f.params.as_dict().items():
        unit = "°" if k == "misalign_deg" else ""
        note = "   (not determined: held)" if names.get(k, k) in held else ""
        lines.append(f"  {k:<12} = {v:+.5f}{unit} ± {fmt(se.get(k), '.5f')}{note}")
    if f.current_mps is not None:
        lines.append(
            f"current      north {f.current_mps[0]:+.3f}, east {f.current_mps[1]:+.3f} m/s (mean)"
        )
    lines.append(f"identifiable {'yes' if f.identifiable else 'NO: ' + f.ident.reason}")
    one = res.rule.one_axis
    if one is not None:
        terms = ", ".join(f"{k} {v:+.5f}" for k, v in one.as_dict().items())
        lines.append(f"one axis     LS-{one.model} {terms} (the same forward readings)")
    lines.append(f"forward      {_forward_text(res.rule)}")
    lines.append(f"RMSE fit     forward {f.rmse_l_mps:.4f}, athwart {f.rmse_t_mps:.4f} m/s")
    lines.append(render(SCORE_HEADER, [_scores_row("all", res.scores)]))
    return "\n".join(lines) + "\n"


def cmd_calibrate(args: argparse.Namespace) -> int:
    """``calibrate --axes 2``."""
    if args.average is not None or args.trace is not None:
        raise UsageError("--average and --trace are one-axis options")
    if args.save:
        check_writable("--save", args.save)
    lag_s, source = _lag(args)
    recs = _records(args, args.uut, args.ref)
    model = getattr(args, "model", None) or "EM3"
    method: Literal["ls", "kf"] = "kf" if args.method == "kf" else "ls"
    res = twoaxis.calibrate_two_axis(
        recs,
        model,
        method,
        lag_s,
        lag_source=source,
        reference=args.ref,
        one_axis=_one_axis(args, args.captures, lag_s),
    )
    if args.json:
        sys.stdout.write(json.dumps(res.to_dict(), indent=2) + "\n")
    else:
        sys.stdout.write(_text(res))
    if args.save:
        twoaxis.save_two_axis(args.save, res)
        if not args.json:
            sys.stdout.write(f"saved        {args.save}\n")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """``evaluate --axes 2``: a two-axis calibration file applied to captures."""
    params, doc = twoaxis.load_two_axis(args.params)
    uut = args.uut or str(doc.get("uut", ""))
    ref = args.ref or str(doc.get("reference", "dvl"))
    lag = args.lag if args.lag is not None else doc.get("lag_s")
    if not isinstance(lag, (int, float)):
        raise UsageError(f"{args.params} has no lag: pass --lag SECONDS")
    recs = _records(args, uut, ref)
    rule = twoaxis.rule_of(doc, args.params)
    rows = twoaxis.evaluate_two_axis(recs, params, float(lag), rule)
    truth = read_truth(args.truth) if args.truth else None
    scored = (
        [twoaxis.truth_scores(r, params, truth, float(lag), rule) for r in recs] if truth else []
    )
    if args.json:
        out = []
        for i, r in enumerate(rows):
            d = r.to_dict()
            if scored:
                d["truth"] = scored[i].to_dict()
            out.append(d)
        doc_out = {"axes": 2, **rule.to_dict(), "rows": out}
        sys.stdout.write(json.dumps(doc_out, indent=2) + "\n")
        return 0
    sys.stdout.write(
        f"two axes: misalignment {params.misalign_deg:+.3f}°, transverse scale "
        f"{params.m_t:+.4f}, bias {params.b_t_mps:+.4f} m/s, lag {float(lag):.2f} s\n"
        f"forward speed: {_forward_text(rule)}\n"
    )
    sys.stdout.write(render(SCORE_HEADER, [_scores_row(r.capture, r.scores) for r in rows]))
    if scored:
        sys.stdout.write("\nagainst the truth (RMSE m/s: raw, calibrated, floor)\n")
        sys.stdout.write(
            render(
                [
                    "capture",
                    "fwd raw",
                    "fwd cal",
                    "fwd 1 axis",
                    "fwd floor",
                    "athw raw",
                    "athw cal",
                    "floor",
                ],
                [
                    [
                        r.name,
                        fmt(s.rmse_l_raw, ".4f"),
                        fmt(s.rmse_l_cal, ".4f"),
                        fmt(s.rmse_l_one_axis, ".4f"),
                        fmt(s.rmse_l_floor, ".4f"),
                        fmt(s.rmse_t_raw, ".4f"),
                        fmt(s.rmse_t_cal, ".4f"),
                        fmt(s.rmse_t_floor, ".4f"),
                    ]
                    for r, s in zip(recs, scored, strict=True)
                ],
            )
        )
    return 0


def cmd_crossval(args: argparse.Namespace) -> int:
    """``crossval --axes 2``: least squares trained on each capture, scored on every other."""
    lag_s, _ = _lag(args)
    recs = _records(args, args.uut, args.ref)
    model = getattr(args, "model", None) or "EM3"
    try:
        ones = [_one_axis(args, [p], lag_s) for p in args.captures]
        rows = twoaxis.crossval_two_axis(recs, model, lag_s, ones)
    except OfflineError as exc:
        raise UsageError(str(exc)) from None
    if args.json:
        sys.stdout.write(
            json.dumps({"axes": 2, "lag_s": lag_s, "rows": [r.to_dict() for r in rows]}, indent=2)
            + "\n"
        )
        return 0
    sys.stdout.write(
        render(
            ["train", "test", "alpha°", "±", *SCORE_HEADER[2:]],
            [
                [
                    r.train,
                    r.test,
                    fmt(r.misalign_deg, "+.3f"),
                    fmt(r.misalign_std_deg, ".3f"),
                    *_scores_row(r.test, r.scores)[2:],
                ]
                for r in rows
            ],
        )
    )
    return 0
