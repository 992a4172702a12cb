"""bench/learn_bound.py: each UUT learns at most one reading every ``EVERY_S`` seconds
while the bound is on, and learns every reading again once it is restored."""

from __future__ import annotations

import math

import pytest

from emlogd.pipeline.uut import UutCalibration
from tests.scripts import load_script

bound = load_script("bench/learn_bound.py")


def test_each_uut_learns_one_reading_every_interval(monkeypatch: pytest.MonkeyPatch) -> None:
    learnt: list[tuple[int, float]] = []

    def record(self: UutCalibration, t: float, raw: float) -> None:
        learnt.append((id(self), t))

    monkeypatch.setattr(UutCalibration, "learn", record)
    one, two = object.__new__(UutCalibration), object.__new__(UutCalibration)
    restore = bound.thin_learning(0.5)
    for k in range(10):  # 5 Hz for 2 s, the two UUTs interleaved
        one.learn(0.2 * k, 1.0)
        two.learn(0.2 * k + 0.1, 1.0)
    times = {u: [t for who, t in learnt if who == id(u)] for u in (one, two)}
    assert times[one] == pytest.approx([0.0, 0.6, 1.2, 1.8])
    assert times[two] == pytest.approx([0.1, 0.7, 1.3, 1.9])
    restore()
    learnt.clear()
    one.learn(1.9, 1.0)
    assert learnt == [(id(one), 1.9)]


def test_a_tree_argument_names_the_interval() -> None:
    assert bound.split_tree("/work/tree") == ("/work/tree", 0.0)
    assert bound.split_tree("/work/tree@0.5") == ("/work/tree", 0.5)
    assert bound.split_tree("tree@inf") == ("tree", math.inf)


def test_a_negative_interval_is_refused() -> None:
    with pytest.raises(ValueError, match="every_s"):
        bound.thin_learning(-1.0)
