"""The PD6/PD13 decoder: lines framed, parsed and assembled into one record per block.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import ClassVar

from drivers.base import FramedDecoder, Framer, Use
from drivers.errors import FrameError
from drivers.framing import LineFramer
from drivers.rdi_ascii.parse import _ensemble, _parse_line
from drivers.rdi_ascii.records import (
    _LAST,
    _NOT_SENT,
    _RANK,
    Pd6Ensemble,
    Pd6Record,
    PdHealth,
)
from drivers.records import (
    Rejected,
    SpeedRecord,
    bottom_track,
)


@dataclass(slots=True)
class _Block:
    values: list[object]
    """Each line's value at its rank in :data:`ORDER` (:data:`_NOT_SENT` until it comes)."""
    last_rank: int
    damaged: str = ""


class PdAsciiDecoder(FramedDecoder[Pd6Record]):
    """PD6/PD13 decoder (registry names ``pd6`` and ``pd13``; see the package docstring)."""

    protocol: ClassVar[str] = "pd6"
    binary: ClassVar[bool] = False
    uses: ClassVar[frozenset[Use]] = frozenset({"bottom", "water"})
    """:BS bottom track, :WS water-mass track."""
    heading: ClassVar[bool] = True
    """:SA."""

    _block: _Block | None = None
    """The ensemble being assembled (None between blocks)."""

    # The framer's frame is a line; the ensemble logic runs in feed() so that one
    # ensemble record comes out per block. parse_frame takes a whole block.

    def _make_framer(self) -> Framer:
        self._lines = LineFramer(b":", self.options.max_length)
        return self._lines

    def _flush(self) -> Iterable[bytes | FrameError]:
        out: list[bytes | FrameError] = list(super()._flush())
        if self._block is not None:
            out.append(FrameError("incomplete ensemble at end of stream (no :BD)"))
            self._block = None
        return out

    def feed(self, data: bytes) -> Iterator[Pd6Record | Rejected]:
        """Decode a chunk; yields complete ensembles (and rejects per the error policy)."""
        pending = self._pending
        pending.extend(self._framer.feed(data))
        while pending:
            item = pending.popleft()
            if isinstance(item, FrameError):
                self._damage(f"a line was rejected ({item.reason})")
                yield from self._reject(item)
                continue
            try:
                kind, value = _parse_line(item)
            except FrameError as exc:
                if not exc.raw:
                    exc.raw = item[:256]
                self._damage(f"line rejected ({exc.reason})")
                yield from self._reject(exc)
                continue
            except Exception as exc:  # contained as in Decoder.feed: an internal reject
                err = FrameError(f"{type(exc).__name__}: {exc}", item, reason="internal")
                err.__cause__ = exc
                self._damage("line rejected (internal)")
                yield from self._reject(err)
                continue
            done = self._assemble(kind, value, item)
            if done is None:
                continue
            if isinstance(done, FrameError):
                yield from self._reject(done)
                continue
            self.counters.records += 1
            yield done

    def _damage(self, why: str) -> None:
        if self._block is not None and not self._block.damaged:
            self._block.damaged = why

    def _assemble(self, kind: str, value: object, raw: bytes) -> Pd6Record | FrameError | None:
        """Add a parsed line to the block: a finished record, a reject, or None."""
        if kind == "HM":  # the :HM line, a record of its own
            assert isinstance(value, PdHealth)
            return value
        rank = _RANK[kind]
        block = self._block
        if rank == 0:  # :SA
            self._block = _Block([value] + [_NOT_SENT] * _LAST, 0)
            if block is not None:
                return FrameError("ensemble discarded: no :BD before the next :SA")
            return None
        if block is None:
            return FrameError(f":{kind} outside an ensemble (no :SA before it)", raw)
        if rank <= block.last_rank:
            self._block = None
            return FrameError(f"ensemble discarded: :{kind} out of order or repeated", raw)
        values = block.values
        values[rank] = value
        block.last_rank = rank
        if rank != _LAST:
            return None
        self._block = None
        if block.damaged:
            return FrameError(f"ensemble discarded: {block.damaged}", raw)
        if _NOT_SENT in (values[_RANK["TS"]], values[_RANK["BS"]]):
            missing = [k for k in ("TS", "BS") if values[_RANK[k]] is _NOT_SENT]
            return FrameError(f"ensemble discarded: no {', '.join(':' + m for m in missing)}", raw)
        return _ensemble(values)

    def parse_frame(self, frame: bytes) -> Pd6Record:
        """Decode one complete frame: a whole ensemble (its lines ``:SA`` … ``:BD``
        separated by CR/LF) or one ``:HM`` line, into the one record :meth:`feed` would
        yield for it. This decoder's buffered block and counters are left alone.

        Raises:
            FrameError: a subclass naming the reject reason of a bad line; ``framing``
                for a bad block or anything but exactly one record.
        """
        alone = PdAsciiDecoder(self.port, errors="raise", options=self.options)
        records = [*alone.feed(frame + b"\r\n"), *alone.flush()]
        if len(records) != 1:
            raise FrameError(f"{len(records)} records in the frame, expected one", frame)
        record = records[0]
        if isinstance(record, Rejected):  # cannot happen with errors="raise"
            raise FrameError(record.detail, record.raw)
        return record

    def parse_line(self, frame: bytes) -> tuple[str, object]:
        """Parse one ``:XX,...`` line into (type, value).

        Raises:
            FrameError: a subclass naming the reject reason.
        """
        return _parse_line(frame)

    def speed_records(self, record: Pd6Record) -> tuple[SpeedRecord, ...]:
        """:BS → sog (role ``bottom``, source ``PD6:BS``), :WS → stw (``water``,
        ``PD6:WS``); vessel-motion sign; the :SA heading taken as true."""
        if not isinstance(record, Pd6Ensemble):
            return ()
        port, hdg = self.port, record.heading_deg
        bs = record.bottom_ship
        out = [bottom_track(port, None if bs is None else (bs.b, bs.a), hdg, "PD6:BS")]
        ws = record.water_ship
        if ws is not None:
            out.append(
                SpeedRecord(
                    port=port,
                    kind="stw",
                    role="water",
                    longitudinal_mps=ws.b,
                    transverse_mps=ws.a,
                    valid=True,
                    heading_true_deg=hdg,
                    source="PD6:WS",
                )
            )
        return tuple(out)


# ------------------------------------------------------------------ encoder
