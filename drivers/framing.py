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

import re
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

    __slots__ = (
        "_buf",
        "_cap",
        "_discarding",
        "_max_length",
        "_one_line",
        "_start_bytes",
        "_start_re",
        "_starts",
    )

    def __init__(self, starts: bytes, max_length: int, cap: int = 1024) -> None:
        if not starts:
            raise ValueError("starts must name at least one start character")
        self._starts = frozenset(starts)
        self._start_bytes = tuple(bytes([c]) for c in sorted(self._starts))
        chars = b"".join(re.escape(b) for b in self._start_bytes)
        self._start_re = re.compile(b"[" + chars + b"]")
        # a start character, no other one, no CR/LF, trailing blanks cut, then CR LF
        self._one_line = re.compile(
            b"([" + chars + b"](?:[^" + chars + b"\r\n]*[^" + chars + b"\r\n \t])?)[ \t]*\r\n"
        ).fullmatch
        self._max_length = max_length
        self._cap = max(cap, max_length)
        self._buf = bytearray()
        self._discarding = False

    def feed(self, data: bytes) -> list[bytes | FrameError]:
        """Add bytes; return every complete frame (or framing error) they finish."""
        buf = self._buf
        if not buf and not self._discarding:
            # the hot path: one whole line per read, CR LF, a single start character
            m = self._one_line(data)
            if m is not None:
                frame = m.group(1)
                if len(frame) + 2 <= self._max_length:
                    return [frame]
        out: list[bytes | FrameError] = []
        if self._discarding:
            data = self._resume(data)
        if not data:
            return out
        if b"\n" not in data and b"\r" not in data:
            self._hold(data, out)
        else:
            self._split(data, out)
        return out

    def _resume(self, data: bytes) -> bytes:
        """While an over-long line is discarded: what follows its terminator (nothing
        while none has come)."""
        cut = _first_terminator(data)
        if cut < 0:
            return b""
        self._discarding = False
        return data[cut + 1 :]

    def _hold(self, data: bytes, out: list[bytes | FrameError]) -> None:
        """Bytes without a terminator: kept for the line they begin, or the line refused
        as too long (and discarded up to its terminator)."""
        buf = self._buf
        if len(buf) + len(data) > self._cap:
            out.append(
                TooLongError(
                    f"line longer than {self._cap} bytes without a terminator",
                    bytes(buf[:64]) + data[:64],
                )
            )
            buf.clear()
            self._discarding = True
            return
        buf += data

    def _split(self, data: bytes, out: list[bytes | FrameError]) -> None:
        """Bytes with a terminator: every line they finish framed, the rest kept."""
        buf = self._buf
        whole = bytes(buf) + data if buf else data
        buf.clear()
        lines = whole.splitlines()  # bytes: splits on CR, LF and CR LF only
        rest = b"" if whole[-1] in (10, 13) else lines.pop()
        for line in lines:
            if line:
                self._line(line, out)
        if not rest:
            return
        if len(rest) > self._cap:
            out.append(
                TooLongError(f"line longer than {self._cap} bytes without a terminator", rest[:128])
            )
            self._discarding = True
        else:
            buf += rest

    def flush(self) -> list[FrameError]:
        """Report an unterminated line left in the buffer, and clear it."""
        out: list[FrameError] = []
        if self._buf:
            raw = bytes(self._buf)
            self._buf.clear()
            out.append(FrameError("line not terminated at end of stream", raw))
        self._discarding = False
        return out

    def _line(self, line: bytes, out: list[bytes | FrameError]) -> None:
        if line[0] in self._starts and self._start_re.search(line, 1) is None:
            self._frame(line.rstrip(b" \t"), out)  # the common case: one frame, nothing spliced
            return
        cuts = sorted(i for b in self._start_bytes for i in _positions(line, b))
        if not cuts:
            out.append(FrameError("line without a start character", line))
            return
        if cuts[0] > 0:
            out.append(FrameError("garbage before the start character", line[: cuts[0]]))
        for a, b in pairwise(cuts):
            out.append(FrameError("truncated frame (a new frame starts inside it)", line[a:b]))
        self._frame(line[cuts[-1] :].rstrip(b" \t"), out)

    def _frame(self, frame: bytes, out: list[bytes | FrameError]) -> None:
        if len(frame) + 2 > self._max_length:
            out.append(
                TooLongError(f"{len(frame) + 2} characters, limit {self._max_length}", frame)
            )
        else:
            out.append(frame)


def _first_terminator(data: bytes) -> int:
    lf, cr = data.find(b"\n"), data.find(b"\r")
    if lf < 0:
        return cr
    if cr < 0:
        return lf
    return min(lf, cr)


def _positions(line: bytes, sub: bytes) -> Iterator[int]:
    i = line.find(sub)
    while i >= 0:
        yield i
        i = line.find(sub, i + 1)


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
