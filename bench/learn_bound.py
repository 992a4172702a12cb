"""A bound on what learning from fewer readings could save: each UUT learns at most one
reading every ``EVERY_S`` seconds, and the readings in between are not learnt at all.

Learning and supervising block means of a log's readings (one step per block of
``EVERY_S`` instead of one per reading) does at least the work of one reading per
block, and adds the means' own: the CPU saved with the readings in between simply
skipped is about the most any such scheme can save (not a strict bound: the work that
follows a step, the lag search's and the supervisor's, depends on what was learnt). The
emission is untouched (every reading
is still checked, corrected with the calibration in force and encoded); what is learnt,
and so what is applied, is not the same (a bound, not a candidate).
:func:`thin_learning` wraps :meth:`emlogd.pipeline.uut.UutCalibration.learn` in this
process; ``bench/bench_replay_ab.py`` and ``bench/bench_live_ab.py`` take a tree as
``TREE@EVERY_S`` to time that tree so (``@inf``: each UUT learns its first reading
only, a bound on all of learning).

Run a command so: ``python bench/learn_bound.py EVERY_S ARGS...`` (``ARGS``: those of
``python -m emlogd``, e.g. ``run --config FILE``).
"""

from __future__ import annotations

import math
import runpy
import sys
from collections.abc import Callable
from typing import Any


def thin_learning(every_s: float) -> Callable[[], None]:
    """Each :class:`~emlogd.pipeline.uut.UutCalibration` learns a reading only when at
    least ``every_s`` seconds have passed since the last one it learnt (by the readings'
    times); returns the call that puts the method back."""
    from emlogd.pipeline.uut import UutCalibration

    if not every_s >= 0.0:
        raise ValueError(f"every_s must be a number of seconds >= 0, not {every_s!r}")
    learn = UutCalibration.learn
    last: dict[int, float] = {}

    def thinned(self: UutCalibration, t: float, raw: float) -> None:
        if t - last.get(id(self), -math.inf) < every_s:
            return
        last[id(self)] = t
        learn(self, t, raw)

    UutCalibration.learn = thinned  # type: ignore[method-assign]

    def restore() -> None:
        UutCalibration.learn = learn  # type: ignore[method-assign]

    return restore


def split_tree(arg: str) -> tuple[str, float]:
    """A tree argument of the A/B scripts: ``TREE`` (learning as it is, 0.0) or
    ``TREE@EVERY_S`` (:func:`thin_learning`)."""
    tree, sep, every = arg.rpartition("@")
    if not sep:
        return arg, 0.0
    return tree, float(every)


def main(argv: list[str]) -> Any:
    """``EVERY_S ARGS...``: ``python -m emlogd ARGS...`` with learning thinned."""
    if len(argv) < 2:
        raise SystemExit(__doc__)
    thin_learning(float(argv[0]))
    sys.argv = ["emlogd", *argv[1:]]
    return runpy.run_module("emlogd", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main(sys.argv[1:])
