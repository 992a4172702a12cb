"""Fake devices: the reader on the link receives exactly the capture's bytes, in order."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from drivers.io.capture import CaptureReader
from drivers.io.fake import FakeDevice
from drivers.io.port import SerialSource


def _collect(link: Path, n: int, timeout: float = 10.0) -> bytes:
    deadline = time.monotonic() + timeout
    while not link.exists():
        assert time.monotonic() < deadline
        time.sleep(0.01)
    fd = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    out = b""
    try:
        while len(out) < n and time.monotonic() < deadline:
            try:
                out += os.read(fd, 65536)
            except BlockingIOError:
                time.sleep(0.005)
    finally:
        os.close(fd)
    return out


@pytest.fixture
def capture(write_capture: Callable[..., Path]) -> Path:
    records = []
    for k in range(300):
        records.append((100.0 + k * 0.01, "emlog1", b"$VWVHW,,T,,M,%d.00,N,,K*00" % k, False))
        records.append((100.0 + k * 0.01 + 0.001, "dvl", bytes([0x7F, 0x7F, k % 256]) * 3, True))
    return write_capture({"emlog1": "nmea0183", "dvl": "pd0"}, records)


@pytest.mark.parametrize("speed", [None, 20.0])
def test_reader_receives_the_ports_bytes(
    capture: Path, tmp_path: Path, speed: float | None
) -> None:
    """A FakeDevice, paced or unpaced, delivers exactly its port's bytes in order, reports all 300
    records sent and removes its link when stopped."""
    expected = b"".join(r.data for r in CaptureReader(capture) if r.port == "emlog1")
    dev = FakeDevice(capture, "emlog1", tmp_path / "emlog1", speed=speed).start()
    try:
        got = _collect(tmp_path / "emlog1", len(expected))
        assert got == expected
        assert dev.finished.wait(5) and dev.sent_records == 300
    finally:
        dev.stop()
        dev.join(5)
    assert not (tmp_path / "emlog1").exists()


def test_binary_port_and_loop(capture: Path, fake_device: Callable[..., FakeDevice]) -> None:
    """A looping FakeDevice on a binary port sends the port's bytes again and again, never finishes
    by itself, and removes its link once stopped."""
    once = b"".join(r.data for r in CaptureReader(capture) if r.port == "dvl")
    dev = fake_device(capture, "dvl", loop=True)
    got = _collect(dev.link, 2 * len(once) + 10)
    assert got.startswith(once + once)
    assert not dev.finished.is_set()  # looping until stopped
    dev.stop()
    assert dev.finished.wait(5) and dev.stopped
    dev.join(5)
    assert not dev.link.exists()


def test_timing_is_honoured(
    write_capture: Callable[..., Path], fake_device: Callable[..., FakeDevice]
) -> None:
    # 1 s of capture at twice real time takes at least 0.5 s (only a lower bound is
    # asserted: a loaded machine may be slower, never faster)
    """At speed 2 one second of capture takes at least half a second to arrive; unpaced, all 11
    records arrive intact."""
    records = [(50.0 + 0.1 * k, "e", b"$VWVHW,%d*00" % k, False) for k in range(11)]
    cap = write_capture({"e": "nmea0183"}, records)
    expected = b"".join(b"$VWVHW,%d*00\r\n" % k for k in range(11))
    for speed, link in ((2.0, "timed"), (None, "fast")):
        dev = fake_device(cap, "e", speed=speed, link=cap.parent / link)
        t0 = time.monotonic()
        assert _collect(dev.link, len(expected)) == expected
        assert dev.finished.wait(10)
        took = time.monotonic() - t0
        if speed is not None:
            assert took >= 0.5 * 0.99, took
        else:
            assert dev.sent_records == 11


def test_unknown_port_and_bad_speed(capture: Path, tmp_path: Path) -> None:
    """FakeDevice refuses a port the capture does not declare and a speed of zero."""
    with pytest.raises(ValueError, match="no port"):
        FakeDevice(capture, "gps", tmp_path / "x")
    with pytest.raises(ValueError, match="speed"):
        FakeDevice(capture, "dvl", tmp_path / "x", speed=0.0)


def _read_until(src: SerialSource, n: int, deadline: float) -> bytes:
    """Read ``src`` until ``n`` bytes came or the deadline passed."""
    got = b""
    while len(got) < n and time.monotonic() < deadline:
        c = src.read()
        if c is None:
            time.sleep(0.002)
            continue
        got += c[1]
    return got


def test_serial_source_reads_a_fake_device_and_survives_its_restart(
    capture: Path, tmp_path: Path
) -> None:
    """SerialSource reads a FakeDevice's exact bytes, notices the device going away, and reads its
    replacement at the same path after exactly one reconnect."""
    link = tmp_path / "emlog1"
    expected = b"".join(r.data for r in CaptureReader(capture) if r.port == "emlog1")
    src = SerialSource("emlog1", str(link), backoff_s=(0.01,))
    for round_ in range(2):
        dev = FakeDevice(capture, "emlog1", link, speed=None).start()
        # generous: only catches a hang (it once hit 10 s under heavy load)
        deadline = time.monotonic() + 30
        while not src.is_open and time.monotonic() < deadline:
            if round_ == 0:
                src.open()
            src.poll()
            time.sleep(0.01)
        got = _read_until(src, len(expected), deadline)
        assert got == expected, f"round {round_}"
        dev.stop()  # the device goes away: the source notices and retries
        dev.join(5)
        while src.is_open and time.monotonic() < deadline:
            src.read()
            time.sleep(0.005)
        assert not src.is_open
    assert src.reconnects == 1
    src.close()


def test_a_reader_slow_to_open_still_gets_the_first_record(
    capture: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """pyserial's open ends by flushing the input queue; on a loaded machine that
    flush comes well after the device saw the reader: the device waits settle_s."""
    import serial.serialposix

    configure = vars(serial.serialposix.Serial)["_reconfigure_port"]

    def slow(self: serial.serialposix.Serial, *args: object, **kw: object) -> None:
        time.sleep(0.02)  # between os.open (the device sees a reader) and the flush
        configure(self, *args, **kw)

    monkeypatch.setattr("serial.serialposix.Serial._reconfigure_port", slow)
    link = tmp_path / "emlog1"
    expected = b"".join(r.data for r in CaptureReader(capture) if r.port == "emlog1")
    dev = FakeDevice(capture, "emlog1", link, speed=None).start()
    src = SerialSource("emlog1", str(link))
    try:
        assert src.open()
        assert _read_until(src, len(expected), time.monotonic() + 10) == expected
    finally:
        src.close()
        dev.stop()
        dev.join(5)


def test_fake_capture_serves_several_ports(capture: Path, tmp_path: Path) -> None:
    """One FakeCapture serves each port's bytes at its own link; unknown ports are refused."""
    from drivers.io.fake import FakeCapture

    with pytest.raises(ValueError, match="no port 'gps'"):
        FakeCapture(capture, {"emlog1": tmp_path / "a", "gps": tmp_path / "b"})
    assert not (tmp_path / "a").exists()
    links = {"emlog1": tmp_path / "e", "dvl": tmp_path / "d"}
    expected = {p: b"".join(r.data for r in CaptureReader(capture) if r.port == p) for p in links}
    fds = {}
    dev = FakeCapture(capture, links, speed=None).start()
    try:
        deadline = time.monotonic() + 10
        while not all(link.exists() for link in links.values()):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        fds = {
            p: os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK) for p, link in links.items()
        }
        got = dict.fromkeys(links, b"")
        while any(len(got[p]) < len(expected[p]) for p in links) and time.monotonic() < deadline:
            for p, fd in fds.items():
                try:
                    got[p] += os.read(fd, 65536)
                except BlockingIOError:
                    time.sleep(0.002)
        assert got == expected
        assert dev.finished.wait(5) and dev.sent == {"emlog1": 300, "dvl": 300}
    finally:
        for fd in fds.values():
            os.close(fd)
        dev.stop()
        dev.join(5)
