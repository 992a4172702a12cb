"""The replay pipeline's CPU time on several trees, side by side in one session.

Each round runs, for every tree given, :func:`bench_replay._pipeline` over a trial's
records in a fresh Python with ``PYTHONPATH`` at that tree and its own
``examples/emlogd.yaml``, and reads that process's CPU time around the pipeline alone
(records already in memory); the trees take turns, their order reversed every other
round. On a shared machine the load moves every figure by several per cent: the ratio
to the first tree within a round is the figure to compare (its median over the rounds
is printed). Each run also prints a digest of the pipeline's status at the end, the
same for trees that do the same work. A tree given as ``TREE@EVERY_S`` is timed with
each UUT learning at most one reading every ``EVERY_S`` seconds (``bench/learn_bound.py``:
a bound on what learning from block means could save). Prints figures only.

Run: ``python bench/bench_replay_ab.py TREE[@EVERY_S] [TREE ...] --outdir DIR [--rounds 4] [--records N]``
(``DIR``: a trial's five captures, e.g. ``emlogd simulate DIR --scale 0.2``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from learn_bound import split_tree


def _side(tree: Path, outdir: Path, n_records: int, every_s: float) -> None:
    """In the child: time the pipeline of the tree on ``PYTHONPATH`` (its learning thinned
    to one reading every ``every_s`` per UUT when that is over 0); print the CPU seconds
    and the status's digest."""
    import bench_replay
    from learn_bound import thin_learning

    from drivers.io.capture import CaptureReader

    records: list[tuple[float, str, bytes]] = []
    for f in sorted(outdir.glob("[1-5]-*.cap")):
        records += [(t, port, data) for t, port, data, _ in CaptureReader(f).received()]
    if n_records:
        records = records[:n_records]
    if every_s > 0.0:
        thin_learning(every_s)
    bench_replay.CLOCK[0] = time.process_time
    seconds, pipe = bench_replay._pipeline(records, tree / "examples" / "emlogd.yaml")
    status = json.dumps(pipe.status(), sort_keys=True, default=str)
    print(f"{seconds:.4f} {hashlib.sha256(status.encode()).hexdigest()[:12]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "trees", nargs="+", help="source trees, TREE or TREE@EVERY_S (the first: the baseline)"
    )
    ap.add_argument("--outdir", type=Path, required=True, help="the trial's directory")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--records", type=int, default=0, help="the first N records only (0: all)")
    ap.add_argument("--side", action="store_true", help=argparse.SUPPRESS)  # one tree, a child
    args = ap.parse_args()
    trees = args.trees
    if args.side:
        where, every_s = split_tree(trees[0])
        _side(Path(where).resolve(), args.outdir, args.records, every_s)
        return
    cpu: dict[str, list[float]] = {t: [] for t in trees}
    for r in range(args.rounds):
        for tree in trees if r % 2 == 0 else trees[::-1]:
            where, every_s = split_tree(tree)
            path = Path(where).resolve()
            out = subprocess.run(
                [sys.executable, __file__, f"{path}@{every_s}", "--side",
                 "--outdir", str(args.outdir), "--records", str(args.records)],
                env=dict(os.environ, PYTHONPATH=str(path)), cwd=path,
                check=True, capture_output=True, text=True,
            )  # fmt: skip
            seconds, digest = out.stdout.split()
            cpu[tree].append(float(seconds))
            load = os.getloadavg()[0]
            print(
                f"round {r + 1}: {tree}  {float(seconds):.3f} s CPU  status {digest}  load {load:.1f}"
            )
    base = cpu[trees[0]]
    for tree in trees:
        ratios = [a / b for a, b in zip(cpu[tree], base, strict=True)]
        print(
            f"{tree}: median {statistics.median(cpu[tree]):.3f} s, {statistics.median(ratios):.3f}x "
            f"the first tree (by round {' '.join(f'{x:.3f}' for x in ratios)})"
        )


if __name__ == "__main__":
    main()
