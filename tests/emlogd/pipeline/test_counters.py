"""A UUT's counters and running scores."""

from __future__ import annotations

import math

import pytest

from emlogd.pipeline.counters import Counters, Score


def test_score_is_the_rmse_of_what_it_was_given() -> None:
    """Raw and corrected RMSE over the same samples; None before any."""
    s = Score()
    assert s.rmse_raw is None and s.rmse_corrected is None
    for er, ec in ((0.3, 0.1), (-0.4, 0.0)):
        s.add(er, ec)
    assert s.n == 2
    assert s.rmse_raw == pytest.approx(math.sqrt((0.09 + 0.16) / 2))
    assert s.rmse_corrected == pytest.approx(math.sqrt(0.01 / 2))


def test_counters_as_plain_types() -> None:
    """Every reason is a key, the supervisor's own included."""
    c = Counters()
    c.changes += 1
    c.uut_stalled += 2
    d = c.as_dict()
    assert d["changes"] == 1 and d["uut_stalled"] == 2 and d["learnt"] == 0
