"""What :class:`~emlogd.pipeline.core.Pipeline`'s ``feed``, ``tick`` and ``flush`` return.

The caller delivers it: the sentences in the order they were made (:class:`Emit`), the
events worth a log line (:class:`Event`) and the calibrations to persist, gathered in one
:class:`Output` per call.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from emlogd.pipeline.calibration import Calibration


class Emit(NamedTuple):
    """A sentence to send to every output sink (a named tuple: one is made per sentence,
    in a third of a frozen dataclass's time).

    Attributes:
        t: the receive time of the UUT sentence that caused it, s.
        port: the UUT port.
        sentence: the NMEA sentence without CR LF (checksummed, ≤ 82 characters).
    """

    t: float
    port: str
    sentence: str


@dataclass(frozen=True, slots=True)
class Event:
    """Something worth a log line (state changes, lag found, reference lost...)."""

    t: float
    port: str
    kind: str
    detail: Mapping[str, object]


class Output:
    """What one :meth:`Pipeline.feed`, :meth:`Pipeline.tick` or :meth:`Pipeline.flush`
    call produced, returned to the caller, which delivers it: the sentences in the order
    they were made (corrected speeds, status, VDR, fused speed), the events, and the
    calibrations to persist. Each call returns a new one; the pipeline keeps no
    reference to it and calls nothing of the caller's.

    A plain class (one is made per record): half a list-factory dataclass's construction.
    """

    __slots__ = ("emits", "events", "persist")

    def __init__(self) -> None:
        self.emits: list[Emit] = []
        self.events: list[Event] = []
        self.persist: list[Calibration] = []

    def add(self, other: Output) -> None:
        """Append another call's output after this one's (a caller collecting several)."""
        self.emits.extend(other.emits)
        self.events.extend(other.events)
        self.persist.extend(other.persist)
