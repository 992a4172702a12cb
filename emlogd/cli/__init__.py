"""The ``emlogd`` command line: one entry point, one sub-command per job.

``main(argv)`` is embeddable and testable (nothing assigns ``sys.argv``). Exit
codes: 0 success, 1 runtime error (one clear line on stderr, a traceback only
with ``--debug``), 2 usage error. This is the only module allowed to print.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from datetime import date
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from drivers import DecoderOptions, EmlogdError, make_decoder, protocol_names
from drivers.base import Decoder
from emlogd import __version__
from emlogd.jsonio import to_jsonable
from emlogd.offline.dataset import Recording
from emlogd.offline.jobs import (
    CalibrationResult,
    calibrate,
    crossval,
    evaluate,
    load_captures,
    load_params,
    save_params,
)
from emlogd.offline.tables import fmt, render, table2, table3
from emlogd.pipeline.core import UutSettings

if TYPE_CHECKING:
    from calib.models import Params
    from emlogd.offline.simulate import Truth, TruthScore

Handler = Callable[[argparse.Namespace], int]

_SNIFF_CHUNK = 4096


class UsageError(EmlogdError):
    """A command line that parses but makes no sense (exit code 2)."""


# ---------------------------------------------------------------------------- helpers


def _is_tty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _progress(msg: str, fraction: float | None = None) -> None:
    """Progress on stderr, only when stderr is a terminal."""
    if not _is_tty(sys.stderr):
        return
    pct = "" if fraction is None else f" {100.0 * fraction:5.1f} %"
    sys.stderr.write(f"\r{msg}{pct}\x1b[K")
    sys.stderr.flush()


def _progress_done() -> None:
    if _is_tty(sys.stderr):
        sys.stderr.write("\r\x1b[K")
        sys.stderr.flush()


def _decoder_options(args: argparse.Namespace) -> DecoderOptions:
    return DecoderOptions(
        checksum="optional" if getattr(args, "checksum_optional", False) else "required",
        max_length=getattr(args, "max_length", None) or DecoderOptions().max_length,
    )


def _sniff_protocol(path: Path) -> str:
    """Guess the protocol of a raw (non-capture) file from its first bytes."""
    with open(path, "rb") as f:
        head = f.read(_SNIFF_CHUNK)
    if b"\x7f\x7f" in head[:64]:
        return "pd0"
    if head[:1] == b"\x7d":
        return "pd4"
    text = head.lstrip()
    if text[:1] == b":":
        return "pd6"
    if b"$" in head or b"!" in head:
        return "nmea0183"
    raise UsageError(f"{path}: cannot tell the protocol from the content; pass --protocol")


def _is_capture(path: Path) -> bool:
    import gzip

    from drivers.io.capture import MAGIC

    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rb") as f:
            first = f.readline(256)
    except (gzip.BadGzipFile, EOFError):
        return False
    return bool(first.rstrip(b"\r\n") == MAGIC.encode("ascii"))


# ---------------------------------------------------------------------------- dump


def _dump_records(args: argparse.Namespace) -> Iterator[tuple[float | None, str, object]]:
    """Yield (receive time, port, record) for the dump command; fills ``args._decoders``."""
    path = Path(args.file)
    options = _decoder_options(args)
    decoders: dict[str, tuple[str, Decoder]] = {}
    args._decoders = decoders
    if _is_capture(path):
        from drivers.io.capture import CaptureReader

        reader = CaptureReader(path)
        for name, proto in reader.ports.items():
            proto = args.protocol or proto
            decoders[name] = (proto, make_decoder(proto, name, errors="yield", options=options))
        for rec in reader:
            _, dec = decoders[rec.port]
            for out in dec.feed(rec.data):
                yield rec.t, rec.port, out
    else:
        proto = args.protocol or _sniff_protocol(path)
        name = path.stem
        dec = make_decoder(proto, name, errors="yield", options=options)
        decoders[name] = (proto, dec)
        with open(path, "rb") as f:
            while chunk := f.read(65536):
                for out in dec.feed(chunk):
                    yield None, name, out
    for name, (_, dec) in decoders.items():
        for out in dec.flush():
            yield None, name, out


def _format_record(rec: object) -> str:
    d = to_jsonable(rec)
    kind = d.pop("type", type(rec).__name__) if isinstance(d, dict) else type(rec).__name__
    if not isinstance(d, dict):
        return f"{kind} {d}"
    parts = [f"{k}={json.dumps(v, separators=(',', ':'))}" for k, v in d.items() if v is not None]
    return f"{kind} " + " ".join(parts)


def cmd_dump(args: argparse.Namespace) -> int:
    """Decode a capture or a raw log of one protocol; print records and counters."""
    out = sys.stdout
    for t, port, rec in _dump_records(args):
        if args.json:
            line = {"t": t, "port": port, "record": to_jsonable(rec)}
            out.write(json.dumps(line, separators=(",", ":")) + "\n")
        else:
            ts = "-" if t is None else f"{t:.6f}"
            out.write(f"{ts} {port} {_format_record(rec)}\n")
    summary = {
        name: {"protocol": proto, **dec.counters.as_dict()}
        for name, (proto, dec) in args._decoders.items()
    }
    if args.json:
        out.write(json.dumps({"summary": summary}, separators=(",", ":")) + "\n")
    else:
        out.write(_summary_table(summary))
    return 0


def _summary_table(summary: dict[str, dict[str, Any]]) -> str:
    lines = [f"{'port':<12} {'protocol':<9} {'records':>8} {'rejected':>8}  reasons"]
    for name, s in summary.items():
        rejects: dict[str, int] = s["rejects"]
        total = sum(rejects.values())
        reasons = ", ".join(f"{k}={v}" for k, v in rejects.items() if v) or "-"
        lines.append(f"{name:<12} {s['protocol']:<9} {s['records']:>8} {total:>8}  {reasons}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- record


def _parse_port_spec(spec: str) -> tuple[str, str, int, str]:
    """Parse ``NAME=URL[,baud=N][,protocol=P]``."""
    name, sep, rest = spec.partition("=")
    if not sep or not name or not rest:
        raise UsageError(f"--port {spec!r}: expected NAME=URL[,baud=N][,protocol=P]")
    url, *opts = rest.split(",")
    baud, proto = 9600, "nmea0183"
    for opt in opts:
        key, sep, value = opt.partition("=")
        if key == "baud" and sep and value.isdigit():
            baud = int(value)
        elif key == "protocol" and sep and value in protocol_names():
            proto = value
        else:
            raise UsageError(
                f"--port {spec!r}: bad option {opt!r} (baud=N, protocol={'|'.join(protocol_names())})"
            )
    return name, url, baud, proto


def cmd_record(args: argparse.Namespace) -> int:
    """Capture live ports into a capture v1 file until Ctrl-C, SIGTERM or --duration."""
    import selectors

    from drivers import is_binary
    from drivers.io.capture import CaptureWriter
    from drivers.io.port import SerialSource

    specs = [_parse_port_spec(s) for s in args.port]
    names = [s[0] for s in specs]
    if len(set(names)) != len(names):
        raise UsageError("--port names must be unique")
    stop = False

    def _stop(signum: int, frame: FrameType | None) -> None:
        nonlocal stop
        stop = True

    old = signal.signal(signal.SIGTERM, _stop)
    sources = {
        name: SerialSource(name, url, baudrate=baud, stale_timeout_s=args.stale_timeout)
        for name, url, baud, _ in specs
    }
    binary = {name: is_binary(proto) for name, _, _, proto in specs}
    partial: dict[str, bytearray] = {name: bytearray() for name in sources}
    counts = dict.fromkeys(sources, 0)
    sel = selectors.DefaultSelector()
    registered: dict[str, int] = {}
    t_end = None if args.duration is None else time.monotonic() + args.duration
    last_t = 0.0
    try:
        with CaptureWriter(args.out, {n: p for n, _, _, p in specs}) as writer:
            for src in sources.values():
                src.open()
            while not stop and (t_end is None or time.monotonic() < t_end):
                for name, src in sources.items():
                    fd = src.fileno()
                    if registered.get(name) != fd:
                        if name in registered:
                            sel.unregister(registered.pop(name))
                        if fd is not None:
                            sel.register(fd, selectors.EVENT_READ, name)
                            registered[name] = fd
                    for ev in src.poll() + src.events():
                        sys.stderr.write(f"{ev.port}: {ev.kind} {ev.detail}\n")
                try:
                    ready = sel.select(timeout=0.2)
                except KeyboardInterrupt:
                    break
                for key, _ in ready:
                    name = key.data
                    chunk = sources[name].read()
                    if chunk is None:
                        continue
                    t = max(chunk.t, last_t)
                    last_t = t
                    if binary[name]:
                        writer.write_chunk(t, name, chunk.data)
                        counts[name] += 1
                        continue
                    buf = partial[name]
                    buf += chunk.data
                    *lines, rest = bytes(buf).split(b"\n")
                    buf[:] = rest
                    for line in lines:
                        writer.write_line(t, name, line.rstrip(b"\r"))
                        counts[name] += 1
                _progress("recording: " + ", ".join(f"{k}={v}" for k, v in counts.items()))
            for name, buf in partial.items():
                if buf:
                    writer.write_chunk(max(time.time(), last_t), name, bytes(buf))
    finally:
        _progress_done()
        for src in sources.values():
            src.close()
        sel.close()
        signal.signal(signal.SIGTERM, old)
    sys.stderr.write(
        f"wrote {args.out}: " + ", ".join(f"{k} {v} records" for k, v in counts.items()) + "\n"
    )
    return 0


# ---------------------------------------------------------------------------- fake


def cmd_fake(args: argparse.Namespace) -> int:
    """Serve one port of a capture on a pty symlink, like the real device would."""
    from drivers.io.capture import read_ports
    from drivers.io.fake import FakeDevice

    ports = read_ports(args.capture)
    if args.port is None:
        if len(ports) != 1:
            raise UsageError(f"{args.capture} has ports {', '.join(ports)}: choose one with --port")
        port = next(iter(ports))
    elif args.port not in ports:
        raise UsageError(f"{args.capture} has no port {args.port!r} (has {', '.join(ports)})")
    else:
        port = args.port
    speed = None if args.fast else args.speed
    device = FakeDevice(args.capture, port, args.link, speed=speed, loop=args.loop)

    def _stop(signum: int, frame: FrameType | None) -> None:
        device.stop()

    old = signal.signal(signal.SIGTERM, _stop)
    sys.stderr.write(f"serving {port} from {args.capture} on {args.link}\n")
    try:
        device.run()
    except KeyboardInterrupt:
        device.stop()
    finally:
        signal.signal(signal.SIGTERM, old)
    return 0


# ---------------------------------------------------------------------------- simulate


def cmd_simulate(args: argparse.Namespace) -> int:
    """Write the simulated sea trial (five captures, truth.yaml and truth.csv.gz)."""
    from emlogd.offline.simulate import simulate

    if not 0.0 < args.scale <= 10.0:
        raise UsageError(f"--scale must be in (0, 10], not {args.scale}")
    result = simulate(
        args.outdir,
        seed=args.seed,
        scale=args.scale,
        dvl_format=args.dvl_format,
        current=args.current,
        circles=args.circles,
        progress=_progress,
    )
    _progress_done()
    for tr, path in zip(result.trajectories, result.files, strict=True):
        lines = sum(tr.lines.values())
        raw = ", ".join(f"{k} {v:.3f}" for k, v in tr.rmse_raw_mps.items())
        sys.stdout.write(
            f"{path}: {tr.duration_s / 60.0:6.1f} min, {lines:8d} lines, raw RMSE m/s: {raw}\n"
        )
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


# ---------------------------------------------------------------------------- import


def _date_arg(value: str) -> date:
    try:
        return date.fromisoformat(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD, not {value!r}") from None


def cmd_import(args: argparse.Namespace) -> int:
    """Turn NMEA logs or CSV exports into a capture."""
    from emlogd.offline import importer

    if not args.port or not args.port.isidentifier():
        raise UsageError(f"--port must be a name (letters, digits, _), not {args.port!r}")
    if args.format == "nmea":
        for opt in ("map", "preset", "time_format", "heading_ref"):
            if getattr(args, opt) is not None:
                raise UsageError(f"--{opt.replace('_', '-')} applies to --format csv only")
        report = importer.import_nmea(
            args.files, args.out, port=args.port, day=args.date, progress=_progress
        )
    else:
        if args.date is not None:
            raise UsageError("--date applies to --format nmea only")
        if len(args.files) != 1:
            raise UsageError("--format csv imports one file at a time")
        if args.preset is None and args.map is None:
            raise UsageError("--format csv needs --map key=Column,... or --preset expedition")
        mapping = dict(importer.EXPEDITION) if args.preset == "expedition" else {}
        if args.map is not None:
            mapping.update(importer.parse_map(args.map))
        report = importer.import_csv(
            args.files[0],
            args.out,
            mapping,
            time_format=args.time_format or "ole",
            heading_ref=args.heading_ref or "true",
            port=args.port,
            progress=_progress,
        )
    _progress_done()
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
    for k, v in sorted(report.notes.items()):
        sys.stdout.write(f"note         {k} {v}\n")
    return 0


# ---------------------------------------------------------------------------- offline


def _settings(args: argparse.Namespace, **over: Any) -> UutSettings:
    """The UUT of an offline job, as the daemon's settings (defaults from the declarations)."""
    kw: dict[str, Any] = {
        "port": args.uut,
        "reference_port": args.ref,
        "reference_field": args.ref_field or "bottom",
        "uut_source": getattr(args, "uut_source", None) or "VHW",
        "component": "magnitude" if getattr(args, "magnitude", False) else "longitudinal",
        "current": bool(getattr(args, "current", False)),
        "heading": getattr(args, "heading", None) or "auto",
        "magnetic_variation_deg": getattr(args, "variation", None),
    }
    if getattr(args, "model", None):
        kw["model"] = args.model
    kw.update(over)
    try:
        return UutSettings(**kw)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _lag_arg(value: str) -> float | None:
    if value == "auto":
        return None
    try:
        return float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected auto or seconds, not {value!r}") from None


