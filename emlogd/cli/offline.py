"""Offline commands: simulate, import, calibrate, evaluate, crossval, report, replay."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from collections.abc import Sequence
from datetime import date
from pathlib import Path
from typing import TYPE_CHECKING, Any

from calib.metrics import ImoVerdict
from calib.models import MODEL_NAMES
from drivers.io.capture import REORDER_WINDOW_S
from emlogd.cli.common import (
    Subparsers,
    UsageError,
    key_arg,
    positive_float,
    progress,
    progress_done,
)
from emlogd.offline.dataset import Recording
from emlogd.offline.jobs import (
    CalibrationResult,
    OfflineError,
    calibrate,
    crossval,
    evaluate,
    load_captures,
    load_params,
    save_params,
)
from emlogd.offline.tables import fmt, render, table2, table3
from emlogd.pipeline.settings import UutSettings

if TYPE_CHECKING:
    from calib.models import Params
    from emlogd.offline.simulate import Truth, TruthScore
    from emlogd.pipeline.core import Emit, Pipeline

# ---------------------------------------------------------------------------- simulate


def cmd_simulate(args: argparse.Namespace) -> int:
    """Write the simulated sea trial (five captures, truth.yaml and truth.csv.gz)."""
    from emlogd.offline.simulate import EMLOG1, EMLOG2, TrajectoryTruth, simulate, with_sensor

    if not 0.0 < args.scale <= 10.0:
        raise UsageError(f"--scale must be in (0, 10], not {args.scale}")
    emlogs = {EMLOG1.port: EMLOG1, EMLOG2.port: EMLOG2}
    for port, given in args.sensor or ():
        try:
            emlogs[port] = with_sensor(emlogs[port], given)
        except ValueError as exc:
            raise UsageError(f"--sensor: {exc}") from None

    def written(tr: TrajectoryTruth, path: Path) -> None:
        progress_done()
        lines = sum(tr.lines.values())
        raw = ", ".join(f"{k} {v:.3f}" for k, v in tr.rmse_raw_mps.items())
        sys.stdout.write(
            f"{path}: {tr.duration_s / 60.0:6.1f} min, {lines:8d} lines, raw RMSE m/s: {raw}\n"
        )

    result = simulate(
        args.outdir,
        seed=args.seed,
        scale=args.scale,
        dvl_format=args.dvl_format,
        current=args.current,
        circles=args.circles,
        emlogs=(emlogs[EMLOG1.port], emlogs[EMLOG2.port]),
        progress=progress,
        on_written=written,
    )
    progress_done()
    sys.stdout.write(f"{result.truth_path}: truth ({result.elapsed_s:.1f} s)\n")
    return 0


def _current_arg(value: str) -> tuple[float, float]:
    """``N,E`` in m/s (simulate --current)."""
    north, sep, east = value.partition(",")
    try:
        c = (float(north), float(east))
    except ValueError:
        c = (math.nan, math.nan)
    if not sep or not all(math.isfinite(x) and abs(x) <= 3.0 for x in c):
        raise argparse.ArgumentTypeError(f"expected N,E in m/s within ±3, not {value!r}")
    return c


def _sensor_arg(value: str) -> tuple[str, dict[str, float]]:
    """``PORT:KEY=V,...`` (simulate --sensor): one of the trial's EMlogs and the values
    it sets (:func:`emlogd.offline.simulate.with_sensor` checks the keys and ranges)."""
    from emlogd.offline.simulate import EMLOG1, EMLOG2

    ports = (EMLOG1.port, EMLOG2.port)
    port, sep, rest = value.partition(":")
    if not sep or port not in ports:
        expected = " or ".join(f"{p}:KEY=V,..." for p in ports)
        raise argparse.ArgumentTypeError(f"expected {expected}, not {value!r}")
    given: dict[str, float] = {}
    for item in rest.split(","):
        key, eq, text = item.partition("=")
        key = key.strip()
        if not eq or not key:
            raise argparse.ArgumentTypeError(f"{item!r}: expected KEY=V")
        if key in given:
            raise argparse.ArgumentTypeError(f"{key} given twice in {value!r}")
        try:
            x = float(text)
        except ValueError:
            x = math.nan
        if not math.isfinite(x):
            raise argparse.ArgumentTypeError(f"{key}: {text!r} is not a number")
        given[key] = x
    return port, given


def _truth(args: argparse.Namespace, uuts: Sequence[str]) -> Truth | None:
    """``--truth DIR``: the simulated trial's truth (checked to know ``uuts``), else None."""
    if not getattr(args, "truth", None):
        return None
    from emlogd.offline.simulate import read_truth

    truth = read_truth(args.truth)
    for port in uuts:
        truth.emlog(port)
    return truth


