"""Benchmark: what a capture reader loses to one corrupted time and to jitter, and its speed.

Takes a capture (default: the demo capture shipped in ``emlogd/data``) and writes two
copies to a temporary directory: one whose record 18 % into the file has the hundreds
digit of its seconds raised by one (a forward jump of 100 s), one with every record's
time moved by a uniform ±50 ms (seed 1). Prints how many records the reader of the tree
on ``PYTHONPATH`` gives back and skips for each, and its reading time per record (best
of 3, the unmodified capture). Run it with another tree on ``PYTHONPATH`` to compare.

Run: ``PYTHONPATH=. python bench/bench_capture_times.py [CAPTURE]``
"""

from __future__ import annotations

import gzip
import random
import sys
import tempfile
import time
from pathlib import Path

from drivers.io.capture import CaptureReader

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "emlogd" / "data" / "demo-figure8.cap.gz"


def _count(path: Path) -> tuple[int, int, object]:
    reader = CaptureReader(path, errors="skip")
    n = sum(1 for _ in reader.received())
    return n, reader.n_skipped, getattr(reader, "reordered", "n/a")


def _read_back(what: str, lines: list[str], n_records: int, path: Path) -> None:
    """Write ``lines`` as a capture at ``path`` and print what the reader gives back of
    it (records read, skipped, reordered) under the heading ``what``."""
    path.write_text("\n".join(lines))
    n, skipped, reordered = _count(path)
    print(
        f"{what}: read {n}, skipped {skipped} "
        f"({100 * skipped / n_records:.1f} %), reordered {reordered}"
    )


def main() -> None:
    src = Path(sys.argv[1]) if len(sys.argv) > 1 else DEMO
    opener = gzip.open if src.name.endswith(".gz") else open
    with opener(src, "rt") as f:
        lines = f.read().split("\n")
    recs = [i for i, line in enumerate(lines) if line.startswith("(")]
    print(f"{src.name}: {len(recs)} records")
    with tempfile.TemporaryDirectory() as tmp:
        flip = list(lines)
        i = recs[int(0.18 * len(recs))]
        stamp, rest = flip[i].split(")", 1)
        s = stamp[1:]
        pos = s.index(".") - 3  # the hundreds of seconds
        s2 = s[:pos] + str(min(int(s[pos]) + 1, 9)) + s[pos + 1 :]
        flip[i] = f"({s2}){rest}"
        _read_back(f"one time {s} -> {s2}", flip, len(recs), Path(tmp) / "flip.cap")
        rng = random.Random(1)
        jitter = list(lines)
        for i in recs:
            stamp, rest = jitter[i].split(")", 1)
            jitter[i] = f"({float(stamp[1:]) + rng.uniform(-0.05, 0.05):.6f}){rest}"
        _read_back("±50 ms jitter", jitter, len(recs), Path(tmp) / "jitter.cap")
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        n = sum(1 for _ in CaptureReader(src).received())
        best = min(best, time.perf_counter() - t0)
    print(f"reading: {best * 1e6 / n:.2f} µs per record (best of 3)")


if __name__ == "__main__":
    main()