def _load(paths: Sequence[str], settings: UutSettings, args: argparse.Namespace) -> list[Recording]:
    """Read the captures; without ``--uut-source`` a UUT that sends no VHW is read from VBW."""
    recs = load_captures(paths, settings, progress=_progress)
    if not getattr(args, "uut_source", None) and not any(r.raw.size for r in recs):
        recs = load_captures(
            paths, dataclasses.replace(settings, uut_source="VBW"), progress=_progress
        )
    _progress_done()
    return recs


def _calibration_text(res: CalibrationResult) -> str:
    se = res.stderr
    held = set(res.ident.unidentifiable)
    params = "\n".join(
        f"  {k:<2} = {v:+.5f} ± {fmt(se.get(k), '.5f')}"
        + ("   (not determined: held at its prior)" if k in held else "")
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
    if lag.note:
        lag_txt += f"\n  warning: {lag.note}"
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
    out += [
        f"identifiable {'yes' if res.identifiable else 'NO: ' + res.ident.reason}",
        f"condition    {fmt(res.ident.cond_info, '.3g')}",
        f"RMSE raw     {fmt(res.rmse_raw, '.4f')} m/s",
        f"RMSE cal     {fmt(res.rmse_cal, '.4f')} m/s",
        f"improvement  {fmt(res.improvement_pct, '.1f')} %",
    ]
    if res.nis_mean is not None:
        out.append(
            f"NIS          mean {fmt(res.nis_mean, '.2f')}, "
            f"{fmt(100.0 * (res.nis_frac_inside or math.nan), '.1f')} % inside the 95 % bounds"
        )
    return "\n".join(out) + "\n"


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Estimate an error model of one EMlog against a reference from captures."""
    settings = _settings(args)
    recs = _load(args.captures, settings, args)
    if args.average is not None and args.method != "ls":
        raise UsageError("--average applies to --method ls")
    res = calibrate(
        recs, settings, args.method, lag=args.lag, trace=args.trace, average_s=args.average
    )
    if args.save:
        save_params(args.save, res)
    if args.json:
        sys.stdout.write(json.dumps(res.to_dict(), indent=2) + "\n")
    else:
        sys.stdout.write(_calibration_text(res))
        if args.save:
            sys.stdout.write(f"saved        {args.save}\n")
    return 0


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
        }
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
        return 0
    sys.stdout.write(
        f"{cal.params.model} {cal.params.as_dict()} from {args.params}, "
        f"{settings.port} against {settings.reference_port}, lag {lag_s:.2f} s\n"
    )
    sys.stdout.write(
        render(
            ["capture", "samples", "RMSE raw", "RMSE cal", "improv. %"]
            + (["truth: raw", "cal", "floor"] if truth is not None else []),
            [
                [
                    r.capture,
                    str(r.n_samples),
                    fmt(r.rmse_raw, ".4f"),
                    fmt(r.rmse_cal, ".4f"),
                    fmt(r.improvement_pct, ".1f"),
                    *_truth_cells(sc),
                ]
                for r, sc in zip(rows, scores, strict=True)
            ],
        )
    )
    return 0


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


def _truth_cells(score: TruthScore | None) -> list[str]:
    """RMSE against the truth: raw, calibrated or corrected, the floor (m/s)."""
    if score is None:
        return []
    return [
        fmt(score.rmse_raw, ".4f"),
        fmt(score.rmse_corrected, ".4f"),
        fmt(score.rmse_floor, ".4f"),
    ]


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

    def progress(done: int, total: int, what: str) -> None:
        _progress(f"crossval: {what}", done / total)

    result, lag = crossval(recs, settings, lag=args.lag, workers=args.workers, progress=progress)
    _progress_done()
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
        }
        sys.stdout.write(json.dumps(doc) + "\n")
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
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """PNG figures like the paper's (needs the report extra)."""
    from emlogd.offline.report import report

    settings = _settings(args)
    recs = _load(args.captures, settings, args)
    paths = report(recs, settings, args.out, lag=args.lag, progress=_progress)
    _progress_done()
    for path in paths:
        sys.stdout.write(f"{path}\n")
    return 0


# ---------------------------------------------------------------------------- daemon


def _config_path(args: argparse.Namespace) -> str:
    from emlogd.config import DEFAULT_PATH

    return str(getattr(args, "config", None) or DEFAULT_PATH)


def cmd_run(args: argparse.Namespace) -> int:
    """Run the daemon in the foreground (systemd runs it this way)."""
    import structlog

    from emlogd.config import load_config
    from emlogd.daemon.logsetup import configure_logging
    from emlogd.daemon.loop import Daemon

    cfg = load_config(_config_path(args))
    configure_logging(cfg.log_format, cfg.log_level)
    log = structlog.get_logger("emlogd")
    return Daemon(cfg.path, log, state_path=args.state).run()


def cmd_check_config(args: argparse.Namespace) -> int:
    """Validate a config file without starting."""
    from emlogd.config import load_config

    cfg = load_config(args.file)
    ports = ", ".join(f"{p.name} ({p.protocol}, {p.role})" for p in cfg.ports)
    uuts = ", ".join(
        f"{u.uut} {u.model} vs {u.reference} ({u.reference_field})" for u in cfg.calibration
    )
    sys.stdout.write(f"{args.file}: ok\n  ports: {ports}\n  calibration: {uuts or 'none'}\n")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """Run the daemon's pipeline over captures; write the corrected NMEA; print a summary."""
    import dataclasses

    from emlogd.config import load_config
    from emlogd.daemon.statefile import StateStore
    from emlogd.offline.replay import replay
    from emlogd.pipeline.calibration import Calibration, checker
    from emlogd.pipeline.core import Output, Pipeline
    from emlogd.settings import pipeline_from_config

    cfg = load_config(args.config)
    ports, uuts = pipeline_from_config(cfg)
    truth = _truth(args, [u.port for u in uuts])
    if args.learn is not None:
        uuts = [dataclasses.replace(u, learn=args.learn) for u in uuts]
    store = StateStore(args.state) if args.state else None
    cals: dict[str, Calibration] = {}
    if store is not None:
        cals, report = store.load(check=checker(uuts))
        for line in report:
            sys.stderr.write(f"emlogd replay: {line}\n")
    pipeline = Pipeline(ports, uuts, cals)

    def persist(_: Output) -> None:
        if store is not None:
            store.save({c.uut: c for c in pipeline.calibrations()})

    to_stdout = args.out is None and not args.json
    sink = open(args.out, "wb") if args.out else (sys.stdout.buffer if to_stdout else None)  # noqa: SIM115
    try:
        result = replay(
            pipeline,
            args.captures,
            sink=sink,
            speed=None if args.fast or args.speed is None else args.speed,
            on_persist=persist,
            progress=_progress,
            truth=truth,
        )
    finally:
        _progress_done()
        if args.out and sink is not None:
            sink.close()
    if store is not None:
        persist(Output())
    doc = result.to_dict()
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
            + (["truth: raw", "corr.", "floor"] if truth is not None else []),
            rows,
            left=3,
        )
    )
    out.write(
        f"{result.records} records in {result.elapsed_s:.1f} s "
        f"({result.span_s / max(result.elapsed_s, 1e-9):.0f}x real time), "
        f"{result.emitted} sentences emitted, {result.persisted} persists\n"
    )
    return 0


