"""Benchmark: the per-sample windows and the config load of several trees, side by side.

Times, in a fresh process per tree (``PYTHONPATH`` at that tree), in thread CPU time:

- ``SampleRing.add`` with ``cadence=True`` (every reference and heading sample: the
  median of its last intervals gives the alignment gap);
- ``ReadingCheck.check`` (every UUT reading: the median of its last intervals gives the
  log's nominal rate);
- ``load_config`` of the tree's ``examples/emlogd.yaml``, the first call in the process
  and a second one, with how often the installed entry points were scanned (counted
  after the imports).

The readings are at 10 Hz with a 5 ms jitter, the same series for every tree. The
trees run in turn, ``--rounds`` times, so a shift of the machine's load falls on all of
them; compare the ratios of one round. Prints figures only.

Run: ``python bench/bench_hotspots.py TREE [TREE ...] [--samples 100000] [--rounds 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, random, sys, time
tree, n = sys.argv[1], int(sys.argv[2])
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.readings import ReadingCheck, ReadingLimits
from emlogd.config import load_config
import drivers

rng = random.Random(1)
ts, t = [], 0.0
for _ in range(n):
    t += 0.1 + rng.gauss(0.0, 0.005)
    ts.append(t)

def best(f, reps=5):
    b = float("inf")
    for _ in range(reps):
        t0 = time.thread_time_ns()
        f()
        b = min(b, time.thread_time_ns() - t0)
    return b / n / 1e3

def ring():
    r = SampleRing(64, cadence=True)
    for x in ts:
        r.add(x, 1.0)

def check():
    c = ReadingCheck(ReadingLimits())
    for x in ts:
        c.check(x, 2.0)

scans = [0]
real = drivers.entry_points
def counting(**kw):
    scans[0] += 1
    return real(**kw)
drivers.entry_points = counting
cfg = tree + "/examples/emlogd.yaml"
t0 = time.thread_time_ns(); load_config(cfg); t1 = time.thread_time_ns()
load_config(cfg); t2 = time.thread_time_ns()
print(json.dumps({
    "ring_us": best(ring), "check_us": best(check),
    "load1_ms": (t1 - t0) / 1e6, "load2_ms": (t2 - t1) / 1e6, "scans": scans[0],
}))
"""


def one(tree: Path, samples: int) -> dict[str, float]:
    """One tree's figures, from a fresh process with ``PYTHONPATH`` at that tree."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(tree), str(samples)],
        env=env,
        cwd=tree,  # ``-c`` puts the working directory first on the path
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    fig: dict[str, float] = json.loads(out.splitlines()[-1])
    return fig


def main() -> None:
    """Run the trees in turn and print their figures and the ratios to the first."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("trees", nargs="+", type=Path, help="source trees (the first: the baseline)")
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    trees = [t.resolve() for t in args.trees]
    for r in range(args.rounds):
        figs = [one(t, args.samples) for t in trees]
        base = figs[0]
        for tree, f in zip(trees, figs, strict=True):
            print(
                f"round {r + 1} {tree.name}: SampleRing.add {f['ring_us']:.2f} us "
                f"({f['ring_us'] / base['ring_us']:.2f}x), ReadingCheck.check "
                f"{f['check_us']:.2f} us ({f['check_us'] / base['check_us']:.2f}x), "
                f"load_config first {f['load1_ms']:.1f} ms, again {f['load2_ms']:.1f} ms "
                f"({f['load2_ms'] / base['load2_ms']:.2f}x), entry-point scans {f['scans']:.0f}"
            )


if __name__ == "__main__":
    main()
