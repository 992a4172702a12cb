"""Where the daemon's CPU goes at live rates: thread CPU per wake-up and per call, by step.

Runs the real daemon (``emlogd run``, through a wrapper that times it with
``time.thread_time_ns``) against three fake devices replaying the simulated figure-8
at real speed (1 Hz VHW, 10 Hz VBW + 5 Hz VHW, 10 Hz PD6), then prints two tables:

1. Per wake-up, by what the wake-up did (a port read, a resting port becoming
   readable, a housekeeping round): the CPU spent in the wait (``epoll.poll``: the
   kernel's wake-up and the return into Python), in ``Pipeline.feed``, and in the
   daemon's own Python around it (the rest of the time until the next wait).
2. Per timed call: the calls, the CPU per call and the share of one core (nested
   steps are counted in their callers too; learning one UUT reading, and its
   alignment, filter step and supervision, wherever it is called from).

3. The daemon alone: its loop thread's CPU with ``Pipeline.feed`` and ``Pipeline.tick``
   stubbed (each returns an empty output at once), the same ports read at the same
   rates: what the loop, the reads and the rests cost without the pipeline's work.

The tables come from three runs of ``--seconds`` each: the first times only the
wait, ``Pipeline.feed`` and ``Pipeline.tick`` (what a wake-up did is marked, not timed);
the second times each step, which costs a few µs of CPU a timed call with the caches
cold (about 20 µs a wake-up, which the first table would count as the daemon's own);
the third times nothing but the loop.
Compare trees with the same script (``PYTHONPATH`` at each tree: the wrapper finds the
wait of either loop). Prints figures only.

Run: ``python bench/bench_wake_costs.py [--seconds 40] [--trial DIR]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from bench_daemon import run_wrapped, trial_dir

WRAPPER = r"""
import atexit, collections, json, sys, time
import drivers.io.port as dp
import emlogd.daemon.loop as dm
import emlogd.daemon.outputs as do
import emlogd.pipeline.core as pp
import emlogd.pipeline.learner as pl
import emlogd.pipeline.supervisor as ps
import emlogd.pipeline.uut as pu
from emlogd.cli import main

T = time.thread_time_ns
acc = collections.defaultdict(lambda: [0, 0])
kinds = collections.defaultdict(lambda: [0, 0, 0, 0])  # wake-ups, wait, body, feed (ns)
cur = {"did": [], "feed": 0, "wait": 0, "back": None, "port": "housekeeping"}
t0 = [0, 0.0]

STEPS = sys.argv[2] == "steps"  # else the split: the wait and the pipeline's calls timed
if sys.argv[2] == "stub":  # the daemon alone: the pipeline's work left out
    pp.Pipeline.feed = lambda self, t, port, data: pp.Output()
    pp.Pipeline.tick = lambda self, t: pp.Output()

def mark(cls, meth, did):
    # what a wake-up did, untimed (the split's run)
    f = getattr(cls, meth, None)
    if f is None:
        return
    def w(*a, **k):
        cur["did"].append(did(a) if callable(did) else did)
        return f(*a, **k)
    setattr(cls, meth, w)

def wrap(cls, meth, label, did=None):
    f = getattr(cls, meth, None)
    if f is None:
        return  # not in this version of the daemon
    if not STEPS and meth not in ("feed", "tick"):
        if did is not None:
            mark(cls, meth, did)
        return
    def w(*a, **k):
        if did is not None:
            cur["did"].append(did(a) if callable(did) else did)
        lab = label(a) if callable(label) else label
        t = T()
        try:
            return f(*a, **k)
        finally:
            dt = T() - t
            x = acc[lab]
            x[0] += dt
            x[1] += 1
            if meth == "feed":
                cur["feed"] += dt
                cur["port"] = "housekeeping"
    setattr(cls, meth, w)

class Wait:
    # the loop's epoll (or its selector's): one poll() call ends a wake-up's work
    def __init__(self, ep):
        self.ep = ep
    def poll(self, *a):
        t = T()
        if cur["back"] is not None:
            k = kinds["+".join(sorted(set(cur["did"]))) or "timeout, nothing due"]
            k[0] += 1
            k[1] += cur["wait"]
            k[2] += t - cur["back"] - cur["feed"]
            k[3] += cur["feed"]
        r = self.ep.poll(*a)
        t2 = T()
        cur.update(did=[], feed=0, wait=t2 - t, back=t2)
        return r
    def __getattr__(self, name):
        return getattr(self.ep, name)

D = dm.Daemon
_init = D.__init__
def init(self, *a, **k):
    _init(self, *a, **k)
    if hasattr(self, "calls"):  # callbacks straight from the loop's epoll
        self.poll = Wait(self.poll)
    else:  # a selectors loop
        self.sel._selector = Wait(self.sel._selector)
