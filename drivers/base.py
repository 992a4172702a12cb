"""The decoder contract every protocol module implements (docs/ARCHITECTURE.md).

A decoder turns bytes into frozen records: ``feed(chunk)`` accepts arbitrary chunk
boundaries (one byte at a time gives the same records as the whole stream) and
yields every record completed by that chunk; ``parse_frame(frame)`` decodes one
complete frame. :class:`Decoder` is generic in the protocol's record type ``R``: each
protocol module names the union of its records (``NmeaRecord``, ``Pd6Record``,
``Pd0Record``, ``Pd45Record``) and its decoder is a ``Decoder`` of it, so ``feed``
yields ``R | Rejected``, ``parse_frame`` returns ``R`` and ``speed_records`` takes an
``R``. Every rejected frame increments exactly one per-reason counter
in :attr:`Decoder.counters`, whatever the error policy:

- ``errors="raise"``: the :class:`~drivers.errors.FrameError` is raised from
  ``feed``; frames already split from the chunk stay queued and come out on the
  next call, so nothing after the bad frame is lost;
- ``errors="yield"``: a :class:`~drivers.records.Rejected` record is yielded;
- ``errors="skip"``: the frame is dropped (but counted). The daemon runs this way.

A frame whose decoding fails with any other exception (a bug, or a library's
surprise) is contained the same way: it becomes a :class:`~drivers.errors.FrameError`
of reason ``internal`` naming the exception, and the frames after it are decoded.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import ClassVar, Generic, Literal, Protocol, TypeVar

from drivers.errors import REJECT_REASONS, FrameError, RejectReason
from drivers.records import Rejected, SpeedRecord

R = TypeVar("R")
"""A protocol's record type (the union of its record dataclasses)."""

ErrorPolicy = Literal["raise", "yield", "skip"]
ChecksumPolicy = Literal["required", "optional"]

Use = Literal["uut", "bottom", "water", "speed", "gnss"]
"""What a port's data can be to a calibration (:attr:`Decoder.uses`):

- ``uut``: an EMlog's reading to calibrate and correct (VHW/VBW);
- ``bottom``, ``water``: a DVL's bottom or water-mass track as the reference;
- ``speed``: an EMlog's reading as the reference;
- ``gnss``: GNSS speed and course over ground (RMC/VTG) as the reference.

The last four are the values of a calibration's ``reference_field``."""

NMEA_MAX_LENGTH = 82
"""NMEA 0183 limit: characters including ``$`` and CR LF."""

LINE_BUFFER_CAP = 1024
"""Hard cap on a buffered text line in bytes, whatever the leniency: bounds memory."""

SHORTEST_LINE_LIMIT = 8
"""The lowest line limit a port may set (:attr:`DecoderOptions.max_length`)."""


@dataclass(frozen=True, slots=True)
class DecoderOptions:
    """Per-port decoding options.

    Attributes:
        checksum: ``"required"`` (default) rejects an NMEA sentence without ``*hh``;
            ``"optional"`` accepts it. A wrong checksum is always rejected.
        max_length: longest accepted text line in characters, counting the start
            character and CR LF (NMEA: 82). Real logs contain longer lines, so a
            port can be made lenient by raising it (at most ``LINE_BUFFER_CAP``).
    """

    checksum: ChecksumPolicy = "required"
    max_length: int = NMEA_MAX_LENGTH

    def __post_init__(self) -> None:
        if self.checksum not in ("required", "optional"):
            raise ValueError(f"checksum must be 'required' or 'optional', not {self.checksum!r}")
        if not SHORTEST_LINE_LIMIT <= self.max_length <= LINE_BUFFER_CAP:
            raise ValueError(
                f"max_length must be within {SHORTEST_LINE_LIMIT}..{LINE_BUFFER_CAP}, "
                f"not {self.max_length}"
            )


@dataclass(slots=True)
class DecoderCounters:
    """Per-port counts: decoded records and rejected frames by reason."""

    records: int = 0
    rejects: dict[RejectReason, int] = field(
        default_factory=lambda: dict.fromkeys(REJECT_REASONS, 0)
    )

    @property
    def rejected(self) -> int:
        """Total rejected frames."""
        return sum(self.rejects.values())

    def as_dict(self) -> dict[str, object]:
        """A JSON-ready copy: ``{"records": n, "rejects": {reason: n, ...}}``."""
        return {"records": self.records, "rejects": dict(self.rejects)}


