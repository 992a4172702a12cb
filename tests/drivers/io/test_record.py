"""Recording live ports into a capture file (drivers.io.record), on real ptys."""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import pytest

from drivers import DeviceError
from drivers.io.capture import CaptureReader
from drivers.io.record import MAX_PARTIAL_BYTES, PortSpec, record


def test_text_lines_and_binary_chunks_are_stored_with_receive_times(
    pty_pair: tuple[int, int, str], tmp_path: Path
) -> None:
    """A text port's bytes become one record per line (split across writes), in time order."""
    master, _slave, path = pty_pair
    out = tmp_path / "rec.cap"
    events: list[str] = []

    def talk() -> None:
        time.sleep(0.3)
        os.write(master, b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n$VWVHW,,T,")
        time.sleep(0.3)
        os.write(master, b",M,3.60,N,6.67,K*6A\r\n")

    writer = threading.Thread(target=talk)
    writer.start()
    counts = record(
        [PortSpec("log", path, 4800, "nmea0183")],
        out,
        duration_s=1.5,
        on_event=lambda ev: events.append(ev.kind),
    )
    writer.join()
    assert counts == {"log": 2}
    reader = CaptureReader(out)
    recs = list(reader)
    assert reader.ports == {"log": "nmea0183"}
    assert [r.data for r in recs] == [
        b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n",
        b"$VWVHW,,T,,M,3.60,N,6.67,K*6A\r\n",
    ]
    assert recs[1].t - recs[0].t == pytest.approx(0.3, abs=0.2)
    assert "connected" in events


def test_a_missing_device_fails_before_writing(tmp_path: Path) -> None:
    """A port that cannot be opened at the start raises and leaves no file."""
    out = tmp_path / "rec.cap"
    with pytest.raises(DeviceError, match="port log"):
        record([PortSpec("log", str(tmp_path / "nothing"), 4800, "nmea0183")], out)
    assert not out.exists()


def test_should_stop_ends_the_recording(pty_pair: tuple[int, int, str], tmp_path: Path) -> None:
    """should_stop is polled while waiting: the recording ends without any input."""
    _master, _slave, path = pty_pair
    t0 = time.monotonic()
    deadline = t0 + 0.5
    counts = record(
        [PortSpec("log", path, 4800, "nmea0183")],
        tmp_path / "rec.cap",
        should_stop=lambda: time.monotonic() > deadline,
    )
    assert counts == {"log": 0}
    assert time.monotonic() - t0 < 5.0


def test_a_wall_clock_stepped_back_moves_no_stamp(
    pty_pair: tuple[int, int, str], tmp_path: Path
) -> None:
    """The wall clock stepped back an hour just after the recording starts (NTP or GNSS
    time setting a computer that booted with a wrong clock): the records are stamped on
    the timeline anchored at the start, 0.3 s apart as they came. Stamped with the wall
    clock, every record of that hour took the last time written before the step."""
    master, _slave, path = pty_pair
    out = tmp_path / "rec.cap"
    start = time.time()
    reads = iter([start])

    def stepped() -> float:
        return next(reads, time.time() - 3600.0)

    def talk() -> None:
        for speed in (b"3.50,N,6.48", b"3.60,N,6.67"):
            time.sleep(0.3)
            os.write(master, b"$VWVHW,,T,,M," + speed + b",K*6A\r\n")

    writer = threading.Thread(target=talk)
    writer.start()
    record([PortSpec("log", path, 4800, "nmea0183")], out, duration_s=1.2, clock=stepped)
    writer.join()
    recs = list(CaptureReader(out))
    assert len(recs) == 2
    assert recs[0].t >= start
    assert recs[1].t - recs[0].t == pytest.approx(0.3, abs=0.2)


def test_a_text_port_that_never_ends_its_line_is_stored_in_bounded_chunks(
    pty_pair: tuple[int, int, str], tmp_path: Path
) -> None:
    """A text port sending 256 KiB without a newline (garbage, a wrong baud rate) in
    64-byte writes, then a sentence: the capture replays the very bytes sent, and no
    record holds more than a read past MAX_PARTIAL_BYTES. The unended line was held whole
    and copied at every read: memory without bound, each read's cost growing with it
    (20 s of 32 KB/s in 64-byte writes cost 4.7 s of CPU, 0.6 s now)."""
    master, _slave, path = pty_pair
    out = tmp_path / "rec.cap"
    garbage = bytes(range(11, 75)) * 4096  # no newline: 256 KiB
    sentence = b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n"

    def talk() -> None:
        time.sleep(0.2)
        for i in range(0, len(garbage), 64):
            os.write(master, garbage[i : i + 64])
        os.write(master, sentence)

    writer = threading.Thread(target=talk)
    writer.start()
    counts = record([PortSpec("log", path, 115200, "nmea0183")], out, duration_s=3.0)
    writer.join()
    recs = list(CaptureReader(out))
    assert b"".join(r.data for r in recs) == garbage + sentence
    assert max(len(r.data) for r in recs) <= MAX_PARTIAL_BYTES + 4096  # a read past it
    assert counts == {"log": len(recs)}