def _score_rec(truth: Truth | None, port: str, rec: Recording, params: Params) -> TruthScore | None:
    """A capture's raw and calibrated readings scored against the truth (None without one)."""
    if truth is None:
        return None
    from calib.models import correct_array
    from emlogd.offline.simulate import score_truth

    return score_truth(truth, port, rec.t_read, rec.raw, correct_array(params, rec.raw))


def imo_cell(v: ImoVerdict | None) -> str:
    """An IMO A.824(19) verdict in a few characters: ``97.5 % meets``, ``61.0 % fails``."""
    if v is None or v.n == 0:
        return "-"
    return f"{100.0 * v.fraction:.1f} % {'meets' if v.meets else 'fails'}"


def _truth_cells(score: TruthScore | None) -> list[str]:
    """Against the truth: RMSE raw, calibrated or corrected, the floor (m/s); IMO raw, cal."""
    if score is None:
        return []
    return [
        fmt(score.rmse_raw, ".4f"),
        fmt(score.rmse_corrected, ".4f"),
        fmt(score.rmse_floor, ".4f"),
        imo_cell(score.imo_raw),
        imo_cell(score.imo_corrected),
    ]


# ---------------------------------------------------------------------------- import


def _date_arg(value: str) -> date:
    try:
        return date.fromisoformat(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD, not {value!r}") from None


MAX_UTC_OFFSET_H = 14.0
"""The largest clock offset from UTC a logger can have (the time zones span −12 to +14 h)."""


def _utc_offset_arg(value: str) -> float:
    """import --utc-offset: hours within ±:data:`MAX_UTC_OFFSET_H`."""
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and abs(x) <= MAX_UTC_OFFSET_H):
        raise argparse.ArgumentTypeError(
            f"expected hours in [-{MAX_UTC_OFFSET_H:g}, {MAX_UTC_OFFSET_H:g}], not {value!r}"
        )
    return x


def _import_presets() -> list[str]:
    from emlogd.offline.importer import PRESETS

    return list(PRESETS)


def cmd_import(args: argparse.Namespace) -> int:
    """Turn NMEA logs or CSV exports into a capture."""
    from emlogd.offline import importer

    if not args.port or not args.port.isidentifier():
        raise UsageError(f"--port must be a name (letters, digits, _), not {args.port!r}")
    if args.format == "nmea":
        for opt in ("map", "preset", "time_format", "heading_ref", "utc_offset", "variation"):
            if getattr(args, opt) is not None:
                raise UsageError(f"--{opt.replace('_', '-')} applies to --format csv only")
        report = importer.import_nmea(
            args.files, args.out, port=args.port, day=args.date, progress=progress
        )
    else:
        if args.date is not None:
            raise UsageError("--date applies to --format nmea only")
        if len(args.files) != 1:
            raise UsageError("--format csv imports one file at a time")
        report = importer.import_csv(
            args.files[0],
            args.out,
            importer.parse_map(args.map) if args.map is not None else None,
            preset=args.preset,
            time_format=args.time_format,
            heading_ref=args.heading_ref,
            utc_offset_h=args.utc_offset,
            variation_deg=args.variation,
            port=args.port,
            progress=progress,
        )
    progress_done()
    if args.json:
        sys.stdout.write(json.dumps(report.to_dict(), indent=2) + "\n")
        return 0
    span = report.t_end - report.t_start
    sys.stdout.write(
        f"{report.out}: {report.written} sentences on port {report.port} "
        f"({span / 60.0:.1f} min) from {report.lines} {'lines' if args.format == 'nmea' else 'rows'}\n"
    )
    sys.stdout.write(
        "written      " + ", ".join(f"{k} {v}" for k, v in sorted(report.sentences.items())) + "\n"
    )
    skipped = {k: v for k, v in report.skipped.items() if v}
    sys.stdout.write(
        "skipped      "
        + (", ".join(f"{k} {v}" for k, v in sorted(skipped.items())) or "none")
        + "\n"
    )
    for k, v in sorted(report.cells.items()):
        sys.stdout.write(f"cell skipped {k} {v}\n")
    for k, v in sorted(report.notes.items()):
        sys.stdout.write(f"note         {k} {v}\n")
    if report.preset is not None:
        sys.stdout.write(f"preset       {report.preset}\n")
    check = report.heading_check
    if check is not None and isinstance(check.get("offset_deg"), float):
        sys.stdout.write(
            f"heading      {check['offset_deg']:+.1f}° from the course on straight legs"
            + (
                f" — more than leeway explains ({check['max_offset_deg']}°): is it "
                "magnetic (--heading-ref magnetic), or the compass wrong?\n"
                if check.get("flagged")
                else "\n"
            )
        )
    if report.variation == "none":
        sys.stdout.write(
            "heading      magnetic, and no variation nor position: give --variation DEG "
            "(here or to calibrate)\n"
        )
    elif report.variation is not None:
        sys.stdout.write(f"heading      magnetic, variation from the {report.variation}\n")
    return 0


