"""``emlogd replay``: the daemon's pipeline over captures."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from emlogd.cli.common import Subparsers, positive_float, progress, progress_done, two_axis_line
from emlogd.cli.offline.args import capture_args, captures_arg, json_arg, truth_arg
from emlogd.cli.offline.shared import truth_cells, truth_of, warn_internal, warn_skips
from emlogd.offline.tables import fmt, render

if TYPE_CHECKING:
    from emlogd.pipeline.core import Emit, Pipeline


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


class _Out:
    """Where ``replay`` writes its sentences: ``--out`` (a capture for a ``.cap`` or
    ``.cap.gz`` name), else stdout unless ``--json``.

    A file ``--out`` is written beside it (:func:`~emlogd.fileio.part_path`) and renamed
    into place once the replay has run, so a reader (another command, another run's
    scores) never sees it half-written, and a replay that fails leaves the old file; a
    device or a pipe is written as it is."""

    def __init__(
        self, path: str | None, uuts: Sequence[str], pipeline: Pipeline, to_stdout: bool
    ) -> None:
        from emlogd.fileio import part_path

        self.path = path
        self.part = part_path(path) if path and _file_or_none(path) else None
        target = str(self.part) if self.part is not None else path
        as_capture = bool(path) and str(path).endswith((".cap", ".cap.gz"))
        try:
            self.capture = (
                _EmitCapture(str(target), uuts, pipeline) if target and as_capture else None
            )
            self.sink: BinaryIO | None = (
                open(target, "wb")  # noqa: SIM115
                if target and not as_capture
                else (sys.stdout.buffer if to_stdout else None)
            )
        except OSError as exc:  # named by --out, not by the part file
            raise OSError(exc.errno, exc.strerror, path) from None

    def close(self, done: bool) -> None:
        """Close what was written; in place if ``done``, else the part file removed."""
        if self.path and self.sink is not None:
            self.sink.close()
        if self.capture is not None:
            self.capture.close()
        if self.part is not None and self.path:
            if done:
                self.part.replace(self.path)
            else:
                self.part.unlink(missing_ok=True)


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
    truth = truth_of(args, [u.port for u in uuts])
    store = StateStore(args.state, uuts=len(uuts)) if args.state else None
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
    out_file = _Out(args.out, [u.port for u in uuts], pipeline, to_stdout)
    done = False
    try:
        result = replay(
            pipeline,
            args.captures,
            sink=out_file.sink,
            on_emit=out_file.capture.write if out_file.capture is not None else None,
            speed=None if args.fast or args.speed is None else args.speed,
            on_persist=persist,
            progress=progress,
            strict=args.strict,
            reorder_window_s=args.reorder_window,
            truth=truth,
        )
        done = True
    finally:
        progress_done()
        out_file.close(done)
    if store is not None:
        persist(Output())
    doc = result.to_dict()
    for line in other_sentences_only(pipeline, args.config):
        sys.stderr.write(f"emlogd replay: warning: {line}\n")
    warn_skips(args.command, result.capture_skips)
    warn_internal(args.command, "replay", result.internal)
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
                *truth_cells(result.truth.get(name)),
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
    out.write("".join(_two_axis_lines(uut_docs)))
    out.write(
        f"{result.records} records in {result.elapsed_s:.1f} s "
        f"({result.span_s / max(result.elapsed_s, 1e-9):.0f}x real time), "
        f"{result.emitted} sentences emitted"
        + (f", {result.persisted} persists to {args.state}" if store is not None else "")
        + "\n"
    )
    return 0


def other_sentences_only(pipeline: Pipeline, config: str) -> list[str]:
    """Per UUT that sent no speed reading at all, or whose configured sentence
    (``uut_source``) never arrived while another of its speed sentences did: why nothing
    was learnt, and the key that helps (a log sending VBW alone replayed with the
    default VHW learns nothing)."""
    out = []
    for name, u in pipeline.uuts.items():
        seen = sorted(set(u.checks) - {u.s.uut_source})
        oor, late = u.cal.counters.out_of_range, u.cal.counters.backlog
        if not u.checks and not late:
            why = f"all {oor} outside the log's range" if oor else "none decoded"
            out.append(
                f"{name}: no speed reading of the log (VHW, VBW) to use ({why}): nothing "
                "was learnt or corrected"
            )
        elif seen and u.s.uut_source not in u.checks:
            out.append(
                f"{name}: no {u.s.uut_source} reading arrived, only {', '.join(seen)}: nothing "
                f"was learnt from them (set calibration[].uut_source: {seen[0]} in {config})"
            )
    return out


def _file_or_none(path: str) -> bool:
    """Whether ``path`` is a regular file or nothing yet (not a device, a pipe, a folder)."""
    p = Path(path)
    return p.is_file() or not p.exists()


def _two_axis_lines(uuts: dict[str, dict[str, object]]) -> list[str]:
    """A line per UUT that learns two axes (``axes: 2``): its figures."""
    found = ((name, u.get("two_axis")) for name, u in uuts.items())
    return [f"{name} {two_axis_line(two)}\n" for name, two in found if isinstance(two, dict)]


def add_parser(sub: Subparsers) -> None:
    """The ``replay`` sub-command."""
    p = sub.add_parser(
        "replay",
        help="run the daemon's pipeline over captures",
        description="The same pipeline as the daemon, over captures in order (state carried "
        "across files): corrected NMEA to --out (or stdout), then a summary.",
    )
    captures_arg(p)
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
    capture_args(p)
    json_arg(p, "summary as one JSON document")
    truth_arg(p, "the emitted speeds")
    p.set_defaults(handler=cmd_replay)
