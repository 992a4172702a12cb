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


def test_score_counts_the_imo_bound_raw_and_corrected() -> None:
    """IMO A.824(19): an error of exactly 0.2 kn below 10 kn (or 2 % above) is within,
    one a millimetre per second more is not; a log meets the bound with 95 % within."""
    from calib.metrics import IMO_MIN_ERROR_MPS

    s = Score()
    ref = 3.0  # below 10 kn: the bound is 0.2 kn
    for _ in range(19):
        s.add(IMO_MIN_ERROR_MPS, 0.0, ref)  # raw exactly at the bound: within
    s.add(IMO_MIN_ERROR_MPS + 0.001, IMO_MIN_ERROR_MPS + 0.001, ref)  # both just outside
    raw, cor = s.imo()
    assert (raw.n, raw.within, raw.meets) == (20, 19, True)
    assert (cor.n, cor.within, cor.meets) == (20, 19, True)
    s.add(IMO_MIN_ERROR_MPS + 0.001, 0.0, ref)  # 19 of 21 raw: below 95 %
    raw, cor = s.imo()
    assert (raw.within, raw.meets) == (19, False) and (cor.within, cor.meets) == (20, True)
    fast = Score()
    fast.add(0.02 * 10.0, 0.02 * 10.0 + 0.001, 10.0)  # 19.4 kn: 2 % of the speed
    r, c = fast.imo()
    assert r.within == 1 and c.within == 0
    s.add(0.1, 0.1)  # without the reference's speed: RMSE only
    assert s.imo()[0].n == 21 and s.n == 22
