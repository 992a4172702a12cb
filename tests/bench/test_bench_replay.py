"""bench/bench_replay.py --parts: the learning calls it times exist, are called on a
replay, and are themselves again once timed."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from drivers.io.capture import CaptureReader
from tests.scripts import ROOT, load_script

bench = load_script("bench/bench_replay.py")

FIGURE8 = ROOT / "examples" / "captures" / "2-figure8.cap.gz"
RECORDS = 4000
"""The figure-8's first records replayed: enough for the lag, the filter and the
supervisor to run."""


def test_every_timed_call_is_a_method_of_today() -> None:
    assert len(bench.part_methods()) == len(bench.PARTS)


def test_parts_times_each_call_and_restores_it(capsys: pytest.CaptureFixture[str]) -> None:
    before = [getattr(cls, name) for cls, name, _ in bench.part_methods()]
    records = [
        (t, port, data)
        for t, port, data, _ in itertools.islice(CaptureReader(Path(FIGURE8)).received(), RECORDS)
    ]
    spent = bench._parts(records)
    labels = [label for *_, label in bench.PARTS]
    for label in ("learning one reading (all of it)", "  learner step", "    Kalman filter steps"):
        assert label in labels and spent.get(label, 0.0) > 0.0, label
    assert [getattr(cls, name) for cls, name, _ in bench.part_methods()] == before
    printed = capsys.readouterr().out
    assert all(label in printed for label in labels)
