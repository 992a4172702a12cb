"""The alignment rule: interpolate between valid neighbours, never bridge, angles on the short arc."""

from __future__ import annotations

import statistics

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from emlogd.pipeline.align import (
    DEFAULT_MAX_GAP_S,
    GAP_INTERVALS,
    MAX_GAP_CAP_S,
    MedianWindow,
    SampleRing,
    cadence_gap,
    interpolate,
    wrap_deg,
)


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


class TestCadence:
    """The gap follows the series' own rate (references from 10 Hz to 0.2 Hz)."""

    @pytest.mark.parametrize("rate_hz", [10.0, 1.0, 0.5, 0.2])
    def test_a_reference_at_any_rate_aligns_midway(self, rate_hz: float) -> None:
        """Midway between two samples of a reference at 0.2–10 Hz a query gets the
        interpolation; with the fixed 1 s gap a reference slower than 0.5 Hz gets nothing."""
        dt = 1.0 / rate_hz
        t = np.arange(50) * dt
        v = 1.0 + 0.01 * np.arange(50)
        ok = np.ones(50, dtype=bool)
        q = t[-10:-1] + dt / 2
        got = interpolate(t, v, ok, q, DEFAULT_MAX_GAP_S, cadence=True)
        assert np.allclose(got, np.interp(q, t, v))
        fixed = interpolate(t, v, ok, q, DEFAULT_MAX_GAP_S)
        assert np.all(np.isfinite(fixed)) == (dt / 2 <= DEFAULT_MAX_GAP_S)

    def test_the_gap_is_a_few_intervals_floored_and_capped(self) -> None:
        """GAP_INTERVALS median intervals, at least the floor, at most MAX_GAP_CAP_S;
        a dropped sample is bridged, an outage of five intervals is not."""
        assert cadence_gap(0.1, DEFAULT_MAX_GAP_S) == DEFAULT_MAX_GAP_S
        assert cadence_gap(2.0, DEFAULT_MAX_GAP_S) == pytest.approx(GAP_INTERVALS * 2.0)
        assert cadence_gap(60.0, DEFAULT_MAX_GAP_S) == MAX_GAP_CAP_S
        ring = SampleRing(100, cadence=True)
        for k in range(20):
            ring.add(2.0 * k, 1.0)
        assert ring.gap_s == pytest.approx(5.0)
        ring.add(42.0, 2.0)  # one sample (t = 40) missing: 4 s between brackets
        assert ring.at(41.0) == pytest.approx(1.75)
        ring.add(54.0, 3.0)  # five missing: 12 s
        assert ring.at(48.0) is None

    def test_repeated_times_stand_by_the_newest(self) -> None:
        """Several samples at one time: the newest brackets the queries on both sides,
        and repeated times do not shrink the cadence."""
        ring = SampleRing(100, cadence=True)
        for k in range(10):
            ring.add(float(k), 1.0)
            ring.add(float(k), 2.0 + k)
        assert ring.gap_s == pytest.approx(GAP_INTERVALS)
        assert ring.at(3.5) == pytest.approx(0.5 * (5.0 + 6.0))
        assert ring.at(4.0) == 6.0


class TestInterpolateArrays:
    """The vectorised form of the rule equals the ring, query by query."""

    @settings(max_examples=200, deadline=None)
    @given(
        steps=st.lists(
            st.one_of(st.floats(0.0, 0.8), st.just(0.0), st.floats(0.8, 8.0)),
            min_size=2,
            max_size=40,
        ),
        values=st.lists(st.floats(0.0, 359.9), min_size=40, max_size=40),
        valid=st.lists(st.booleans(), min_size=40, max_size=40),
        queries=st.lists(st.floats(-1.0, 30.0), min_size=1, max_size=20),
        angular=st.booleans(),
        cadence=st.booleans(),
    )
    def test_same_answers_as_the_ring(
        self,
        steps: list[float],
        values: list[float],
        valid: list[bool],
        queries: list[float],
        angular: bool,
        cadence: bool,
    ) -> None:
        """interpolate() gives SampleRing.at() for every query (nan for None), with
        repeated times, and with the gap fixed or from the cadence."""
        t = np.cumsum(steps)
        v = np.array(values[: t.size])
        ok = np.array(valid[: t.size])
        ring = SampleRing(100, max_gap_s=0.5, angular=angular, cadence=cadence)
        for ti, vi, oi in zip(t, v, ok, strict=True):
            ring.add(float(ti), float(vi), bool(oi))
        arr = interpolate(t, v, ok, np.array(queries), 0.5, angular=angular, cadence=cadence)
        for q, got in zip(queries, arr, strict=True):
            want = ring.at(q)
            if want is None:
                assert np.isnan(got)
            else:
                assert got == pytest.approx(want, abs=1e-9)


class TestMedianWindow:
    """The sorted window gives the medians a sort of the newest values gives, exactly."""

    @given(
        st.lists(
            st.floats(min_value=0.0, max_value=1e6, exclude_min=True) | st.sampled_from([0.1, 1.0]),
            min_size=1,
            max_size=120,
        ),
        st.integers(min_value=1, max_value=40),
    )
    @settings(max_examples=200, deadline=None)
    def test_medians_equal_a_sort_of_the_window(self, values: list[float], size: int) -> None:
        """After each value: median() is statistics.median and upper() sorted()[n // 2]
        of the newest ``size`` values (repeated values included), bit for bit."""
        win = MedianWindow(size)
        for k, v in enumerate(values):
            win.append(v)
            newest = values[max(0, k + 1 - size) : k + 1]
            assert len(win) == len(newest)
            assert win.median() == statistics.median(newest)
            assert win.upper() == sorted(newest)[len(newest) // 2]

    def test_clear_and_bad_size(self) -> None:
        """clear() forgets every value; an empty window has no median; a size below 1 is refused."""
        win = MedianWindow(3)
        for v in (5.0, 1.0, 3.0, 2.0):
            win.append(v)
        assert win.median() == 2.0 and win.upper() == 2.0
        win.clear()
        assert len(win) == 0
        with pytest.raises(IndexError):
            win.median()
        with pytest.raises(ValueError):
            MedianWindow(0)