D.__init__ = init

wrap(D, "_read", lambda a: f"daemon read of {a[1]} (feed included)", lambda a: f"read {a[1]}")
wrap(D, "_rest_ready", "daemon resting port readable", "rest")
wrap(D, "_rest", "daemon resting port readable", "rest")
wrap(D, "_handle", "daemon deliver an output")
wrap(do.Outputs, "deliver", "daemon write sentences to the outputs")
wrap(dp.SerialSource, "read", "port read (os.read, stamp)")
wrap(dp.SerialSource, "poll", "housekeeping: port poll")
wrap(pp.Pipeline, "tick", "housekeeping: pipeline tick", "housekeeping")
def feed_of(a):
    cur["port"] = a[2]
    return f"pipeline feed of {a[2]} (decode, route, learn)"

wrap(pp.Pipeline, "feed", feed_of)
wrap(pp.Pipeline, "_route", lambda a: f"  of which route of {a[2]} (correct, emit, queue)")
wrap(pp.Pipeline, "_after", lambda a: f"  of which after a chunk of {cur['port']} (learn)")
wrap(pp.Pipeline, "_reference", "  of which a reference sample (glitch filter, alignment)")
wrap(pu.UutCalibration, "learn", "    learn one reading (align, health, filter, supervise)")
wrap(pl.Learner, "align", "      of which align it with the reference")
wrap(pl.Learner, "step", "      of which the filter and identifiability (step)")
wrap(ps.Supervisor, "observe", "      of which the supervisor's verdicts (observe)")

def loop(self, _run=D._loop):
    t0[0], t0[1] = T(), time.monotonic()
    _run(self)

D._loop = loop

def dump():
    acc["loop total"] = [T() - t0[0], 1]
    out = {"wall_s": time.monotonic() - t0[1], "acc": acc, "kinds": kinds}
    json.dump(out, open(sys.argv[1], "w"))

atexit.register(dump)
sys.exit(main(sys.argv[3:]))
"""


def _run(trial: Path, seconds: float, mode: str) -> dict[str, Any]:
    """One timed run of the daemon (``mode``: ``split`` or ``steps``); what it measured."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "costs.json"
        run_wrapped(trial, seconds, [sys.executable, "-c", WRAPPER, str(out), mode])
        data: dict[str, Any] = json.loads(out.read_text())
    return data


def main() -> None:
    """Run the timed daemon at live rates and print the CPU by wake-up and by step."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--trial", help="directory with the simulated trial (default: simulate one)")
    args = ap.parse_args()
    trial = trial_dir(args.trial)
    data = _run(trial, args.seconds, "split")
    wall = data["wall_s"]
    kinds = data["kinds"]
    n_all = sum(k[0] for k in kinds.values())
    print(f"live rates for {wall:.0f} s, {n_all / wall:.1f} wake-ups/s; CPU per wake-up, us:")
    print(f"  {'the wake-up did':40s} {'per s':>6s} {'wait':>7s} {'daemon':>7s} {'feed':>7s}")
    tot = [0.0, 0.0, 0.0]
    for kind, (n, wait, body, feed) in sorted(kinds.items(), key=lambda kv: -sum(kv[1][1:])):
        print(
            f"  {kind:40s} {n / wall:6.1f} {wait / n / 1e3:7.1f} {body / n / 1e3:7.1f} "
            f"{feed / n / 1e3:7.1f}"
        )
        tot = [tot[0] + wait, tot[1] + body, tot[2] + feed]
    print(
        f"  {'mean of all wake-ups':40s} {n_all / wall:6.1f} "
        + " ".join(f"{x / n_all / 1e3:7.1f}" for x in tot)
    )
    print(
        "  share of one core: "
        + ", ".join(
            f"{name} {100 * x / 1e9 / wall:.3f} %"
            for name, x in zip(("wait", "daemon", "feed"), tot, strict=True)
        )
    )
    data = _run(trial, args.seconds, "steps")
    wall = data["wall_s"]
    print("CPU per call and share of one core by step (a second run, each step timed):")
    for label, (ns, n) in sorted(data["acc"].items(), key=lambda kv: -kv[1][0]):
        print(f"  {label:45s} {n:6d} calls {ns / n / 1e3:8.1f} us  {100 * ns / 1e9 / wall:6.3f} %")
    data = _run(trial, args.seconds, "stub")
    wall = data["wall_s"]
    wakes = sum(k[0] for k in data["kinds"].values()) / wall
    print(
        "the daemon alone (a third run, Pipeline.feed and tick stubbed): the loop thread "
        f"{100 * data['acc']['loop total'][0] / 1e9 / wall:.3f} % of a core at {wakes:.1f} "
        "wake-ups/s"
    )


if __name__ == "__main__":
    main()
