"""The alignment rule: interpolate between valid neighbours, never bridge, angles on the short arc."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emlogd.pipeline.align import SampleRing, interpolate, wrap_deg


class TestSampleRing:
    """Queries at a past time."""

    def test_interpolates_between_valid_neighbours(self) -> None:
        """A query between two valid samples is their linear interpolation; a hit is exact."""
        ring = SampleRing(100, max_gap_s=0.5)
        for k in range(10):
            ring.add(k * 0.1, 1.0 + k)
        assert ring.at(0.25) == pytest.approx(3.5)
        assert ring.at(0.3) == pytest.approx(4.0)

    def test_a_sample_at_the_query_time_answers_alone_the_newest_first(self) -> None:
        """A query at a sample's time gets that sample (the newest of equal times), at
        the oldest and the newest sample too; before the oldest, nothing."""
        ring = SampleRing(100, max_gap_s=0.5)
        ring.add(0.0, 1.0)
        ring.add(0.2, 2.0)
        ring.add(0.2, 3.0)
        ring.add(0.4, 4.0)
        assert [ring.at(t) for t in (0.0, 0.2, 0.4)] == [1.0, 3.0, 4.0]
        assert ring.at(0.3) == pytest.approx(3.5)
        assert ring.at(-0.1) is None
        ring.add(0.4, None, False)
        assert ring.at(0.4) is None

    def test_never_past_the_newest_sample(self) -> None:
        """A query after the newest sample gets nothing (the caller waits), and covers() says so."""
        ring = SampleRing(100)
        ring.add(1.0, 2.0)
        assert ring.at(1.05) is None
        assert not ring.covers(1.05) and ring.covers(1.0)

    def test_an_outage_is_never_bridged(self) -> None:
        """An invalid neighbour or a gap wider than max_gap_s answers None."""
        ring = SampleRing(100, max_gap_s=0.5)
        ring.add(0.0, 1.0)
        ring.add(1.0, None, False)
        ring.add(1.1, 5.0)
        assert ring.at(0.95) is None and ring.at(1.0) is None
        ring.add(3.0, 6.0)
        assert ring.at(2.0) is None

    def test_stale_samples_are_refused_and_memory_is_bounded(self) -> None:
        """An older sample than the newest is refused; the ring keeps only its capacity."""
        ring = SampleRing(3)
        for k in range(10):
            assert ring.add(float(k), float(k))
        assert not ring.add(5.0, 0.0)
        assert len(ring) == 3
        assert ring.at(1.5) is None and ring.at(8.5) == pytest.approx(8.5)

    def test_headings_interpolate_across_north(self) -> None:
        """359° and 1° interpolate to 0°, not 180°."""
        ring = SampleRing(10, angular=True)
        ring.add(0.0, 359.0)
        ring.add(1.0, 1.0)
        assert ring.at(0.5) == pytest.approx(0.0, abs=1e-9)
        assert ring.at(0.25) == pytest.approx(359.5)

    def test_nearest_and_bad_construction(self) -> None:
        """nearest() picks the closest valid sample within a distance; bad sizes raise."""
        ring = SampleRing(10)
        ring.add(0.0, 1.0)
        ring.add(1.0, 2.0)
        assert ring.nearest(0.8, 0.5) == 2.0 and ring.nearest(5.0, 0.5) is None
        with pytest.raises(ValueError):
            SampleRing(1)
        with pytest.raises(ValueError):
            SampleRing(10, max_gap_s=0.0)
        assert wrap_deg(-10.0) == 350.0 and wrap_deg(720.0) == 0.0


class TestInterpolateArrays:
    """The vectorised form of the rule equals the ring, query by query."""

    @settings(max_examples=200, deadline=None)
    @given(
        steps=st.lists(st.floats(0.0, 0.8), min_size=2, max_size=40),
        values=st.lists(st.floats(0.0, 359.9), min_size=40, max_size=40),
        valid=st.lists(st.booleans(), min_size=40, max_size=40),
        queries=st.lists(st.floats(-1.0, 30.0), min_size=1, max_size=20),
        angular=st.booleans(),
    )
    def test_same_answers_as_the_ring(
        self,
        steps: list[float],
        values: list[float],
        valid: list[bool],
        queries: list[float],
        angular: bool,
    ) -> None:
        """interpolate() gives SampleRing.at() for every query (nan for None)."""
        t = np.cumsum(steps)
        v = np.array(values[: t.size])
        ok = np.array(valid[: t.size])
        ring = SampleRing(100, max_gap_s=0.5, angular=angular)
        for ti, vi, oi in zip(t, v, ok, strict=True):
            ring.add(float(ti), float(vi), bool(oi))
        arr = interpolate(t, v, ok, np.array(queries), 0.5, angular=angular)
        for q, got in zip(queries, arr, strict=True):
            want = ring.at(q)
            if want is None:
                assert np.isnan(got)
            else:
                assert got == pytest.approx(want, abs=1e-9)
