"""An emlogd command run twice, the second time with every clock jumping: what a command
writes must not depend on when it runs, how fast, nor on the hash seed."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

JUMPING_CLOCKS = """
import random, runpy, sys, time
rng = random.Random(7)
for name in ("time", "monotonic", "perf_counter", "process_time", "thread_time"):
    real, off = getattr(time, name), [0.0]
    def jumping(real=real, off=off):
        off[0] += rng.choice((0.0, 0.003, 5.0, 3600.0))
        return real() + off[0]
    setattr(time, name, jumping)
    setattr(time, name + "_ns", lambda j=jumping: int(j() * 1e9))
sys.argv = ["emlogd", *sys.argv[1:]]
runpy.run_module("emlogd", run_name="__main__")
"""
"""``python -c JUMPING_CLOCKS ARGS``: ``emlogd ARGS`` with every clock of the time module
jumping by up to an hour at each reading, before anything is imported."""


def run_twice(args: list[str]) -> list[str]:
    """``emlogd ARGS``' stdout from two processes: as it is, then with every clock jumping
    (:data:`JUMPING_CLOCKS`) and another hash seed (the command must succeed both times)."""
    return [
        subprocess.run(
            [sys.executable, *prefix, *args],
            env={**os.environ, "PYTHONPATH": str(ROOT), "PYTHONHASHSEED": str(k)},
            capture_output=True,
            check=True,
            text=True,
        ).stdout
        for k, prefix in enumerate((["-m", "emlogd"], ["-c", JUMPING_CLOCKS]))
    ]