# ---------------------------------------------------------------------------- offline


def _settings(args: argparse.Namespace, **over: Any) -> UutSettings:
    """The UUT of an offline job, as the daemon's settings (defaults from the declarations)."""
    kw: dict[str, Any] = {
        "port": args.uut,
        "reference_port": args.ref,
        "current": bool(getattr(args, "current", False)),
    }
    given = {
        "reference_field": args.ref_field,
        "uut_source": getattr(args, "uut_source", None),
        "component": "magnitude" if getattr(args, "magnitude", False) else None,
        "heading": getattr(args, "heading", None),
        "magnetic_variation_deg": getattr(args, "variation", None),
        "model": getattr(args, "model", None),
        "r_raw_mps": getattr(args, "r_raw", None),
    }
    kw.update({k: v for k, v in given.items() if v is not None})
    kw.update(over)
    try:
        return UutSettings(**kw)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


STRICT_HELP = "fail at the first malformed capture record instead of counting and skipping it"

REORDER_HELP = (
    "capture records up to S seconds out of time order are put back in order "
    f"(default {REORDER_WINDOW_S:g}; 0: each must follow the last)"
)


def _window_arg(value: str) -> float:
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x >= 0.0):
        raise argparse.ArgumentTypeError(f"expected seconds ≥ 0, not {value!r}")
    return x


def _workers_arg(value: str) -> int:
    """crossval --workers: a whole number of processes, at least one."""
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 1, not {value!r}")
    return n


def _capture_args(p: argparse.ArgumentParser) -> None:
    """``--strict`` and ``--reorder-window``: how a command reads captures."""
    p.add_argument("--strict", action="store_true", help=STRICT_HELP)
    p.add_argument(
        "--reorder-window",
        type=_window_arg,
        default=REORDER_WINDOW_S,
        metavar="S",
        help=REORDER_HELP,
    )


def _warn_skips(command: str, skips: dict[str, dict[str, object]]) -> None:
    """One warning line on stderr per capture with malformed records skipped."""
    for path, rep in skips.items():
        n = rep.get("skipped", 0)
        if not isinstance(n, int) or n == 0:
            continue
        first = rep.get("first")
        where = ""
        if isinstance(first, list) and first:
            where = f" (first at line {first[0]['line']}: {first[0]['error']})"
        sys.stderr.write(
            f"emlogd {command}: warning: {path}: {n} malformed record"
            f"{'s' if n != 1 else ''} skipped{where}; --strict fails instead\n"
        )


def _warn_internal(command: str, where: str, report: dict[str, object]) -> None:
    """One warning line when records failed unforeseen and were contained."""
    n = report.get("count", 0)
    first = report.get("first")
    if not isinstance(n, int) or n == 0 or not isinstance(first, list) or not first:
        return
    f = first[0]
    sys.stderr.write(
        f"emlogd {command}: warning: {where}: {n} record{'s' if n != 1 else ''} failed "
        f"and {'were' if n != 1 else 'was'} skipped (first on port {f['port']}: {f['error']}; "
        f"data {f['data']!r})\n"
    )


