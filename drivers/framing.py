"""Line framing for the text protocols (NMEA 0183, PD6/PD13) and NMEA checksums.

:class:`LineFramer` buffers bytes, splits on any mix of CR and LF, caps the
buffered length (memory stays bounded whatever a port sends) and resynchronises
on the start characters: a line that does not begin with one loses its leading
garbage, and a line holding two start characters (a truncated sentence spliced
to the next one) is cut at each, every fragment but the last being a framing
error. Frames come out without their terminator.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from collections.abc import Iterator
from itertools import pairwise

from drivers.errors import ChecksumError, FrameError, MissingChecksumError, TooLongError

_HEX = b"0123456789ABCDEFabcdef"


class LineFramer:
    """Split a byte stream into lines that start with one of ``starts``.

    Args:
        starts: the bytes that may begin a frame, e.g. ``b"$!"`` for NMEA.
        max_length: longest accepted frame in characters *including* the start
            character and a CR LF terminator (NMEA: 82). Longer complete lines
            come out as :class:`TooLongError`.
        cap: hard limit of the buffer; a line growing past it is dropped up to
            the next terminator and reported once as :class:`TooLongError`.
    """

    __slots__ = ("_buf", "_cap", "_discarding", "_max_length", "_starts")

    def __init__(self, starts: bytes, max_length: int, cap: int = 1024) -> None:
        if not starts:
            raise ValueError("starts must name at least one start character")
        self._starts = frozenset(starts)
        self._max_length = max_length
        self._cap = max(cap, max_length)
        self._buf = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> Iterator[bytes | FrameError]:
        """Add bytes; yield every complete frame (or framing error) they finish."""
        buf = self._buf
        start = 0
        n = len(data)
        while start < n:
            # find the next terminator (CR or LF) in data[start:]
            lf = data.find(b"\n", start)
            cr = data.find(b"\r", start)
            if lf < 0 and cr < 0:
                end = -1
            elif lf < 0:
                end = cr
            elif cr < 0:
                end = lf
            else:
                end = min(lf, cr)
            piece = data[start:] if end < 0 else data[start:end]
            if self._discarding:
                if end < 0:
                    return
                self._discarding = False
            elif len(buf) + len(piece) > self._cap:
                yield TooLongError(
                    f"line longer than {self._cap} bytes without a terminator",
                    bytes(buf[:64]) + piece[:64],
                )
                buf.clear()
                if end < 0:
                    self._discarding = True
                    return
            else:
                buf += piece
                if end < 0:
                    return
                if buf:
                    line = bytes(buf)
                    buf.clear()
                    yield from self._line(line)
            start = end + 1

    def flush(self) -> Iterator[FrameError]:
        """Report an unterminated line left in the buffer, and clear it."""
        if self._buf:
            raw = bytes(self._buf)
            self._buf.clear()
            yield FrameError("line not terminated at end of stream", raw)
        self._discarding = False

    def _line(self, line: bytes) -> Iterator[bytes | FrameError]:
        starts = self._starts
        cuts = [i for i, c in enumerate(line) if c in starts]
        if not cuts:
            yield FrameError("line without a start character", line)
            return
        if cuts[0] > 0:
            yield FrameError("garbage before the start character", line[: cuts[0]])
        for a, b in pairwise(cuts):
            yield FrameError("truncated frame (a new frame starts inside it)", line[a:b])
        frame = line[cuts[-1] :].rstrip(b" \t")
        if len(frame) + 2 > self._max_length:
            yield TooLongError(f"{len(frame) + 2} characters, limit {self._max_length}", frame)
            return
        yield frame


def nmea_checksum(body: bytes) -> int:
    """XOR of the bytes between the start character and ``*`` (both excluded)."""
    c = 0
    for b in body:
        c ^= b
    return c


def split_nmea(frame: bytes, *, required: bool = True) -> bytes:
    """Verify and strip an NMEA frame's checksum.

    Args:
        frame: ``$...*hh`` or ``!...*hh`` without CR LF.
        required: reject a frame without ``*hh`` (else accept it unchecked).

    Returns:
        The body between the start character and ``*`` (both excluded).

    Raises:
        MissingChecksumError: no ``*hh`` and ``required``.
        ChecksumError: the checksum is malformed or does not match.
    """
    star = frame.rfind(b"*")
    if star < 0:
        if required:
            raise MissingChecksumError("checksum missing", frame)
        return frame[1:]
    digits = frame[star + 1 :]
    if len(digits) != 2 or digits[0] not in _HEX or digits[1] not in _HEX:
        raise ChecksumError(f"malformed checksum field {digits[:8]!r}", frame)
    body = frame[1:star]
    if nmea_checksum(body) != int(digits, 16):
        raise ChecksumError(
            f"checksum {digits.decode('ascii')} != computed {nmea_checksum(body):02X}", frame
        )
    return body


def with_checksum(body: str, start: str = "$") -> str:
    """Build a sentence from its body: ``start + body + '*hh'`` (no CR LF)."""
    return f"{start}{body}*{nmea_checksum(body.encode('ascii')):02X}"
