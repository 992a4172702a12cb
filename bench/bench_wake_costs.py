"""Where the daemon's CPU goes at live rates: thread CPU per call, by step.

Runs the real daemon (``emlogd run``, through a wrapper that times a few of its
methods with ``time.thread_time_ns``) against three fake devices replaying the
simulated figure-8 at real speed (1 Hz VHW, 10 Hz VBW + 5 Hz VHW, 10 Hz PD6), then
prints, per timed step, the calls, the CPU per call and the share of one core. The
timing adds a little to each timed call (nested steps are counted in their callers
too). The daemon's own ``time.thread_time_ns`` is the clock: it counts CPU, not
waiting. Prints figures only.

Run: ``python bench/bench_wake_costs.py [--seconds 40] [--trial DIR]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from bench_daemon import _setup, _start, _stop

WRAPPER = r"""
import atexit, collections, json, sys, time
import calib.kalman as kk
import drivers.io.port as dp
import emlogd.daemon.loop as dm
import emlogd.pipeline.core as pp
import selectors
from emlogd.cli import main

T = time.thread_time_ns
acc = collections.defaultdict(lambda: [0, 0])
t0 = [0, 0.0]

def wrap(cls, meth, label):
    f = getattr(cls, meth, None)
    if f is None:
        return  # not in this version of the daemon
    def w(*a, **k):
        t = T()
        try:
            return f(*a, **k)
        finally:
            x = acc[label(a) if callable(label) else label]
            x[0] += T() - t
            x[1] += 1
    setattr(cls, meth, w)

D = dm.Daemon
wrap(D, "_read", lambda a: f"daemon read of {a[1]}")
wrap(D, "_wake_rested", "daemon rested ports due (reads included)")
wrap(D, "_rest_ready", "daemon resting port readable")
wrap(D, "_rest", "daemon resting port readable")
wrap(D, "_register", "daemon (re)register a port")
wrap(D, "_handle", "daemon deliver an output")
wrap(selectors.EpollSelector, "select", "epoll wait and wake-up (select)")
wrap(dp.SerialSource, "read", "port read (os.read, stamp)")
wrap(dp.SerialSource, "poll", "housekeeping: port poll")
wrap(pp.Pipeline, "tick", "housekeeping: pipeline tick")
wrap(pp.Pipeline, "feed", "pipeline feed (decode, learn, emit)")
wrap(pp.Pipeline, "_uut", "pipeline UUT sample (correct, emit, learn)")
wrap(pp.Pipeline, "_learn", "pipeline learn (align, filter, supervise)")
wrap(kk.KfCalibrator, "update", "Kalman filter update")

def loop(self, _run=D._loop):
    t0[0], t0[1] = T(), time.monotonic()
    _run(self)

D._loop = loop

def dump():
    acc["loop total"] = [T() - t0[0], 1]
    json.dump({"wall_s": time.monotonic() - t0[1], "acc": acc}, open(sys.argv[1], "w"))

atexit.register(dump)
sys.exit(main(sys.argv[2:]))
"""


def main() -> None:
    """Run the timed daemon at live rates and print the CPU by step."""
    from emlogd.launch import fake_sensors
    from emlogd.offline.simulate import simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--trial", help="directory with the simulated trial (default: simulate one)")
    args = ap.parse_args()
    trial = Path(args.trial) if args.trial else Path(tempfile.mkdtemp(prefix="emlogd-trial-"))
    if not (trial / "2-figure8.cap").exists():
        simulate(trial, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = _setup(work)
        out = work / "costs.json"
        capture = trial / "2-figure8.cap"
        with fake_sensors(capture, work / "links", ("emlog1", "emlog2", "dvl"), speed=1.0):
            proc, _, srv = _start(work, cfg, [sys.executable, "-c", WRAPPER, str(out)])
            try:
                time.sleep(args.seconds)
            finally:
                _stop(proc, srv)
        data = json.loads(out.read_text())
    wall = data["wall_s"]
    print(f"live rates for {wall:.0f} s; CPU per call and share of one core by step:")
    for label, (ns, n) in sorted(data["acc"].items(), key=lambda kv: -kv[1][0]):
        print(f"  {label:45s} {n:6d} calls {ns / n / 1e3:8.1f} us  {100 * ns / 1e9 / wall:6.3f} %")


if __name__ == "__main__":
    main()