def _warn_recs(command: str, recs: Sequence[Recording]) -> None:
    """The warnings of the captures read: malformed records skipped, records that failed."""
    _warn_skips(command, _skips(recs))
    for r in recs:
        _warn_internal(command, r.path, r.internal)


def _skips(recs: Sequence[Recording]) -> dict[str, dict[str, object]]:
    return {r.path: r.skips for r in recs}


def _load(paths: Sequence[str], settings: UutSettings, args: argparse.Namespace) -> list[Recording]:
    """Read the captures; without ``--uut-source`` a UUT that sends no VHW is read from VBW.

    Malformed records are skipped unless ``--strict`` (the command warns about them
    once it has succeeded: a failure stays one line).
    """
    strict = bool(getattr(args, "strict", False))
    window = float(getattr(args, "reorder_window", REORDER_WINDOW_S))
    recs = load_captures(paths, settings, progress=progress, strict=strict, reorder_window_s=window)
    if not getattr(args, "uut_source", None) and not any(r.raw.size for r in recs):
        recs = load_captures(
            paths,
            dataclasses.replace(settings, uut_source="VBW"),
            progress=progress,
            strict=strict,
            reorder_window_s=window,
        )
    progress_done()
    return recs


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
    se = res.stderr
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


def _warn_lag(command: str, note: str) -> None:
    """The lag fallback's note, once, on stderr (the lag line on stdout says ``fallback``)."""
    if note:
        sys.stderr.write(f"emlogd {command}: warning: {note}\n")


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Estimate an error model of one EMlog against a reference from captures."""
    settings = _settings(args)
    if args.average is not None and args.method != "ls":
        raise UsageError("--average applies to --method ls")
    if args.trace is not None and args.method != "kf":
        raise UsageError("--trace follows the Kalman filter: use it with --method kf")
    for opt, path in (("--save", args.save), ("--trace", args.trace)):
        if path:
            _check_writable(opt, path)
    recs = _load(args.captures, settings, args)
    res = calibrate(
        recs, settings, args.method, lag=args.lag, trace=args.trace, average_s=args.average
    )
    _warn_lag(args.command, res.lag.note)
    if args.json:
        sys.stdout.write(
            json.dumps({**res.to_dict(), "capture_skips": _skips(recs)}, indent=2) + "\n"
        )
    else:
        sys.stdout.write(_calibration_text(res))
    _warn_recs(args.command, recs)
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


def _check_writable(option: str, path: str) -> None:
    """Fail before the work when ``path``'s directory does not exist or is not writable
    (a runtime error naming the option and the path, exit 1)."""
    import os

    parent = Path(path).parent
    if not parent.is_dir():
        raise OfflineError(f"{option} {path}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise OfflineError(f"{option} {path}: the directory {parent} is not writable")


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Apply a frozen calibration to captures: RMSE raw and calibrated per capture."""
    cal, extra = load_params(args.params)
    settings = _settings(
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
    truth = _truth(args, [settings.port])
    recs = _load(args.captures, settings, args)
    rows = evaluate(recs, cal.params, settings, lag_s)
    scores = [_score_rec(truth, settings.port, r, cal.params) for r in recs]
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
            "capture_skips": _skips(recs),
        }
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
        _warn_recs(args.command, recs)
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
                    *_truth_cells(sc),
                ]
                for r, sc in zip(rows, scores, strict=True)
            ],
        )
    )
    _warn_recs(args.command, recs)
    return 0


def _table2_pair(names: list[str], spec: str | None) -> tuple[str, str]:
    if spec:
        train, sep, test = spec.partition(",")
        if not sep or train not in names or test not in names:
            raise UsageError(f"--table2 TRAIN,TEST with names from {', '.join(names)}")
        return train, test
    fig = next((n for n in names if "figure" in n), names[0])
    straight = next((n for n in names if "straight" in n and n != fig), None)
    return fig, straight or next(n for n in names if n != fig)


