"""The live CPU of several trees' daemons measured side by side, at the same moments.

Each round starts the daemon of every tree given (``python -m emlogd run`` with
``PYTHONPATH`` at that tree, its config and state file made by that tree's own
``bench/bench_daemon.py``) at the same time, each on its own three fake devices
replaying the simulated figure-8 at real speed (1 Hz VHW, 10 Hz VBW + 5 Hz VHW, 10 Hz
PD6: the live rates of ``bench_daemon.py``), and reads each daemon's user and system
CPU from ``/proc`` over the same ``--seconds`` after a 5 s warm-up. On a shared machine
the load moves every figure; the trees of one round share it, so their ratio to the
first tree in the same round is the figure to compare (its median over the rounds is
printed). The wake-ups of one round differ between the trees by chance (a resting
port's burst is read in one read or, its lines delayed by the load, in two), by a few
per cent, and the CPU follows them: the CPU per wake-up and its ratio, printed beside,
are not moved by that. A tree given as ``TREE@EVERY_S`` runs its daemon with each UUT
learning at most one reading every ``EVERY_S`` seconds (``bench/learn_bound.py``: a bound
on what learning from block means could save). Prints figures only.

Run: ``python bench/bench_live_ab.py TREE[@EVERY_S] [TREE ...] [--seconds 40] [--rounds 3] [--trial DIR]``
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_daemon import _wakeups
from learn_bound import split_tree

WARM_UP_S = 5.0
"""Seconds between READY=1 and the start of the measurement (ports open, imports done)."""

READY_TIMEOUT_S = 30.0
"""The longest wait for a daemon's READY=1."""

SETUP = (
    "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1] + '/bench'); "
    "from bench_daemon import _setup; print(_setup(Path(sys.argv[2])))"
)


def _cpu(pid: int) -> tuple[float, float, float]:
    """A process's CPU, s: in all (the scheduler's count, ns resolution), user and system
    (in clock ticks: 10 ms, 0.025 % of a core over 40 s)."""
    total = int(Path(f"/proc/{pid}/schedstat").read_text().split()[0]) / 1e9
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    tck = os.sysconf("SC_CLK_TCK")
    return total, int(f[11]) / tck, int(f[12]) / tck


def side(tree: Path, trial: Path, seconds: float, every_s: float = 0.0) -> dict[str, float]:
    """Run ``tree``'s daemon at live rates; its CPU shares (% of a core) and wake-ups/s.
    ``every_s`` over 0: its UUTs learn one reading every ``every_s`` at most
    (``bench/learn_bound.py``)."""
    from emlogd.launch import fake_sensors

    env = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = subprocess.run(
            [sys.executable, "-c", SETUP, str(tree), str(work)],
            env=env, cwd=tree, check=True, capture_output=True, text=True,
        ).stdout.strip()  # fmt: skip
        links = work / "links"
        run = [sys.executable, "-m", "emlogd"]
        if every_s > 0.0:
            run = [sys.executable, str(Path(__file__).with_name("learn_bound.py")), str(every_s)]
        with fake_sensors(trial / "2-figure8.cap", links, ("emlog1", "emlog2", "dvl"), speed=1.0):
            notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
            notify.bind(str(work / "notify.sock"))
            notify.settimeout(READY_TIMEOUT_S)
            with (work / "daemon.log").open("w") as log:
                proc = subprocess.Popen(
                    [*run, "run", "--config", cfg],
                    cwd=work,
                    env={**env, "NOTIFY_SOCKET": str(work / "notify.sock")},
                    stdout=log,
                    stderr=log,
                )
                try:
                    while notify.recv(4096) != b"READY=1":
                        pass
                    time.sleep(WARM_UP_S)
                    c0, w0, t0 = _cpu(proc.pid), _wakeups(proc.pid), time.monotonic()
                    time.sleep(seconds)
                    c1, w1, t1 = _cpu(proc.pid), _wakeups(proc.pid), time.monotonic()
                finally:
                    proc.terminate()
                    proc.wait(20)
                    notify.close()
    wall = t1 - t0
    cpu, user, system = (100 * (b - a) / wall for a, b in zip(c0, c1, strict=True))
    return {"cpu": cpu, "user": user, "sys": system, "wakeups": (w1 - w0) / wall}


def main() -> None:
    """Run the rounds and print each tree's CPU, and its ratio to the first tree's."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "trees", nargs="+", help="source trees, TREE or TREE@EVERY_S (the first: the baseline)"
    )
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--trial", help="directory with the simulated trial (default: simulate one)")
    ap.add_argument("--side", help=argparse.SUPPRESS)  # one tree, in a child
    args = ap.parse_args()
    trial = Path(args.trial) if args.trial else Path(tempfile.mkdtemp(prefix="emlogd-trial-"))
    if args.side is not None:
        where, every_s = split_tree(args.side)
        print(json.dumps(side(Path(where).resolve(), trial, args.seconds, every_s)))
        return
    if not (trial / "2-figure8.cap").exists():
        from emlogd.offline.simulate import simulate

        simulate(trial, seed=1)
    trees = [(Path(where).resolve(), every_s) for where, every_s in map(split_tree, args.trees)]
    names = [f"{tree.name}@{every_s:g}" if every_s > 0.0 else tree.name for tree, every_s in trees]
    runs: list[list[dict[str, float]]] = []
    for k in range(args.rounds):
        procs = [
            subprocess.Popen(
                [
                    sys.executable,
                    __file__,
                    str(tree),
                    "--side",
                    f"{tree}@{every_s}",
                    "--trial",
                    str(trial),
                    "--seconds",
                    str(args.seconds),
                ],
                stdout=subprocess.PIPE,
                text=True,
            )
            for tree, every_s in trees
        ]
        runs.append([json.loads(p.communicate()[0]) for p in procs])
        load = os.getloadavg()[0]
        print(
            f"round {k + 1} (load {load:.1f}): "
            + "; ".join(
                f"{name} {r['cpu']:.3f} % (user {r['user']:.3f}, sys {r['sys']:.3f}), "
                f"{r['wakeups']:.1f} wake-ups/s"
                for name, r in zip(names, runs[-1], strict=True)
            ),
            flush=True,
        )
    print(f"live CPU over {args.seconds:.0f} s, median of {args.rounds} rounds:")
    for i, (tree, every_s) in enumerate(trees):
        cpu = statistics.median(r[i]["cpu"] for r in runs)
        ratio = statistics.median(r[i]["cpu"] / r[0]["cpu"] for r in runs)
        wake = statistics.median(_per_wakeup(r[i]) for r in runs)
        wake_ratio = statistics.median(_per_wakeup(r[i]) / _per_wakeup(r[0]) for r in runs)
        print(
            f"  {tree}{f'@{every_s:g}' if every_s > 0.0 else ''}: {cpu:.3f} % of a core, {ratio:.3f}x the first tree in the same round; "
            f"{wake:.0f} us per wake-up, {wake_ratio:.3f}x"
        )


def _per_wakeup(side: dict[str, float]) -> float:
    """A side's CPU per wake-up, us."""
    return 1e4 * side["cpu"] / side["wakeups"]


if __name__ == "__main__":
    main()