class Decoder(ABC, Generic[R]):
    """Base class of every protocol decoder; ``R`` is the protocol's record type.

    Subclasses implement :meth:`_split` (framing: bytes to complete frames or
    framing errors) and :meth:`parse_frame` (one frame to one record), and
    :meth:`speed_records` (the mapping to the common speed record).

    Args:
        port: name of the port, copied into speed records and rejects.
        errors: the bad-input policy (see the module docstring).
        options: per-port decoding options.
    """

    protocol: ClassVar[str]
    """Registry name, e.g. ``"nmea0183"``."""

    binary: ClassVar[bool]
    """True for binary protocols (stored as ``hex:`` chunks in a capture)."""

    uses: ClassVar[frozenset[Use]] = frozenset()
    """What a port speaking the protocol can be to a calibration (:data:`Use`); none
    unless the decoder says so."""

    heading: ClassVar[bool] = False
    """The protocol's bottom and water track carry the instrument's heading (taken as
    true), so a UUT referenced to it has a heading without a heading port."""

    def __init__(
        self,
        port: str = "",
        *,
        errors: ErrorPolicy = "raise",
        options: DecoderOptions | None = None,
    ) -> None:
        if errors not in ("raise", "yield", "skip"):
            raise ValueError(f"errors must be 'raise', 'yield' or 'skip', not {errors!r}")
        self.port = port
        self.errors: ErrorPolicy = errors
        self.options = options if options is not None else DecoderOptions()
        self.counters = DecoderCounters()
        self._pending: deque[bytes | FrameError] = deque()
        self._ready()

    def _ready(self) -> None:
        """Called once at the end of construction, the port, policy and options set: a
        subclass's own state (the base has none)."""

    def feed(self, data: bytes) -> Iterator[R | Rejected]:
        """Decode a chunk of received bytes.

        Args:
            data: any number of bytes, cut anywhere.

        Yields:
            Records completed by this chunk, and :class:`Rejected` records when
            ``errors="yield"``.

        Raises:
            FrameError: for a rejected frame when ``errors="raise"``.
        """
        self._pending.extend(self._split(data))
        while self._pending:
            item = self._pending.popleft()
            if isinstance(item, FrameError):
                yield from self._reject(item)
                continue
            try:
                record = self.parse_frame(item)
            except FrameError as exc:
                if not exc.raw:
                    exc.raw = item[:256]
                yield from self._reject(exc)
                continue
            except Exception as exc:  # contained: one frame is lost, not the stream
                err = FrameError(f"{type(exc).__name__}: {exc}", item, reason="internal")
                err.__cause__ = exc
                yield from self._reject(err)
                continue
            self.counters.records += 1
            yield record

    def flush(self) -> Iterator[R | Rejected]:
        """End of stream: reject (and count) any incomplete frame still buffered."""
        self._pending.extend(self._flush())
        yield from self.feed(b"")

    def decode_all(self, data: bytes) -> list[R | Rejected]:
        """Decode a whole byte string and flush: a convenience for files and tests."""
        out = list(self.feed(data))
        out.extend(self.flush())
        return out

    def _reject(self, exc: FrameError) -> Iterator[Rejected]:
        self.counters.rejects[exc.reason] += 1
        if self.errors == "raise":
            raise exc
        if self.errors == "yield":
            yield Rejected(self.port, exc.reason, str(exc), exc.raw)

    @abstractmethod
    def _split(self, data: bytes) -> Iterable[bytes | FrameError]:
        """Append ``data`` to the framer and return the frames (or framing errors) it completes."""

    def _flush(self) -> Iterable[bytes | FrameError]:
        """Return framing errors for incomplete data left in the framer; clear it."""
        return ()

    @abstractmethod
    def parse_frame(self, frame: bytes) -> R:
        """Decode one complete frame into one record.

        Raises:
            FrameError: (a subclass naming the reason) if the frame is invalid.
        """

    def speed_records(self, record: R) -> tuple[SpeedRecord, ...]:
        """Map a record of this protocol to zero or more common speed records."""
        return ()


class Framer(Protocol):
    """What :class:`FramedDecoder` needs of a framer (line or binary)."""

    def feed(self, data: bytes) -> Iterable[bytes | FrameError]:
        """Add bytes; return the frames and framing errors they complete."""

    def flush(self) -> Iterable[bytes | FrameError]:
        """End of stream: the frames still completable and the errors for the rest."""


class FramedDecoder(Decoder[R]):
    """A decoder whose framing is delegated to a framer object.

    Subclasses implement :meth:`_make_framer` (called once, after the options are
    set) instead of :meth:`_split` and :meth:`_flush`.
    """

    _framer: Framer

    def _ready(self) -> None:
        self._framer = self._make_framer()

    @abstractmethod
    def _make_framer(self) -> Framer:
        """The framer for this decoder's protocol and options."""

    def _split(self, data: bytes) -> Iterable[bytes | FrameError]:
        return self._framer.feed(data)

    def _flush(self) -> Iterable[bytes | FrameError]:
        return self._framer.flush()