def cmd_crossval(args: argparse.Namespace) -> int:
    """Cross-validate every estimator over the captures (the paper's Tables II and III)."""
    settings = _settings(args)
    recs = _load(args.captures, settings, args)
    t0 = time.perf_counter()

    def onprogress(done: int, total: int, what: str) -> None:
        progress(f"crossval: {what}", done / total)

    result, lag = crossval(recs, settings, lag=args.lag, workers=args.workers, progress=onprogress)
    progress_done()
    _warn_lag(args.command, lag.note)
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
            "capture_skips": _skips(recs),
        }
        sys.stdout.write(json.dumps(doc) + "\n")
        _warn_recs(args.command, recs)
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
    _warn_recs(args.command, recs)
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """PNG figures like the paper's (needs the report extra)."""
    from emlogd.offline.report import report

    settings = _settings(args)
    recs = _load(args.captures, settings, args)
    notes: list[str] = []
    paths = report(
        recs, settings, args.out, lag=args.lag, progress=progress, on_lag_note=notes.append
    )
    progress_done()
    for note in notes:
        _warn_lag(args.command, note)
    for path in paths:
        sys.stdout.write(f"{path}\n")
    _warn_recs(args.command, recs)
    return 0


class _EmitCapture:
    """``replay --out FILE.cap``: what the daemon emitted as a capture v1, one port per UUT
    (and ``fused``), each sentence stamped with the receive time of the sample it corrects."""

    def __init__(self, path: str, uuts: Sequence[str], pipeline: Pipeline) -> None:
        from drivers.io.capture import CaptureWriter

        ports = dict.fromkeys(uuts, "nmea0183")
        if pipeline.fusion is not None:
            ports["fused"] = "nmea0183"
        self.writer = CaptureWriter(path, ports)
        self.writer.comment("emlogd replay: the sentences emitted, by UUT")
        self.t = -math.inf

    def write(self, emits: Sequence[Emit]) -> None:
        for e in emits:
            self.t = max(self.t, e.t)  # sentences made later never go back in time
            self.writer.write_line(self.t, e.port, e.sentence.encode("ascii"))

    def close(self) -> None:
        self.writer.close()


def cmd_replay(args: argparse.Namespace) -> int:
    """Run the daemon's pipeline over captures; write the corrected NMEA; print a summary."""
    from emlogd.config import load_config
    from emlogd.daemon.statefile import StateStore
    from emlogd.offline.replay import replay, unmatched_ports
    from emlogd.pipeline.calibration import Calibration, checker
    from emlogd.pipeline.core import Output
    from emlogd.settings import build_pipeline, pipeline_from_config

    cfg = load_config(args.config)
    _, uuts = pipeline_from_config(cfg)
    truth = _truth(args, [u.port for u in uuts])
    store = StateStore(args.state) if args.state else None
    cals: dict[str, Calibration] = {}
    others: list[Calibration] = []
    if store is not None:
        cals, others, report = store.load_state(check=checker(uuts))
        for line in report:
            sys.stderr.write(f"emlogd replay: {line}\n")
    pipeline = build_pipeline(cfg, cals, others, learn=args.learn)
    for path, missing in unmatched_ports(pipeline, args.captures).items():
        sys.stderr.write(
            f"emlogd replay: warning: {path}: port{'s' if len(missing) != 1 else ''} "
            f"{', '.join(missing)} not in {args.config}: {'their' if len(missing) != 1 else 'its'} "
            "records are skipped\n"
        )

    def persist(_: Output) -> None:
        if store is not None:
            aside = store.save(
                {c.uut: c for c in pipeline.calibrations()}, pipeline.other_calibrations()
            )
            if aside is not None:
                sys.stderr.write(f"emlogd replay: the refused state file is kept as {aside}\n")

    to_stdout = args.out is None and not args.json
    as_capture = bool(args.out) and args.out.endswith((".cap", ".cap.gz"))
    capture = _EmitCapture(args.out, [u.port for u in uuts], pipeline) if as_capture else None
    sink = (
        open(args.out, "wb")  # noqa: SIM115
        if args.out and not as_capture
        else (sys.stdout.buffer if to_stdout else None)
    )
    try:
        result = replay(
            pipeline,
            args.captures,
            sink=sink,
            on_emit=capture.write if capture is not None else None,
            speed=None if args.fast or args.speed is None else args.speed,
            on_persist=persist,
            progress=progress,
            strict=args.strict,
            reorder_window_s=args.reorder_window,
            truth=truth,
        )
    finally:
        progress_done()
        if args.out and sink is not None:
            sink.close()
        if capture is not None:
            capture.close()
    if store is not None:
        persist(Output())
    doc = result.to_dict()
    _warn_skips(args.command, result.capture_skips)
    _warn_internal(args.command, "replay", result.internal)
    if args.json:
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
        return 0
    out = sys.stderr if to_stdout else sys.stdout
    rows = []
    uut_docs = doc["uuts"]
    assert isinstance(uut_docs, dict)
    for name, u in uut_docs.items():
        params = u["params"] or {}
        rows.append(
            [
                name,
                u["state"],
                ", ".join(f"{k}={v:+.4f}" for k, v in params.items()) or "-",
                fmt(u["lag_s"], ".2f"),
                fmt(u["rmse_raw"], ".4f"),
                fmt(u["rmse_corrected"], ".4f"),
                str(u["freezes"]),
                *_truth_cells(result.truth.get(name)),
            ]
        )
    out.write(
        render(
            ["uut", "state", "parameters", "lag s", "RMSE raw", "RMSE corr.", "freezes"]
            + (
                ["truth: raw", "corr.", "floor", "IMO raw", "IMO corr."]
                if truth is not None
                else []
            ),
            rows,
            left=3,
        )
    )
    out.write(
        f"{result.records} records in {result.elapsed_s:.1f} s "
        f"({result.span_s / max(result.elapsed_s, 1e-9):.0f}x real time), "
        f"{result.emitted} sentences emitted"
        + (f", {result.persisted} persists to {args.state}" if store is not None else "")
        + "\n"
    )
    return 0


