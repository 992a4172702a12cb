"""Framing of checksummed binary ensembles (PD0 and PD4/PD5), shared by both decoders.

A frame starts with a header byte sequence, carries its length (excluding the
2-byte checksum) at a fixed offset, and ends with the 16-bit sum of every byte
before it. The framer buffers bytes (bounded), emits complete frames whose
checksum matches, and resynchronises after garbage or a corrupted frame by
searching again from the byte after the bad header. A run of garbage is reported
once (one ``framing`` reject), not per byte; a checksum mismatch is one
``checksum`` reject, and the rest of that corrupted frame (skipped while searching
for the next header) is part of the same reject, not a second one, a header in it
whose checksum fails too included.

A frame's checksum is the difference of two running sums kept along the buffer, so it
costs the same whatever the frame's length: a stream of plausible headers claiming
16 KB frames with wrong checksums, one every few bytes, would otherwise sum 16 KB per
header (a hundred microseconds per byte received: 200 KB of it took 19 s), and those
headers are one reject per claimed frame, not one each.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator
from itertools import accumulate

from drivers.errors import ChecksumError, FrameError

MAX_BUFFER = 65536
"""Bytes kept while looking for a frame (memory bound)."""


def sum16(data: bytes | bytearray | memoryview) -> int:
    """16-bit sum of the bytes (the PD0/PD4/PD5 checksum)."""
    return sum(data) & 0xFFFF


class BinaryFramer:
    """Split a byte stream into checksummed frames.

    Args:
        header: the bytes a frame starts with (``b"\\x7f\\x7f"``, ``b"\\x7d"``).
        length_of: given the buffer (at least ``min_header`` bytes from a header),
            the frame length without the checksum, or None if the header is not
            plausible (the framer then searches on).
        min_header: bytes needed before ``length_of`` can decide.
        name: protocol name for messages.
    """

    __slots__ = (
        "_absorb",
        "_buf",
        "_corrupt_left",
        "_garbage",
        "_header",
        "_length_of",
        "_min_header",
        "_name",
        "_sums",
        "_sums_at",
    )

    def __init__(
        self,
        header: bytes,
        length_of: Callable[[bytearray], int | None],
        min_header: int,
        name: str,
    ) -> None:
        self._header = header
        self._length_of = length_of
        self._min_header = min_header
        self._name = name
        self._buf = bytearray()
        self._sums = [0]
        """Running sums of the bytes received: the buffer's byte ``j`` is preceded by
        ``_sums[_sums_at + j]`` (entries before ``_sums_at`` are for bytes dropped)."""
        self._sums_at = 0
        self._corrupt_left = 0
        """Bytes left of the last frame reported with a wrong checksum: a header among
        them whose checksum fails too is part of that reject."""
        self._garbage = 0
        self._absorb = False

    def _drop(self, n: int) -> None:
        """Drop the buffer's n leading bytes (and their running sums)."""
        del self._buf[:n]
        self._corrupt_left -= n
        self._sums_at += n
        if self._sums_at > len(self._buf):  # amortised: the list is moved rarely
            del self._sums[: self._sums_at]
            self._sums_at = 0

    def _sum16(self, n: int) -> int:
        """The 16-bit sum of the buffer's n leading bytes."""
        return (self._sums[self._sums_at + n] - self._sums[self._sums_at]) & 0xFFFF

    def _skip(self, n: int) -> Iterator[FrameError]:
        """Drop n leading bytes as garbage (reported when the run ends)."""
        self._drop(n)
        if not self._absorb:
            self._garbage += n
        return iter(())

    def _end_garbage(self) -> Iterator[FrameError]:
        if self._garbage:
            n, self._garbage = self._garbage, 0
            yield FrameError(f"{n} bytes of garbage between {self._name} frames")

    def feed(self, data: bytes, *, final: bool = False) -> Iterator[bytes | FrameError]:
        """Add bytes; yield complete frames (checksum verified) and framing errors.

        With ``final`` (end of stream) a header whose frame cannot complete any more
        (a corrupted length) is reported and skipped, and the search goes on in the
        bytes after it, so a good frame behind a damaged one is not lost.
        """
        buf = self._buf
        buf += data
        sums = self._sums
        sums += accumulate(data, initial=sums[-1])
        del sums[-len(data) - 1]  # the initial value, already there
        while True:
            i = buf.find(self._header)
            if i < 0:
                # keep a possible partial header at the end
                keep = len(self._header) - 1
                if len(buf) > keep:
                    yield from self._skip(len(buf) - keep)
                return
            if i > 0:
                yield from self._skip(i)
            if len(buf) < self._min_header:
                if final:
                    yield from self._skip(len(buf))
                return
            n = self._length_of(buf)
            if n is None:
                yield from self._skip(1)
                continue
            if len(buf) < n + 2:
                if (yield from self._incomplete(n, final)):
                    continue
                return
            stored = buf[n] | buf[n + 1] << 8
            computed = self._sum16(n)
            if computed != stored:
                if self._corrupt_left <= 0:  # else a header inside the frame reported
                    yield from self._end_garbage()
                    yield ChecksumError(
                        f"{self._name} checksum {stored:04X} != computed {computed:04X}",
                        bytes(buf[:64]),
                    )
                    self._corrupt_left = n + 2
                self._drop(1)  # resync from the byte after this header
                self._absorb = True
                continue
            yield from self._end_garbage()
            self._absorb = False
            frame = bytes(buf[:n])
            self._drop(n + 2)
            yield frame

    def _incomplete(self, n: int, final: bool) -> Generator[FrameError, None, bool]:
        """A header whose frame of ``n`` bytes (and its checksum) is not all in: at the
        end of the stream reported and passed (a corrupted length), in a buffer past
        :data:`MAX_BUFFER` passed as garbage; whether the search goes on (else the frame
        waits for more bytes)."""
        buf = self._buf
        if final:
            if not self._absorb:
                yield from self._end_garbage()
                yield FrameError(
                    f"{self._name} frame truncated at end of stream ({len(buf)} of {n + 2} bytes)",
                    bytes(buf[:64]),
                )
            self._drop(1)
            self._absorb = True
            return True
        if len(buf) > MAX_BUFFER:
            yield from self._skip(1)
            return True
        return False

    def flush(self) -> Iterator[bytes | FrameError]:
        """End of stream: complete what can be, report what never became a frame."""
        yield from self.feed(b"", final=True)
        if self._buf and not self._absorb:
            self._garbage += len(self._buf)
        self._drop(len(self._buf))
        self._absorb = False
        yield from self._end_garbage()
