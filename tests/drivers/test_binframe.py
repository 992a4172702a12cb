"""The shared binary framer: checksums, garbage runs, absorbed remains, bounds."""

from __future__ import annotations

from drivers.binframe import MAX_BUFFER, BinaryFramer, sum16
from drivers.errors import ChecksumError, FrameError


def _frame(payload: bytes) -> bytes:
    body = b"\xaa\x55" + bytes([len(payload) + 3]) + payload
    return body + sum16(body).to_bytes(2, "little")


def _framer() -> BinaryFramer:
    return BinaryFramer(b"\xaa\x55", lambda b: b[2] if b[2] >= 3 else None, 3, "TEST")


def test_sum16() -> None:
    """sum16 is the byte sum modulo 2**16: 0 for no bytes, and it wraps past 65535."""
    assert sum16(b"") == 0
    assert sum16(b"\xff" * 300) == (255 * 300) & 0xFFFF


def test_frames_and_garbage_runs() -> None:
    """Each run of garbage before or between frames is one framing error giving its byte count, and
    the frames around it come out whole."""
    f = _framer()
    data = b"xx" + _frame(b"one") + b"yyy" + _frame(b"two")
    out = list(f.feed(data)) + list(f.flush())
    frames = [o for o in out if isinstance(o, bytes)]
    errors = [o for o in out if isinstance(o, FrameError)]
    assert [fr[3:] for fr in frames] == [b"one", b"two"]
    assert len(errors) == 2 and all(e.reason == "framing" for e in errors)
    assert "2 bytes" in str(errors[0]) and "3 bytes" in str(errors[1])


def test_corrupted_frame_is_one_checksum_error() -> None:
    """A frame with one flipped payload bit is a single checksum error (its remains are absorbed,
    not reported again) and the next frame still comes out."""
    bad = bytearray(_frame(b"corrupted payload"))
    bad[5] ^= 1
    f = _framer()
    out = list(f.feed(bytes(bad) + _frame(b"ok"))) + list(f.flush())
    assert [type(o) for o in out] == [ChecksumError, bytes]


def test_implausible_header_is_skipped() -> None:
    """A header whose length byte is implausible is skipped and the good frame right behind it is
    still found."""
    f = _framer()
    out = list(f.feed(b"\xaa\x55\x01" + _frame(b"z"))) + list(f.flush())
    assert out[-1] == _frame(b"z")[:-2]


def test_buffer_bounded_when_a_length_never_completes() -> None:
    """A header announcing a frame longer than the buffer bound never lets the buffer grow much past
    MAX_BUFFER however many bytes follow."""
    f = BinaryFramer(b"\xaa\x55", lambda b: 60000, 3, "TEST")
    for _ in range(10):
        list(f.feed(b"\xaa\x55\x00" + b"\x00" * 10_000))
    assert len(f._buf) <= MAX_BUFFER + 10_100
