"""Where the daemon's loop spends its CPU at live rates, function by function.

Runs the real daemon (``emlogd run``, through a wrapper that runs its loop under
:mod:`cProfile` timed by the thread's CPU clock, ``time.thread_time_ns``: the waits in
``epoll.poll`` count for the CPU they use, not for the time they wait) against three
fake devices replaying the simulated figure-8 at real speed (1 Hz VHW, 10 Hz VBW + 5 Hz
VHW, 10 Hz PD6), then prints the functions that use most CPU of their own (``tottime``)
and most with what they call (``cumtime``), each as a share of the loop's CPU. The
profiler's own cost falls on every call, so small functions called often look dearer
than they are: compare shares, and measure a change with ``bench_live_ab.py``. Prints
figures only.

Run: ``python bench/bench_live_profile.py [--seconds 40] [--top 25] [--trial DIR]``
"""

from __future__ import annotations

import argparse
import pstats
import sys
import tempfile
from pathlib import Path

from bench_daemon import run_wrapped, trial_dir

WRAPPER = r"""
import cProfile, sys, time
import emlogd.daemon.loop as dl
from emlogd.cli import main

def loop(self, _run=dl.Daemon._loop):
    prof = cProfile.Profile(time.thread_time_ns, 1e-9)
    prof.enable()
    try:
        _run(self)
    finally:
        prof.disable()
        prof.dump_stats(sys.argv[1])

dl.Daemon._loop = loop
sys.exit(main(sys.argv[2:]))
"""


def _table(stats: pstats.Stats, key: str, top: int, total: float) -> None:
    """The ``top`` functions by ``key`` (``tottime``, ``cumtime``), as shares of ``total``."""
    rows = stats.stats  # type: ignore[attr-defined]
    col = {"tottime": 2, "cumtime": 3}[key]
    order = sorted(rows.items(), key=lambda kv: -kv[1][col])[:top]
    print(f"by {key}: calls, CPU per call (us), share of the loop's CPU")
    for (path, line, name), (_, calls, tt, ct, _) in order:
        where = f"{Path(path).name}:{line}({name})" if line else name
        t = tt if key == "tottime" else ct
        print(
            f"  {where[:60]:60s} {calls:7d} {1e6 * t / max(calls, 1):9.1f} {100 * t / total:6.1f} %"
        )


def main() -> None:
    """Run the profiled daemon at live rates and print where its loop's CPU goes."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--trial", help="directory with the simulated trial (default: simulate one)")
    args = ap.parse_args()
    trial = trial_dir(args.trial)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "loop.prof"
        run_wrapped(trial, args.seconds, [sys.executable, "-c", WRAPPER, str(out)])
        stats = pstats.Stats(str(out))
    total = max(row[3] for row in stats.stats.values())  # type: ignore[attr-defined]
    print(f"the loop's CPU under the profiler: {total:.3f} s over about {args.seconds:.0f} s")
    _table(stats, "tottime", args.top, total)
    _table(stats, "cumtime", args.top, total)


if __name__ == "__main__":
    main()
