"""Tests for emlogd.pipeline.readings: a log's readings checked for rate and acceleration."""

from __future__ import annotations

import random
import tracemalloc
from pathlib import Path

import pytest

from emlogd.pipeline import readings
from emlogd.pipeline.readings import BABBLE_S, RATE_RELEARN_S, ReadingCheck, ReadingLimits


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

    def test_a_log_that_changes_its_rate_is_heard_at_the_new_one(self) -> None:
        """A 1-Hz log set to 5 Hz after 2 minutes, its readings a steady 2.8 m/s with
        0.02 m/s of noise: dropped as babbling at first, heard again within
        RATE_RELEARN_S + 5 s at 5 Hz (nominal interval 0.2 s), every reading after.
        Before, a read dropped for the rate taught no interval: the log was babbling,
        every reading dropped for good."""
        rng = random.Random(1)
        chk = ReadingCheck(ReadingLimits())
        assert all(chk.check(float(k), 2.8 + rng.gauss(0.0, 0.02)) == "" for k in range(120))
        fast = [
            (120.0 + k / 5.0, chk.check(120.0 + k / 5.0, 2.8 + rng.gauss(0.0, 0.02)))
            for k in range(600)
        ]
        assert fast[25][1] == "rate"
        heard = [t for t, why in fast if not why and t > 125.0]
        assert heard and heard[0] <= 120.0 + RATE_RELEARN_S + 5.0, heard[:3]
        assert all(why == "" for t, why in fast if t > heard[0])
        assert chk.nominal_s == pytest.approx(0.2)

    def test_a_log_back_at_its_rate_after_readings_lost_on_the_line_is_heard(self) -> None:
        """A 1-Hz log losing three readings in four on the line for 4 minutes (the gaps
        teach it a 4-s interval), then whole again: heard again within RATE_RELEARN_S +
        10 s (the spell starts once it is babbling), at 1 s. Before, it was babbling at its own rate and dropped for good."""
        chk = ReadingCheck(ReadingLimits())
        assert all(chk.check(float(k), 2.8) == "" for k in range(60))
        for k in range(0, 240, 4):
            chk.check(60.0 + k, 2.8)
        assert chk.nominal_s == pytest.approx(4.0)
        back = [(300.0 + k, chk.check(300.0 + k, 2.8)) for k in range(120)]
        heard = [t for t, why in back if not why and t > 305.0]
        assert heard and heard[0] <= 300.0 + RATE_RELEARN_S + 10.0, back[:10]
        assert chk.nominal_s == pytest.approx(1.0)

    @pytest.mark.parametrize("hz", [5.0, 50.0])
    def test_a_babble_is_not_learnt_as_a_rate(self, hz: float) -> None:
        """A 1-Hz log that babbles 0-7 m/s at random at 5 Hz, or plausible values at
        50 Hz (beyond any log's rate), for 5 minutes: every reading after the first
        seconds is dropped, and its nominal interval stays 1 s."""
        rng = random.Random(2)
        chk = ReadingCheck(ReadingLimits())
        assert all(chk.check(float(k), 2.8) == "" for k in range(60))
        n = int(300 * hz)
        for k in range(n):
            v = rng.uniform(0.0, 7.0) if hz < 10.0 else 2.8 + rng.gauss(0.0, 0.02)
            why = chk.check(60.0 + k / hz, v)
            assert why == "rate" or k < 3 * hz, (k, why)
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


PIPELINE = str(Path(readings.__file__).parent)