def _socket_path(args: argparse.Namespace) -> str:
    if args.socket:
        return str(args.socket)
    from emlogd.config import load_config

    return load_config(_config_path(args)).control_socket


def cmd_control(args: argparse.Namespace) -> int:
    """status / freeze / learn / reset through the daemon's control socket."""
    from emlogd.daemon.control import request

    req: dict[str, object] = {"cmd": args.command}
    if getattr(args, "uut", None):
        req["port"] = args.uut
    if args.command == "learn":
        req["on"] = args.state == "on"
    resp = request(_socket_path(args), req)
    if not resp.get("ok"):
        raise EmlogdError(f"the daemon refused: {resp.get('error')}")
    if args.command == "status" and not args.json:
        status = resp.get("status", {})
        assert isinstance(status, dict)
        for name, u in status.get("uuts", {}).items():
            params = ", ".join(f"{k}={v:+.4f}" for k, v in (u.get("params") or {}).items())
            sys.stdout.write(
                f"{name}: {u['state']}, reference {u['reference']}, {u['model']} "
                f"{params or '(no calibration)'}, lag {fmt(u.get('lag_s'), '.2f')} s, "
                f"learning {'on' if u['learning_enabled'] else 'off'}\n"
            )
        for name, p in status.get("ports", {}).items():
            rejects = sum(p["rejects"].values())
            sys.stdout.write(
                f"port {name}: {p['records']} records, {rejects} rejects"
                f"{', STALE' if p['stale'] else ''}\n"
            )
        return 0
    sys.stdout.write(json.dumps(resp, indent=2, default=str) + "\n")
    return 0


