"""Benchmark: replay throughput of the daemon's pipeline against a parsing anchor.

Runs the full-scale simulated trial (about 1.0 M lines, 221 min) through the same
:class:`emlogd.pipeline.core.Pipeline` that ``emlogd replay --fast`` drives (decode →
align → filter → encode, records already in memory), and times in the same run an
anchor doing the least any NMEA tool does with the same bytes: ``pynmea2.parse(line,
check=True)`` on every NMEA line plus split-and-convert (``float``/``int`` of every
field) of every PD6 line. Also times the whole ``emlogd replay`` command, which adds
reading the 58 MB of capture files and starting Python, and those two apart.

Targets (issue 6): ≥ 1000× real time and ≤ 1.3× the anchor. Prints figures only.

Run: ``python bench/bench_replay.py [--outdir DIR] [--scale 1.0] [--cpu]``
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import pynmea2

from drivers.io.capture import CaptureReader
from emlogd.config import load_config
from emlogd.offline.replay import TICK_S
from emlogd.offline.simulate import simulate
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "emlogd.yaml"
"""The config replayed by default (``--config``: another tree's own, to time that tree
through ``PYTHONPATH`` with this script)."""


CLOCK = [time.perf_counter]
"""The clock of the pipeline, anchor and decoding timings: wall time, or with ``--cpu``
this process's CPU time (on a machine shared with other work, wall time measures the
others' load as much as the code)."""


def _anchor(records: list[tuple[float, str, bytes]]) -> float:
    t0 = CLOCK[0]()
    for _, port, data in records:
        for line in data.split(b"\r\n"):
            if not line:
                continue
            if port == "dvl":
                fields = line.decode("ascii", "replace").split(",")
                for f in fields[1:]:
                    f = f.strip()
                    try:
                        int(f)
                    except ValueError:
                        try:  # noqa: SIM105 - try/except is cheaper: keep the anchor lean
                            float(f)
                        except ValueError:
                            pass
            else:
                try:  # noqa: SIM105 - as above
                    pynmea2.parse(line.decode("ascii", "replace"), check=True)
                except pynmea2.ParseError:
                    pass
    return CLOCK[0]() - t0


def _pipeline(
    records: list[tuple[float, str, bytes]], config: Path = CONFIG
) -> tuple[float, Pipeline]:
    cfg = load_config(config)
    ports, uuts = pipeline_from_config(cfg)
    p = Pipeline(ports, uuts)
    sink: list[bytes] = []
    t0 = CLOCK[0]()
    t_tick = -1e18
    for t, port, data in records:
        out = p.feed(t, port, data)
        if out.emits:
            sink.append(b"".join(e.sentence.encode() + b"\r\n" for e in out.emits))
        if t - t_tick >= TICK_S:  # as emlogd.offline.replay does
            t_tick = t
            p.tick(t)
    return CLOCK[0]() - t0, p


def _decode_only(records: list[tuple[float, str, bytes]], config: Path = CONFIG) -> float:
    """The decoders alone (framing, validation, records, speed records), same config."""
    cfg = load_config(config)
    ports, uuts = pipeline_from_config(cfg)
    decoders = Pipeline(ports, uuts).decoders
    t0 = CLOCK[0]()
    for _, port, data in records:
        dec = decoders.get(port)
        if dec is None:
            continue  # a port the config does not read (the simulated GNSS)
        for rec in dec.feed(data):
            dec.speed_records(rec)
    return CLOCK[0]() - t0