def _pairing_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    p.add_argument(
        "--uut",
        required=required,
        metavar="PORT",
        help="the EMlog's port" + ("" if required else " (default: the parameters file's)"),
    )
    p.add_argument(
        "--ref",
        required=required,
        metavar="PORT",
        help="the reference's port" + ("" if required else " (default: the parameters file's)"),
    )
    p.add_argument(
        "--ref-field",
        choices=["bottom", "water", "speed", "gnss"],
        default="bottom" if required else None,
        help="reference: DVL bottom track (default), DVL water track, an EMlog's speed, "
        "or GNSS speed and course (RMC/VTG) projected on the hull with the heading",
    )


def _model_arg(p: argparse.ArgumentParser) -> None:
    """``--model``: the error model (default: the calibration's declared one)."""
    default = next(f.default for f in dataclasses.fields(UutSettings) if f.name == "model")
    p.add_argument("--model", choices=MODEL_NAMES, help=f"error model (default {default})")


def _water_frame(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--current",
        action="store_true",
        help="estimate the sea current too (the water frame; needs a heading)",
    )
    p.add_argument(
        "--heading",
        metavar="auto|PORT",
        help="heading source (default auto: the reference's, else the UUT's VHW, else any)",
    )
    p.add_argument(
        "--variation",
        type=key_arg(UutSettings, "magnetic_variation_deg"),
        metavar="DEG",
        help="magnetic variation, + east, for magnetic headings without one",
    )


def _common_offline(p: argparse.ArgumentParser, json_doc: bool = True) -> None:
    _water_frame(p)
    p.add_argument("--uut-source", choices=["VHW", "VBW"], help="UUT sentence (default VHW)")
    p.add_argument(
        "--magnitude",
        action="store_true",
        help="compare horizontal speed magnitudes instead of longitudinal speeds",
    )
    p.add_argument(
        "--lag",
        type=key_arg(UutSettings, "lag_s"),
        default=None,
        metavar="auto|SECONDS",
        help="UUT latency (default auto: cross-correlation)",
    )
    _capture_args(p)
    if json_doc:
        p.add_argument("--json", action="store_true", help="one JSON document (README keys)")