# ---------------------------------------------------------------------------- demo


def cmd_demo(args: argparse.Namespace) -> int:
    """The real daemon calibrating the bundled example live (fake devices on ptys)."""
    from emlogd.offline.demo import run_demo

    if not 1.0 <= args.speed <= 50.0:
        raise UsageError("--speed must be within 1..50")
    run_demo(speed=args.speed, workdir=args.workdir)
    return 0


# ---------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (exposed for tests and documentation)."""
    parser = argparse.ArgumentParser(
        prog="emlogd",
        description="EMlog calibration daemon and offline tools.",
    )
    parser.add_argument("--version", action="version", version=f"emlogd {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show tracebacks instead of one-line errors"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser(
        "dump",
        help="decode a capture or a raw log of one protocol",
        description="Decode a capture (port protocols from its header) or a raw log/binary "
        "file of one protocol. Prints one line per record (JSON lines with --json), "
        "then counters per port and reject reason.",
    )
    p.add_argument("file", help="capture v1 file, or a raw NMEA/PD6 log or PD0/PD4/PD5 binary")
    p.add_argument(
        "--protocol",
        choices=protocol_names(),
        help="protocol of a raw file (guessed from its content if omitted)",
    )
    p.add_argument("--json", action="store_true", help="JSON lines, then a summary object")
    p.add_argument(
        "--checksum-optional",
        action="store_true",
        help="accept NMEA sentences without *hh (a wrong checksum is still rejected)",
    )
    p.add_argument(
        "--max-length",
        type=int,
        metavar="N",
        help="longest accepted text line incl. CR LF (default 82, the NMEA limit)",
    )
    p.set_defaults(handler=cmd_dump)

    p = sub.add_parser(
        "record",
        help="capture live serial ports into a capture file",
        description="Capture live ports (any pyserial URL: /dev/ttyUSB0, loop://, "
        "socket://host:port, spy://...) into a capture v1 file until Ctrl-C or SIGTERM.",
    )
    p.add_argument(
        "--port",
        action="append",
        required=True,
        metavar="NAME=URL[,baud=N][,protocol=P]",
        help="a port to record (repeat for several); protocol defaults to nmea0183",
    )
    p.add_argument("--out", required=True, metavar="FILE.cap", help="capture file to write")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--stale-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="report a port silent for S seconds (default 5)",
    )
    p.set_defaults(handler=cmd_record)

    p = sub.add_parser(
        "fake",
        help="serve a capture's port on a pty symlink (fake serial device)",
        description="Replay one port of a capture into a pseudo-terminal published at --link, "
        "with the original timing, scaled (--speed X) or as fast as possible (--fast).",
    )
    p.add_argument("capture", help="capture v1 file")
    p.add_argument("--link", required=True, metavar="PATH", help="symlink to the pty slave")
    p.add_argument("--port", help="port of the capture to serve (needed if it has several)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--speed", type=float, default=1.0, metavar="X", help="X times real time")
    g.add_argument("--fast", action="store_true", help="as fast as the reader takes it")
    p.add_argument("--loop", action="store_true", help="start again at the end")
    p.set_defaults(handler=cmd_fake)

    p = sub.add_parser(
        "demo",
        help="the daemon calibrating the bundled example, live (about 40 s)",
        description="Serve the bundled example (a simulated figure-8) from three fake serial "
        "devices on ptys, run the real daemon against them, read its corrected NMEA, show the "
        "calibration converging and the error before and after.",
    )
    p.add_argument("--speed", type=float, default=10.0, help="replay speed (default 10x)")
    p.add_argument("--workdir", metavar="DIR", help="keep config, ptys, log and state here")
    p.set_defaults(handler=cmd_demo)

    p = sub.add_parser(
        "simulate",
        help="write a simulated sea trial (five captures and the truth)",
        description="Simulate the paper's sea trial: 1-transit, 2-figure8, 3-straight, "
        "4-circles, 5-return as capture v1 files in OUTDIR (ports emlog1, emlog2, dvl, "
        "gnss), plus truth.yaml and the truth per sample in truth.csv.gz.",
    )
    p.add_argument("outdir", help="output directory (created if missing)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("--scale", type=float, default=1.0, help="duration factor (0.1: 10 %% as long)")
    p.add_argument(
        "--dvl-format", choices=["pd6", "pd0"], default="pd6", help="DVL output (default pd6)"
    )
    p.add_argument(
        "--current",
        type=_current_arg,
        metavar="N,E",
        help="a constant sea current, m/s north and east (default: a slowly varying one)",
    )
    p.add_argument(
        "--circles",
        choices=["steps", "constant"],
        default="steps",
        help="the circles at three throttle settings (default) or at one constant speed",
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
        help="csv: columns for time, stw, heading, sog, cog (and lat, lon, set, drift, "
        "variation); knots and degrees unless written Col[mps]",
    )
    p.add_argument("--preset", choices=["expedition"], help="csv: a known program's columns")
    p.add_argument(
        "--time-format", choices=["ole", "iso", "epoch"], help="csv: time column (default ole)"
    )
    p.add_argument(
        "--heading-ref", choices=["true", "magnetic"], help="csv: the heading's reference (true)"
    )
    p.add_argument("--json", action="store_true", help="the import report as JSON")
    p.set_defaults(handler=cmd_import)

    def pairing_args(p: argparse.ArgumentParser, required: bool = True) -> None:
        p.add_argument("--uut", required=required, metavar="PORT", help="EMlog port to calibrate")
        p.add_argument("--ref", required=required, metavar="PORT", help="reference port")
        p.add_argument(
            "--ref-field",
            choices=["bottom", "water", "speed", "gnss"],
            default="bottom" if required else None,
            help="reference: DVL bottom track (default), DVL water track, an EMlog's speed, "
            "or GNSS speed and course (RMC/VTG) projected on the hull with the heading",
        )

    def water_frame(p: argparse.ArgumentParser) -> None:
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
            type=float,
            metavar="DEG",
            help="magnetic variation, + east, for magnetic headings without one",
        )

    def common_offline(p: argparse.ArgumentParser) -> None:
        water_frame(p)
        p.add_argument("--uut-source", choices=["VHW", "VBW"], help="UUT sentence (default VHW)")
        p.add_argument(
            "--magnitude",
            action="store_true",
            help="compare horizontal speed magnitudes instead of longitudinal speeds",
        )
        p.add_argument(
            "--lag",
            type=_lag_arg,
            default=None,
            metavar="auto|SECONDS",
            help="UUT latency (default auto: cross-correlation)",
        )
        p.add_argument("--json", action="store_true", help="one JSON document (README keys)")

    p = sub.add_parser(
        "calibrate",
        help="fit an error model of one EMlog against a reference",
        description="Estimate the lag, fit EM1..EM4 by least squares or the Kalman filter, "
        "print parameters ± standard errors, identifiability, RMSE raw and calibrated.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    pairing_args(p)
    p.add_argument("--model", choices=["EM1", "EM2", "EM3", "EM4"], default="EM3")
    p.add_argument("--method", choices=["ls", "kf"], default="ls")
    p.add_argument("--save", metavar="PARAMS.yaml", help="write the calibration file")
    p.add_argument(
        "--trace",
        metavar="FILE.csv",
        help="with --method kf: one CSV row per sample (parameters, current, σ, NIS, state)",
    )
    p.add_argument(
        "--average",
        type=float,
        metavar="SECONDS",
        help="with --method ls: fit block means over SECONDS (default 20 for a gnss "
        "reference, whose noise would shrink the scale; else 0: every sample)",
    )
    common_offline(p)
    p.set_defaults(handler=cmd_calibrate)

    p = sub.add_parser(
        "evaluate",
        help="apply frozen parameters to captures",
        description="Apply a parameters file (calibrate --save) to captures: RMSE raw, "
        "calibrated and the improvement per capture.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    p.add_argument("--params", required=True, metavar="PARAMS.yaml", help="parameters file")
    pairing_args(p, required=False)
    water_frame(p)
    p.add_argument("--uut-source", choices=["VHW", "VBW"], help="UUT sentence (default VHW)")
    p.add_argument(
        "--lag", type=float, default=None, metavar="SECONDS", help="override the saved lag"
    )
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
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.set_defaults(handler=cmd_crossval)

    p = sub.add_parser(
        "report",
        help="PNG figures like the paper's (extra: emlogd[report])",
        description="Write figures to --out: speeds raw/calibrated/reference, KF convergence "
        "sleeve (±3σ), NIS with χ² bounds, the track map, cross-validation heat maps.",
    )
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help="capture v1 files")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    pairing_args(p)
    p.add_argument("--model", choices=["EM1", "EM2", "EM3", "EM4"], default="EM3")
    common_offline(p)
    p.set_defaults(handler=cmd_report)

    p = sub.add_parser(
        "run",
        help="run the daemon (foreground; systemd Type=notify)",
        description="Read the sensors, learn the calibration, emit corrected NMEA.",
    )
    p.add_argument("--config", metavar="FILE", help="config file (default /etc/emlogd/emlogd.yaml)")
    p.add_argument("--state", metavar="FILE", help="override the config's state file")
    p.set_defaults(handler=cmd_run)

    p = sub.add_parser("check-config", help="validate a config file without starting")
    p.add_argument("file", help="config file")
    p.set_defaults(handler=cmd_check_config)

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
    g.add_argument("--learn", dest="learn", action="store_true", default=None, help="learn")
    g.add_argument("--no-learn", dest="learn", action="store_false", help="frozen parameters only")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--speed", type=float, metavar="X", help="pace at X times real time")
    g.add_argument("--fast", action="store_true", help="as fast as possible (default)")
    p.add_argument("--out", metavar="FILE", help="write the corrected NMEA here")
    p.add_argument("--json", action="store_true", help="summary as one JSON document")
    p.add_argument(
        "--truth",
        metavar="DIR",
        help="a simulated trial's directory: score the emitted speeds against its true "
        "speed through water",
    )
    p.set_defaults(handler=cmd_replay)

    for name, text in (
        ("status", "show the running daemon's calibration and ports"),
        ("freeze", "stop learning (all UUTs or --uut) and persist"),
        ("reset", "forget the calibration (all UUTs or --uut)"),
        ("learn", "switch learning on or off"),
    ):
        p = sub.add_parser(name, help=text, description=text + " (through the control socket).")
        if name == "learn":
            p.add_argument("state", choices=["on", "off"])
        p.add_argument("--uut", metavar="PORT", help="one UUT only")
        p.add_argument("--config", metavar="FILE", help="config file naming the control socket")
        p.add_argument("--socket", metavar="PATH", help="control socket path")
        p.add_argument("--json", action="store_true", help="raw JSON answer")
        p.set_defaults(handler=cmd_control)

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else 2
    handler: Handler = args.handler
    try:
        return handler(args)
    except UsageError as exc:
        if args.debug:
            raise
        sys.stderr.write(f"emlogd {args.command}: {exc}\n")
        return 2
    except (EmlogdError, OSError) as exc:
        if args.debug:
            raise
        if isinstance(exc, BrokenPipeError):
            return 0
        sys.stderr.write(f"emlogd {args.command}: error: {exc}\n")
        return 1
    except KeyboardInterrupt:
        _progress_done()
        return 130
    finally:
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            # the reader went away (emlogd dump | head): silence the interpreter's own complaint
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
