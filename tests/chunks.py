"""Feeding a stream decoder or framer its input in chunks, as a serial port delivers it."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol, TypeVar

T_co = TypeVar("T_co", covariant=True)


class Stream(Protocol[T_co]):
    """What takes bytes in pieces: a decoder or a framer."""

    def feed(self, data: bytes) -> Iterable[T_co]: ...

    def flush(self) -> Iterable[T_co]: ...


def feed_in_chunks(stream: Stream[T_co], data: bytes, cuts: Iterable[int]) -> list[T_co]:
    """What ``stream`` gives for ``data`` cut at the offsets ``cuts`` (in any order), then
    flushed."""
    out: list[T_co] = []
    prev = 0
    for c in sorted(cuts):
        out.extend(stream.feed(data[prev:c]))
        prev = c
    out.extend(stream.feed(data[prev:]))
    out.extend(stream.flush())
    return out