def test_a_log_babbling_one_sentence_a_read_keeps_no_memory_per_reading() -> None:
    """A 1-Hz log, then 200 000 reads of one sentence 20 µs apart (4 s of a babble at
    50 kHz): every read is dropped for the rate, the log babbling from the third on,
    and the check's memory does not grow with the babble. Every drop within 10 s was
    kept in a list whose oldest was removed at every reading: 200 000 drops held
    (several MB), and each reading cost the whole list, 55 µs against 0.7."""
    chk = ReadingCheck(ReadingLimits())
    for k in range(60):
        assert chk.check(float(k), 2.8) == ""
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        whys = [chk.check(60.0 + k * 20e-6, 2.8) for k in range(200_000)]
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(
        d.size_diff
        for d in after.compare_to(before, "filename")
        if d.traceback[0].filename.startswith(PIPELINE)
    )
    assert grown < 64_000
    assert set(whys[2:]) == {"rate"}
    # back at 1 Hz: heard again once no read was dropped for BABBLE_S
    assert chk.check(64.0 + BABBLE_S + 1.0, 2.8) == ""


class TestBursts:
    """A log whose readings come in regular small bursts (a multiplexer or logger that
    batches, a USB-serial adapter's latency timer): its rate is its bursts' rate times
    their readings, and a babble is dropped as before."""

    @staticmethod
    def _pairs(
        chk: ReadingCheck, t0: float, seconds: int, apart: float = 0.005, size: int = 2
    ) -> list[str]:
        rng = random.Random(3)
        whys: list[str] = []
        for k in range(seconds):
            jitter = rng.uniform(-0.05, 0.05)
            for i in range(size):
                whys.append(chk.check(t0 + k + jitter + apart * i, 2.8 + rng.gauss(0.0, 0.02)))
        return whys

    @pytest.mark.parametrize(("apart", "size"), [(0.005, 2), (0.005, 3), (0.1, 2)])
    def test_a_log_sending_bursts_once_a_second_is_kept_whole(
        self, apart: float, size: int
    ) -> None:
        """Two readings 5 ms apart once a second (±50 ms), or two 0.1 s apart (a log at
        twice the rate of the lines it is sent with), for 5 minutes: every one kept,
        learnt as bursts of two a second. Three 5 ms apart (beyond RATE_BURST before the
        rate is learnt): dropped at first, heard within RATE_RELEARN_S + 5 s, every
        reading after. Learnt from the longer of the two intervals, a log in pairs was
        heard at 1 Hz and babbling: 37 of 1198 of a real log's kept."""
        chk = ReadingCheck(ReadingLimits())
        whys = self._pairs(chk, 0.0, 300, apart, size)
        heard = 0 if size <= 2 else size * int(RATE_RELEARN_S + 5.0)
        assert set(whys[heard:]) == {""}, whys.index("rate")
        assert chk.burst == size
        assert chk.nominal_s == pytest.approx(1.0, abs=0.06)
        assert chk.max_rate_hz() == pytest.approx(1.05 * size, rel=0.06)

    @pytest.mark.parametrize("learnt", ["pairs", "single"])
    def test_a_100_hz_babble_is_dropped_and_raises_no_rate(self, learnt: str) -> None:
        """A log learnt in pairs (or one reading a second), then babbling 0-14 kn at
        random at 100 Hz for a minute: every reading after the first few is dropped,
        neither its bursts' interval nor their size learnt from the babble; back in
        pairs, heard again once none was dropped for BABBLE_S."""
        rng = random.Random(4)
        chk = ReadingCheck(ReadingLimits())
        if learnt == "pairs":
            assert set(self._pairs(chk, 0.0, 60)) == {""}
        else:
            assert all(chk.check(float(k), 2.8) == "" for k in range(60))
        burst, nominal = chk.burst, chk.nominal_s
        whys = [chk.check(60.0 + k / 100.0, rng.uniform(0.0, 7.2)) for k in range(6000)]
        assert set(whys[5:]) == {"rate"}, [w for w in whys[5:] if w != "rate"][:5]
        assert chk.burst == burst and chk.nominal_s == pytest.approx(nominal, abs=0.01)
        assert chk.max_rate_hz() < 2.2
        if learnt == "pairs":
            back = self._pairs(chk, 121.0, 60)
            assert set(back[2 * int(BABBLE_S) + 2 :]) == {""}