def add_parsers(sub: Subparsers) -> None:
    """The ``simulate``, ``import``, ``calibrate``, ``evaluate``, ``crossval`` and ``report`` sub-commands."""
    p = sub.add_parser(
        "simulate",
        help="write a simulated sea trial (five captures and the truth)",
        description="Simulate the paper's sea trial: 1-transit, 2-figure8, 3-straight, "
        "4-circles, 5-return as capture v1 files in OUTDIR (ports emlog1, emlog2, dvl, "
        "gnss), plus truth.yaml and the truth per sample in truth.csv.gz.",
    )
    p.add_argument("outdir", help="output directory (created if missing)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="duration factor in (0, 10] (default 1; 0.1: 10 %% as long)",
    )
    p.add_argument(
        "--dvl-format", choices=["pd6", "pd0"], default="pd6", help="DVL output (default pd6)"
    )
    p.add_argument(
        "--current",
        type=_current_arg,
        metavar="N,E",
        help="a constant sea current, m/s north and east (default: a slowly varying one; "
        "a current to the south is written --current=-0.6,0.4)",
    )
    p.add_argument(
        "--circles",
        choices=["steps", "constant"],
        default="steps",
        help="the circles at three throttle settings (default) or at one constant speed",
    )
    p.add_argument(
        "--sensor",
        type=_sensor_arg,
        action="append",
        metavar="PORT:KEY=V,...",
        help="another EMlog: PORT emlog1 or emlog2, KEY a (s/m), m, b (m/s) of its EM4 "
        "error model, latency (s) or noise (m/s, 1σ); the values not given keep their "
        "defaults (truth.yaml lists every sensor's); repeatable",
    )
    p.set_defaults(handler=cmd_simulate)

    p = sub.add_parser(
        "import",
        help="turn NMEA logs or CSV exports into a capture",
        description="Import logs without receive times into a capture v1 file on one port. "
        "nmea: NMEA 0183 logs, timed by their RMC (else ZDA, else GGA + --date) fixes; "
        "csv: one CSV export with a column map (or --preset expedition), written as VHW, "
        "RMC and VDR sentences at the row times. Skipped lines are counted by reason.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="input files, in time order")
    p.add_argument("--format", choices=["nmea", "csv"], required=True, help="input format")
    p.add_argument("--out", required=True, metavar="FILE.cap", help="capture to write (.gz ok)")
    p.add_argument("--port", default="nmea", help="port name in the capture (default nmea)")
    p.add_argument(
        "--date", type=_date_arg, metavar="YYYY-MM-DD", help="nmea: UTC date for GGA-only logs"
    )
    p.add_argument(
        "--map",
        metavar="KEY=COL,...",
        help="csv: columns for time, stw (and date, heading, sog, cog, lat, lon, set, drift, "
        "variation); A|B: the first present, Col?: optional; knots unless written Col[mps]",
    )
    p.add_argument(
        "--preset",
        choices=["auto", *_import_presets()],
        help="csv: a known export's columns (default without --map: auto, chosen by the header)",
    )
    p.add_argument(
        "--time-format",
        metavar="ole|iso|epoch|PATTERN",
        help="csv: the time column (a strptime PATTERN for date + ' ' + time with a date "
        "column); default: the preset's, else told by the first time",
    )
    p.add_argument(
        "--heading-ref",
        choices=["true", "magnetic"],
        help="csv: the heading's reference (default: the preset's, else true)",
    )
    p.add_argument(
        "--utc-offset",
        type=_utc_offset_arg,
        metavar="HOURS",
        help="csv: the logger's clock minus UTC (times are taken as UTC without it)",
    )
    p.add_argument(
        "--variation",
        type=key_arg(UutSettings, "magnetic_variation_deg"),
        metavar="DEG",
        help="csv: magnetic variation, + east, when no column gives one (else the IGRF "
        "model at the fixes' positions, at calibration)",
    )
    p.add_argument("--json", action="store_true", help="the import report as JSON")
    p.set_defaults(handler=cmd_import)

    p = sub.add_parser(
        "calibrate",
        help="fit an error model of one EMlog against a reference",
        description="Estimate the lag, fit EM1..EM4 by least squares or the Kalman filter, "
        "print parameters ± standard errors, identifiability, RMSE raw and calibrated.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    _pairing_args(p)
    _model_arg(p)
    p.add_argument(
        "--method",
        choices=["ls", "kf"],
        default="ls",
        help="ls: least squares over all samples (default); kf: the daemon's Kalman filter, "
        "sample by sample",
    )
    p.add_argument("--save", metavar="PARAMS.yaml", help="write the calibration file")
    p.add_argument(
        "--trace",
        metavar="FILE.csv",
        help="with --method kf: one CSV row per sample (parameters, current, σ, NIS, state)",
    )
    p.add_argument(
        "--average",
        type=_window_arg,
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
    _common_offline(p)
    p.set_defaults(handler=cmd_calibrate)

    p = sub.add_parser(
        "evaluate",
        help="apply frozen parameters to captures",
        description="Apply a parameters file (calibrate --save) to captures: RMSE raw, "
        "calibrated and the improvement per capture.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    p.add_argument("--params", required=True, metavar="PARAMS.yaml", help="parameters file")
    _pairing_args(p, required=False)
    _water_frame(p)
    p.add_argument("--uut-source", choices=["VHW", "VBW"], help="UUT sentence (default VHW)")
    p.add_argument(
        "--lag",
        type=key_arg(UutSettings, "lag_s", allow_auto=False),
        default=None,
        metavar="SECONDS",
        help="override the saved lag (default: the file's; [0, 30] like the config key lag)",
    )
    _capture_args(p)
    p.add_argument("--json", action="store_true", help="one JSON document (README keys)")
    p.add_argument(
        "--truth",
        metavar="DIR",
        help="a simulated trial's directory: score raw and calibrated speeds against its "
        "true speed through water",
    )
    p.set_defaults(handler=cmd_evaluate)

    p = sub.add_parser(
        "crossval",
        help="cross-validate every estimator over captures (Tables II and III)",
        description="Train LS-EM1..4 and KF-EM1..4 on each capture, evaluate on every other; "
        "print the paper's Table III layout (per estimator) and Table II layout (one pair).",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files (≥ 2)")
    _pairing_args(p)
    _common_offline(p)
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
        help="processes, at least 1 (default: all cores)",
    )
    p.set_defaults(handler=cmd_crossval)

    p = sub.add_parser(
        "report",
        help="PNG figures like the paper's (extra: emlogd[report])",
        description="Write figures to --out: speeds raw/calibrated/reference, KF convergence "
        "sleeve (±3σ), NIS with χ² bounds, the track map, cross-validation heat maps.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    _pairing_args(p)
    _model_arg(p)
    _common_offline(p, json_doc=False)  # the figures are the output: their paths on stdout
    p.set_defaults(handler=cmd_report)


def add_replay_parser(sub: Subparsers) -> None:
    """The ``replay`` sub-command."""
    p = sub.add_parser(
        "replay",
        help="run the daemon's pipeline over captures",
        description="The same pipeline as the daemon, over captures in order (state carried "
        "across files): corrected NMEA to --out (or stdout), then a summary.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    p.add_argument("--config", required=True, metavar="FILE", help="config file")
    p.add_argument(
        "--state", metavar="FILE", help="load frozen parameters from and persist to FILE"
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--learn",
        dest="learn",
        action="store_true",
        default=None,
        help="learn from the captures (default: each calibration's learn key)",
    )
    g.add_argument(
        "--no-learn",
        dest="learn",
        action="store_false",
        help="do not learn: apply only the parameters loaded with --state",
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument("--speed", type=positive_float, metavar="X", help="pace at X times real time")
    g.add_argument("--fast", action="store_true", help="as fast as possible (default)")
    p.add_argument(
        "--out",
        metavar="FILE",
        help="write the corrected NMEA here; a FILE.cap or FILE.cap.gz name writes a capture "
        "v1 with one port per UUT, each sentence at the time of the sample it corrects",
    )
    _capture_args(p)
    p.add_argument("--json", action="store_true", help="summary as one JSON document")
    p.add_argument(
        "--truth",
        metavar="DIR",
        help="a simulated trial's directory: score the emitted speeds against its true "
        "speed through water",
    )
    p.set_defaults(handler=cmd_replay)