def _profile(records: list[tuple[float, str, bytes]]) -> None:
    """cProfile of :func:`_pipeline` over one capture: the functions by cumulative time."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.runcall(_pipeline, records)
    pstats.Stats(prof).sort_stats("cumulative").print_stats(30)


PARTS = (
    ("emlogd.pipeline.uut", "UutCalibration", "learn", "learning one reading (all of it)"),
    ("emlogd.pipeline.learner", "Learner", "align", "  alignment (lag, reference, heading)"),
    ("emlogd.pipeline.learner", "Learner", "_lag_step", "    lag search"),
    ("emlogd.pipeline.learner", "Learner", "step", "  learner step"),
    ("calib.kalman.filters", "KfCalibrator", "update", "    Kalman filter steps"),
    ("emlogd.pipeline.learner", "Learner", "_judge", "    identifiability (both bounds)"),
    ("emlogd.pipeline.learner", "Learner", "_envelope", "    envelope check"),
    ("emlogd.pipeline.supervisor", "Supervisor", "observe", "  supervision (all of it)"),
    ("emlogd.pipeline.evidence", "Drift", "add", "    drift"),
    ("emlogd.pipeline.supervisor", "Supervisor", "_detect", "    change detection"),
    ("emlogd.pipeline.supervisor", "Supervisor", "_propose", "    proposals"),
    ("emlogd.pipeline.supervisor", "Supervisor", "_recheck", "    re-check"),
)
"""The calls :func:`_parts` times: module, class, method, label (indented under the
call it is made from)."""


def part_methods() -> list[tuple[type, str, str]]:
    """Each of :data:`PARTS` as (class, method name, label); raises AttributeError when a
    method is gone (a renamed step must be renamed here too)."""
    import importlib

    found = []
    for module, cls_name, name, label in PARTS:
        cls = getattr(importlib.import_module(module), cls_name)
        if not callable(getattr(cls, name)):
            raise AttributeError(f"{cls_name}.{name} is not a method")
        found.append((cls, name, label))
    return found


def _parts(records: list[tuple[float, str, bytes]]) -> dict[str, float]:
    """Seconds inside the main learning calls over one pipeline run (each call timed
    with :data:`CLOCK`; the timing adds about 1 µs a call to the total); printed, and
    returned by label. The methods are restored afterwards."""
    spent: dict[str, float] = {}
    calls: dict[str, int] = {}

    def timed(fn: Callable[..., object], label: str) -> Callable[..., object]:
        def wrapper(*args: object, **kwargs: object) -> object:
            clock = CLOCK[0]
            t0 = clock()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[label] = spent.get(label, 0.0) + clock() - t0
                calls[label] = calls.get(label, 0) + 1

        return wrapper

    methods = part_methods()
    saved = [(cls, name, cls.__dict__.get(name)) for cls, name, _ in methods]
    try:
        for cls, name, label in methods:
            setattr(cls, name, timed(getattr(cls, name), label))
        total, _ = _pipeline(records)
    finally:
        for cls, name, fn in saved:
            if fn is None:
                delattr(cls, name)  # an inherited method: the wrapper goes
            else:
                setattr(cls, name, fn)
    print(f"pipeline with the calls timed: {total:.2f} s; decoding alone: "
          f"{min(_decode_only(records) for _ in range(2)):.2f} s")  # fmt: skip
    for _, _, label in methods:
        n = calls.get(label, 0)
        per = 1e6 * spent.get(label, 0.0) / n if n else 0.0
        print(f"  {label:40s} {spent.get(label, 0.0):6.2f} s  {n:8d} calls  {per:7.1f} µs/call")
    return spent


def main() -> None:
    """Generate (or reuse) the trial, time pipeline and anchor, print figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--outdir", help="existing or new trial directory")
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--config", type=Path, default=CONFIG, help="the config to replay")
    ap.add_argument(
        "--profile",
        action="store_true",
        help="instead: profile the pipeline over the figure-8 and print where the time goes",
    )
    ap.add_argument(
        "--parts",
        action="store_true",
        help="instead: time the learning calls over the full trial (seconds in each)",
    )
    ap.add_argument(
        "--cpu",
        action="store_true",
        help="time the pipeline, anchor and decoding in process CPU time instead of wall time",
    )
    args = ap.parse_args()
    if args.cpu:
        CLOCK[0] = time.process_time
    outdir = Path(args.outdir or tempfile.mkdtemp(prefix="emlogd-bench-"))
    files = sorted(outdir.glob("[1-5]-*.cap"))
    if len(files) != 5:
        files = list(simulate(outdir, seed=1, scale=args.scale).files)
    if args.profile:
        _profile([(t, port, data) for t, port, data, _ in CaptureReader(files[1]).received()])
        return
    t_read = time.perf_counter()
    records: list[tuple[float, str, bytes]] = []
    span = 0.0
    for f in files:
        first = len(records)
        records += [(t, port, data) for t, port, data, _ in CaptureReader(f).received()]
        span += records[-1][0] - records[first][0]
    t_read = time.perf_counter() - t_read
    if args.parts:
        _parts(records)
        return
    n_lines = sum(d.count(b"\n") for _, _, d in records)
    print(
        f"trial: {len(files)} captures, {len(records)} records, {n_lines} lines, {span / 60:.1f} min"
    )
    best_p = best_a = best_d = float("inf")
    pipe = None
    for _ in range(3):
        tp, pipe = _pipeline(records, args.config)
        ta = _anchor(records)
        td = _decode_only(records, args.config)
        best_p, best_a, best_d = min(best_p, tp), min(best_a, ta), min(best_d, td)
    assert pipe is not None
    print(
        f"pipeline (decode+align+KF+encode): {best_p:6.2f} s  {n_lines / best_p:9.0f} lines/s  "
        f"{span / best_p:7.0f}x real time  (target >= 1000x)"
    )
    print(
        f"anchor (pynmea2.parse check=True + PD6 split/convert): {best_a:6.2f} s  "
        f"{n_lines / best_a:9.0f} lines/s"
    )
    print(f"pipeline / anchor: {best_p / best_a:.2f}  (target <= 1.3)")
    print(
        f"  of which decoding alone: {best_d:6.2f} s = {best_d / best_a:.2f}x the anchor; "
        f"the rest (align, filter, supervise, encode): {best_p - best_d:6.2f} s = "
        f"{(best_p - best_d) / best_a:.2f}x the anchor"
    )
    uuts = pipe.status()["uuts"]
    assert isinstance(uuts, dict)
    for name, u in uuts.items():
        print(f"  {name}: {u['state']}, rmse raw {u['rmse_raw']}, corrected {u['rmse_corrected']}")
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "emlogd", "replay", *map(str, files), "--config",
         str(args.config), "--json"],
        check=True, stdout=subprocess.DEVNULL,
    )  # fmt: skip
    wall = time.perf_counter() - t0
    print(
        f"emlogd replay --fast (whole command, reading the captures): {wall:.2f} s, "
        f"{span / wall:.0f}x real time"
    )
    t_start = min(_start_up() for _ in range(3))
    print(
        f"  of which reading the captures (CaptureReader.received, into a list): {t_read:.2f} s; "
        f"starting Python and importing the command's modules: {t_start:.2f} s"
    )


def _start_up() -> float:
    """Wall time of a Python that imports what ``emlogd replay`` runs, and exits."""
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-c", "import emlogd.cli, emlogd.offline.replay, emlogd.pipeline.core"],
        check=True,
    )
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
