"""Line framing and NMEA checksums."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import ChecksumError, FrameError, MissingChecksumError, TooLongError
from drivers.framing import LineFramer, nmea_checksum, split_nmea, with_checksum
from tests.chunks import feed_in_chunks
from tests.profiles import by_profile


def _feed(framer: LineFramer, data: bytes) -> list[bytes | FrameError]:
    return list(framer.feed(data)) + list(framer.flush())


def test_any_mix_of_terminators() -> None:
    """CR LF, LF, CR and LF CR each end a line, an empty line yields nothing, and frames come out
    without their terminator."""
    f = LineFramer(b"$", 82)
    out = _feed(f, b"$A*00\r\n$B*00\n$C*00\r$D*00\n\r\n")
    assert out == [b"$A*00", b"$B*00", b"$C*00", b"$D*00"]


def test_garbage_and_spliced_frames_are_framing_errors() -> None:
    """Bytes before the start character and a sentence cut short by a new start character are
    framing errors carrying their raw bytes, and the last fragment is the frame."""
    f = LineFramer(b"$!", 82)
    out = _feed(f, b"xx$GPGGA,1$VWVHW,2*00\r\n")
    assert isinstance(out[0], FrameError) and out[0].raw == b"xx"
    assert isinstance(out[1], FrameError) and out[1].raw == b"$GPGGA,1"
    assert out[2] == b"$VWVHW,2*00"


def test_too_long_and_cap() -> None:
    """A terminated line over max_length is a TooLongError and the next line still passes, while a
    line growing past the cap is reported once, empties the buffer and is dropped up to its
    terminator."""
    f = LineFramer(b"$", 82, cap=256)
    out = _feed(f, b"$" + b"A" * 80 + b"\r\n" + b"$" + b"B" * 78 + b"\r\n")
    assert isinstance(out[0], TooLongError)
    assert out[1] == b"$" + b"B" * 78
    f = LineFramer(b"$", 82, cap=256)
    out = list(f.feed(b"$" + b"C" * 10_000))
    assert len(out) == 1 and isinstance(out[0], TooLongError)
    assert len(f._buf) == 0
    out = _feed(f, b"more junk\n$OK*00\n")
    assert out == [b"$OK*00"]  # the rest of the long line is dropped up to its terminator


def test_unterminated_line_reported_at_flush() -> None:
    """An unterminated line yields nothing while fed and becomes one framing error carrying its
    bytes at flush."""
    f = LineFramer(b"$", 82)
    assert list(f.feed(b"$PARTIAL")) == []
    (err,) = list(f.flush())
    assert isinstance(err, FrameError) and err.raw == b"$PARTIAL"


def test_checksum_helpers() -> None:
    """with_checksum appends the XOR checksum that split_nmea verifies (lowercase hex accepted) and
    strips, a wrong or malformed checksum is a ChecksumError, and a missing one is refused unless
    not required."""
    s = with_checksum("VWVHW,,T,,M,3.50,N,6.48,K")
    assert s.endswith("*" + format(nmea_checksum(s[1:-3].encode()), "02X"))
    assert split_nmea(s.encode()) == s[1:-3].encode()
    lower_hex = with_checksum("VWVHW,,T,,M,3.49,N,6.46,K")[:-1] + "e"  # "*5E" sent as "*5e"
    assert split_nmea(lower_hex.encode()) == b"VWVHW,,T,,M,3.49,N,6.46,K"
    with pytest.raises(ChecksumError, match="computed"):
        split_nmea(s[:-1].encode() + b"0" if s[-1] != "0" else s[:-1].encode() + b"1")
    with pytest.raises(MissingChecksumError):
        split_nmea(b"$VWVHW,1")
    assert split_nmea(b"$VWVHW,1", required=False) == b"VWVHW,1"
    with pytest.raises(ChecksumError, match="malformed"):
        split_nmea(b"$VWVHW,1*G1")


@settings(max_examples=200, deadline=None)
@given(
    lines=st.lists(st.text(alphabet="ABC,.0123", max_size=30), max_size=10),
    cuts=st.lists(st.integers(0, 400), max_size=10),
)
def test_chunking_never_changes_the_frames(lines: list[str], cuts: list[int]) -> None:
    """Any split of a stream of lines into chunks gives the same frames and errors as the stream fed
    whole."""
    data = b"".join(b"$" + ln.encode() + b"\r\n" for ln in lines)
    whole = _feed(LineFramer(b"$", 82), data)
    f = LineFramer(b"$", 82)
    out = feed_in_chunks(f, data, cuts)
    assert [o if isinstance(o, bytes) else (type(o), o.raw) for o in out] == [
        o if isinstance(o, bytes) else (type(o), o.raw) for o in whole
    ]


@pytest.mark.fuzz
@settings(max_examples=by_profile(300), deadline=None)
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=10))
def test_any_chunking_of_arbitrary_bytes_gives_the_same_frames(
    data: bytes, cuts: list[int]
) -> None:
    """Any split of arbitrary bytes into chunks gives the same frames and reject reasons as the
    bytes fed whole."""
    whole = _feed(LineFramer(b"$!", 82), data)
    f = LineFramer(b"$!", 82)
    out = feed_in_chunks(f, data, cuts)
    assert [o if isinstance(o, bytes) else o.reason for o in out] == [
        o if isinstance(o, bytes) else o.reason for o in whole
    ]


@pytest.mark.fuzz
@settings(max_examples=by_profile(500), deadline=None)
@given(st.lists(st.sampled_from([b"$", b"!", b" ", b"\t", b"A", b",", b"*", b"\r", b"\x00"]),
                max_size=90).map(b"".join))  # fmt: skip
def test_one_line_fast_path_equals_byte_by_byte(line: bytes) -> None:
    """A whole line ending CR LF (the hot path) frames as it does fed a byte at a time."""
    data = line + b"\r\n"
    fast = LineFramer(b"$!", 82).feed(data)
    slow_framer = LineFramer(b"$!", 82)
    slow = [x for i in range(len(data)) for x in slow_framer.feed(data[i : i + 1])]
    assert [(type(x), x if isinstance(x, bytes) else (str(x), x.raw)) for x in fast] == [
        (type(x), x if isinstance(x, bytes) else (str(x), x.raw)) for x in slow
    ]
