"""``emlogd simulate``: the simulated sea trial as captures and its truth."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, get_args

from emlogd.cli.common import Subparsers, UsageError, progress, progress_done
from emlogd.offline.simkinematics import CirclesMode
from emlogd.offline.simsensors import DvlFormat

if TYPE_CHECKING:
    from emlogd.offline.simulate import TrajectoryTruth


def cmd_simulate(args: argparse.Namespace) -> int:
    """Write the simulated sea trial (five captures, truth.yaml and truth.csv.gz)."""
    from emlogd.offline.simulate import EMLOG1, EMLOG2, MIN_SCALE, simulate, with_sensor

    if not MIN_SCALE <= args.scale <= 10.0:
        raise UsageError(f"--scale must be in [{MIN_SCALE:g}, 10], not {args.scale}")
    if args.seed < 0:
        raise UsageError(f"--seed must be 0 or more, not {args.seed}")
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


def add_parser(sub: Subparsers) -> None:
    """The ``simulate`` sub-command."""
    p = sub.add_parser(
        "simulate",
        help="write a simulated sea trial (five captures and the truth)",
        description="Simulate the paper's sea trial: 1-transit, 2-figure8, 3-straight, "
        "4-circles, 5-return as capture v1 files in OUTDIR (ports emlog1, emlog2, dvl, "
        "gnss), plus truth.yaml and the truth per sample in truth.csv.gz.",
    )
    p.add_argument("outdir", help="output directory (created if missing)")
    p.add_argument("--seed", type=int, default=1, help="random seed, 0 or more (default 1)")
    p.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="duration factor in [0.005, 10] (default 1; 0.1: 10 %% as long)",
    )
    p.add_argument(
        "--dvl-format", choices=get_args(DvlFormat), default="pd6", help="DVL output (default pd6)"
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
        choices=get_args(CirclesMode),
        default="steps",
        help="the circles at three throttle settings (default) or at one constant speed",
    )
    p.add_argument(
        "--sensor",
        type=_sensor_arg,
        action="append",
        metavar="PORT:KEY=V,...",
        help="another EMlog: PORT emlog1 or emlog2, KEY a (s/m), m, b (m/s) of its EM4 "
        "error model, latency (s), noise (m/s, 1σ), misalign (degrees, + the sensor's "
        "forward axis to starboard), mt, bt (m/s) the transverse scale and bias of "
        "emlog2's VBW (mt: m unless given); the values not given keep their "
        "defaults (truth.yaml lists every sensor's); repeatable",
    )
    p.set_defaults(handler=cmd_simulate)
