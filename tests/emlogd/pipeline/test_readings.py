"""Tests for emlogd.pipeline.readings: a log's readings checked for rate and acceleration."""

from __future__ import annotations

import time

import pytest

from emlogd.pipeline.readings import BABBLE_S, ReadingCheck, ReadingLimits


class TestReadingCheck:
    """A log's readings: its rate and the vessel's acceleration."""

    def test_a_configured_rate_holds_and_a_log_beyond_it_is_dropped_whole(self) -> None:
        """max_rate_hz 5: a 4-Hz log passes whole; a 10-Hz log loses its third reading
        beyond the rate within 10 s and then everything, until it keeps the rate."""
        chk = ReadingCheck(ReadingLimits(max_rate_hz=5.0))
        assert all(chk.check(k / 4.0, 2.8) == "" for k in range(200))
        fast = [chk.check(50.0 + k / 10.0, 2.8) for k in range(100)]
        assert fast[:2] == ["", ""] and fast[-50:] == ["rate"] * 50
        assert chk.check(70.1, 2.8) == "" and chk.nominal_s is None

    def test_the_nominal_rate_is_learnt(self) -> None:
        """Without max_rate_hz the median interval of the accepted readings is learnt."""
        chk = ReadingCheck(ReadingLimits())
        for k in range(40):
            chk.check(k * 0.5, 2.8)
        assert chk.nominal_s == pytest.approx(0.5)
        assert chk.max_rate_hz() == pytest.approx(2.1)

    def test_readings_out_of_range_count_for_the_rate(self) -> None:
        """A 1-Hz log whose readings are out of its range, three in four, for 4 minutes
        (astern below -1 m/s), then all in range again: heard again at once, its nominal
        interval still 1 s. Skipped before the check, they left gaps that taught a 4-s
        interval: the log at its own rate was babbling, every reading dropped for good."""
        chk = ReadingCheck(ReadingLimits())
        assert all(chk.check(float(k), 2.8) == "" for k in range(60))
        for k in range(240):
            if k % 4:
                chk.arrived(60.0 + k)
            else:
                assert chk.check(60.0 + k, 2.8) == ""
        back = [chk.check(300.0 + k, 2.8) for k in range(60)]
        assert set(back) == {""}, back
        assert chk.nominal_s == pytest.approx(1.0)

    def test_acceleration(self) -> None:
        """1 m/s² and 0.3 m/s of margin: 2.8 → 4.0 in 1 s is refused, → 4.0 in 1 s after
        2 s of silence is not; the refusal's allowance is frozen at its first reading."""
        chk = ReadingCheck(ReadingLimits(max_reading_accel_mps2=1.0))
        assert chk.check(0.0, 2.8) == ""
        assert chk.check(1.0, 4.2) == "accel"
        assert chk.check(5.0, 4.2) == "accel"  # readings kept coming: not 0.3 + 5 m/s
        assert chk.check(6.0, 2.9) == ""
        assert chk.check(8.0, 4.2) == ""  # 2 s of silence: 0.3 + 2 m/s


def test_a_log_babbling_one_sentence_a_read_costs_each_reading_little() -> None:
    """A 1-Hz log, then 650 000 reads of one sentence 20 µs apart (13 s of a babble at
    50 kHz): every read is dropped for the rate, the log babbling from the third on,
    and the whole run costs well under 3 s of CPU. Every drop within 10 s was kept in a
    list whose oldest was removed at every reading: each cost the whole list (half a
    million) once the babble was 10 s old, 55 µs a reading against 0.7."""
    chk = ReadingCheck(ReadingLimits())
    for k in range(60):
        assert chk.check(float(k), 2.8) == ""
    c0 = time.process_time()
    whys = [chk.check(60.0 + k * 20e-6, 2.8) for k in range(650_000)]
    assert time.process_time() - c0 < 3.0
    assert set(whys[2:]) == {"rate"}
    # back at 1 Hz: heard again once no read was dropped for BABBLE_S
    assert chk.check(73.0 + BABBLE_S + 1.0, 2.8) == ""
