"""Teledyne-RDI PD6 and PD13 ASCII output (which Rowe SeaPILOT emulates).

An ensemble is a block of ``:XX,...`` lines (docs/PROTOCOLS.md §5.1–5.2) in this order:
``:SA :TS [:RA] [:WI :WS :WE :WD] :BI :BS :BE :BD [:HM]``. PD6 has no checksum, so
every line is validated instead: its type, its field count, numeric syntax (spaces
and a leading ``+`` allowed, PD13 pads with spaces), and the ``A``/``V`` status.

Assembly: a block starts at ``:SA`` and is emitted as one :class:`Pd6Ensemble` when
its ``:BD`` line arrives (the last line PD6/PD13 send; a Pathfinder's trailing
``:HM`` comes out as its own :class:`PdHealth` record). A block is never spliced:
a line out of order, a repeated line, or a rejected line inside the block discards
the whole block, counted once as ``framing`` (the rejected line itself is counted
under its own reason). Lines before the first ``:SA`` are discarded the same way.

Invalid data: velocity −32768 (mm/s) or status ``V`` → the vector is None.

Sign convention: PD6/PD13 give the **vessel's** motion (``:BS`` T + = moving to
starboard, L + = moving forward, N + = moving away from the bottom; ``:BE`` + =
moving east/north/up), so the speed record is ``:BS`` as is (PD0 is the opposite).
``:RA`` beam ranges are in decimetres (the manual's example pairs 71.31 dm with
``:BD`` 7.13 m); they are converted to metres.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import ClassVar, TypeAlias, TypeVar, get_args

from drivers.base import FramedDecoder, Framer, Use
from drivers.errors import FieldError, FrameError, OutOfRangeError, UnknownSentenceError
from drivers.framing import LineFramer
from drivers.rdi import INVALID, MAX_MMS, mms
from drivers.records import (
    MAX_DEPTH_M,
    PHYSICAL_RANGES,
    Rejected,
    SpeedRecord,
    bottom_track,
    check_ranges,
)

ORDER = ("SA", "TS", "RA", "WI", "WS", "WE", "WD", "BI", "BS", "BE", "BD")
"""Line types of one ensemble, in transmission order."""

_RANK = {k: i for i, k in enumerate(ORDER)}

_LAST = len(ORDER) - 1
"""The rank of ``:BD``, the line that ends an ensemble."""

_NOT_SENT = object()
"""The value of a block's line that has not arrived (an invalid vector's is None)."""


@dataclass(frozen=True, slots=True)
class Velocity:
    """A velocity triple (plus the error velocity for the instrument frame), m/s.

    Attributes:
        a, b, c: the components (instrument X/Y/Z, ship T/L/N, earth E/N/U).
        error: error velocity (instrument frame only), m/s, or None.
    """

    a: float
    b: float
    c: float
    error: float | None = None


@dataclass(frozen=True, slots=True)
class DistanceMadeGood:
    """``:WD``/``:BD``: distance made good east/north/up (m), range (m), time since good (s)."""

    east_m: float
    north_m: float
    up_m: float
    range_m: float
    time_since_good_s: float


@dataclass(frozen=True, slots=True)
class Pd6Ensemble:
    """One PD6/PD13 ensemble (velocities None when invalid or not sent).

    Attributes:
        pitch_deg, roll_deg, heading_deg: attitude, degrees.
        timestamp: the DVL clock ``YYMMDDHHmmsshh`` as sent.
        salinity_ppt, temperature_c, depth_m, sound_speed_mps: :TS environment.
        bit: built-in-test result.
        pressure_kpa: :RA pressure (PD13), or None.
        beam_ranges_m: :RA range to bottom per beam, m (PD13), or None.
        water_instrument, water_ship, water_earth: water-mass velocities.
        water_dmg: :WD, or None.
        bottom_instrument, bottom_ship, bottom_earth: bottom-track velocities.
        bottom_dmg: :BD, or None.
    """

    pitch_deg: float
    roll_deg: float
    heading_deg: float
    timestamp: str
    salinity_ppt: float
    temperature_c: float
    depth_m: float
    sound_speed_mps: float
    bit: int
    pressure_kpa: float | None
    beam_ranges_m: tuple[float, float, float, float] | None
    water_instrument: Velocity | None
    water_ship: Velocity | None
    water_earth: Velocity | None
    water_dmg: DistanceMadeGood | None
    bottom_instrument: Velocity | None
    bottom_ship: Velocity | None
    bottom_earth: Velocity | None
    bottom_dmg: DistanceMadeGood | None

    @property
    def bottom_range_m(self) -> float | None:
        """Range to the bottom from :BD, m (None if not sent)."""
        return self.bottom_dmg.range_m if self.bottom_dmg is not None else None


@dataclass(frozen=True, slots=True)
class PdHealth:
    """A Pathfinder ``:HM`` system-health line, fields kept as text (not all documented)."""

    fields: tuple[str, ...]


Pd6Record: TypeAlias = Pd6Ensemble | PdHealth
"""Every record :class:`PdAsciiDecoder` yields (besides :class:`~drivers.records.Rejected`)."""

RECORDS: tuple[type[Pd6Record], ...] = get_args(Pd6Record)
"""The members of :data:`Pd6Record`, in its order."""

RECORD_PARTS = (Velocity, DistanceMadeGood)
"""The dataclasses nested in a :class:`Pd6Ensemble` (never yielded on their own)."""


_DECIMAL_RE = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)"
_INTEGER_RE = r"[+-]?[0-9]+"
_DECIMAL = re.compile(_DECIMAL_RE).fullmatch
_INTEGER = re.compile(_INTEGER_RE).fullmatch
_N = TypeVar("_N", int, float)


def _num(field: str, name: str, raw: bytes) -> float:
    """A decimal number, right-aligned with leading spaces or not (no exponent, no ``_``,
    no ``nan``, no trailing blank: a digit lost to a blank would read as another number)."""
    f = field.lstrip(" ")
    if not _DECIMAL(f):
        raise FieldError(f"{name}: {field!r} is not a number", raw)
    return float(f)


def _int(field: str, name: str, raw: bytes) -> int:
    """A decimal integer, right-aligned with leading spaces or not (no ``_``, no trailing
    blank)."""
    f = field.lstrip(" ")
    if not _INTEGER(f):
        raise FieldError(f"{name}: {field!r} is not an integer", raw)
    return int(f)


def _each(
    fields: list[str],
    kind: str,
    raw: bytes,
    match: Callable[[str], object],
    convert: Callable[[str], _N],
    what: str,
) -> list[_N]:
    """Every field as :func:`_num` or :func:`_int` reads it (``match`` their pattern,
    ``what`` "a number" or "an integer"), a bad one named ``:KIND field i``."""
    values: list[_N] = []
    for f in fields:
        g = f.lstrip(" ")
        if not match(g):
            raise FieldError(f":{kind} field {len(values) + 1}: {f!r} is not {what}", raw)
        values.append(convert(g))
    return values


def _velocity(fields: list[str], n: int, kind: str, raw: bytes) -> Velocity | None:
    """``n`` integer mm/s values then a status letter; None when invalid."""
    if len(fields) != n + 1:
        raise FieldError(f":{kind} has {len(fields)} fields, expected {n + 1}", raw)
    status = fields[n].strip()
    if status not in ("A", "V"):
        raise FieldError(f":{kind} status {status!r}, expected A or V", raw)
    return _velocity_of(
        _each(fields[:n], kind, raw, _INTEGER, int, "an integer"),
        status == "V",
        kind,
        raw,
    )


def _velocity_of(values: Sequence[int], void: bool, kind: str, raw: bytes) -> Velocity | None:
    for v in values:
        if not INVALID <= v <= MAX_MMS:
            raise OutOfRangeError(f":{kind} velocity {v} mm/s outside int16", raw)
    if void or INVALID in values[:3]:
        return None
    err = None
    if len(values) == 4:
        err = None if values[3] == INVALID else values[3] / 1000.0
    return Velocity(values[0] / 1000.0, values[1] / 1000.0, values[2] / 1000.0, err)


def _dmg(fields: list[str], kind: str, raw: bytes) -> DistanceMadeGood:
    if len(fields) != 5:
        raise FieldError(f":{kind} has {len(fields)} fields, expected 5", raw)
    e, n, u, r, dt = _each(fields, kind, raw, _DECIMAL, float, "a number")
    return _dmg_of(e, n, u, r, dt, kind, raw)


def _dmg_of(
    e: float, n: float, u: float, r: float, dt: float, kind: str, raw: bytes
) -> DistanceMadeGood:
    if r < 0 or dt < 0:
        raise OutOfRangeError(f":{kind} range {r} or time {dt} negative", raw)
    return DistanceMadeGood(e, n, u, r, dt)


def _attitude(pitch: float, roll: float, heading: float, raw: bytes) -> tuple[float, float, float]:
    """Pitch, roll and heading within range; a heading of 360 reads as 0."""
    check_ranges(":SA", raw, pitch=pitch, roll=roll, heading=heading)
    return pitch, roll, 0.0 if heading == 360 else heading


def _environment(
    stamp: str, sal: float, temp: float, depth: float, c: float, bit: int, raw: bytes
) -> tuple[str, float, float, float, float, int]:
    check_ranges(":TS", raw, salinity=sal, temperature=temp, depth=depth, sound_speed=c)
    if not _stamp_ok(stamp):
        raise OutOfRangeError(f":TS time {stamp!r} is no date and time", raw)
    return stamp, sal, temp, depth, c, bit


def _stamp_ok(stamp: str) -> bool:
    """``YYMMDDHHmmsshh`` names a real month, day, hour, minute and second."""
    mo, d, h, mi, sec = (int(stamp[i : i + 2]) for i in (2, 4, 6, 8, 10))
    return 1 <= mo <= 12 and 1 <= d <= 31 and h < 24 and mi < 60 and sec < 60


def _ranges(
    p: float, r: list[float], raw: bytes
) -> tuple[float, tuple[float, float, float, float]]:
    """:RA pressure (kPa) and four beam ranges (dm → m), none negative."""
    if p < 0 or min(r) < 0 or max(r) / 10.0 > MAX_DEPTH_M:
        raise OutOfRangeError(f":RA pressure {p} or ranges {r} out of range", raw)
    return p, (r[0] / 10.0, r[1] / 10.0, r[2] / 10.0, r[3] / 10.0)


def _ensemble(values: list[object]) -> Pd6Ensemble:
    """The ensemble record of an assembled block (each line's value at its rank in
    :data:`ORDER`, :data:`_NOT_SENT` where the line was not sent)."""
    sa, ts, ra, wi, ws, we, wd, bi, bs, be, bd = values
    assert isinstance(sa, tuple) and isinstance(ts, tuple)
    return Pd6Ensemble(
        pitch_deg=sa[0],
        roll_deg=sa[1],
        heading_deg=sa[2],
        timestamp=ts[0],
        salinity_ppt=ts[1],
        temperature_c=ts[2],
        depth_m=ts[3],
        sound_speed_mps=ts[4],
        bit=ts[5],
        pressure_kpa=ra[0] if isinstance(ra, tuple) else None,
        beam_ranges_m=ra[1] if isinstance(ra, tuple) else None,
        water_instrument=wi if isinstance(wi, Velocity) else None,
        water_ship=ws if isinstance(ws, Velocity) else None,
        water_earth=we if isinstance(we, Velocity) else None,
        water_dmg=wd if isinstance(wd, DistanceMadeGood) else None,
        bottom_instrument=bi if isinstance(bi, Velocity) else None,
        bottom_ship=bs if isinstance(bs, Velocity) else None,
        bottom_earth=be if isinstance(be, Velocity) else None,
        bottom_dmg=bd if isinstance(bd, DistanceMadeGood) else None,
    )


# One pattern per line type for a line whose every field is good, a group per value
# (blanks as _num, _int and the status checks allow them; the :TS time a real date and
# time, as _stamp_ok requires); any other line goes through the field-by-field checks
# of _parse_fields, which name what is wrong. Each reader checks the ranges of the
# common case inline and hands any other values to the checks that name what is out of
# range (_attitude, _environment, _velocity_of, _dmg_of).
_D = f" *({_DECIMAL_RE})"
_I = f" *({_INTEGER_RE})"
_STATUS = " *([AV]) *"
_STAMP = (
    " *([0-9]{2}(?:0[1-9]|1[0-2])(?:0[1-9]|[12][0-9]|3[01])(?:[01][0-9]|2[0-3])"
    "[0-5][0-9][0-5][0-9][0-9]{2}) *"
)
_Groups: TypeAlias = tuple[str, ...]
_PITCH, _ROLL, _SAL, _TEMP, _C, _DEPTH = (
    PHYSICAL_RANGES[k] for k in ("pitch", "roll", "salinity", "temperature", "sound_speed", "depth")
)


def _sa(g: _Groups, kind: str, raw: bytes) -> object:
    pitch, roll, heading = float(g[0]), float(g[1]), float(g[2])
    if _PITCH[0] <= pitch <= _PITCH[1] and _ROLL[0] <= roll <= _ROLL[1] and 0.0 <= heading < 360.0:
        return pitch, roll, heading
    return _attitude(pitch, roll, heading, raw)  # the checks that name what is wrong


def _ts(g: _Groups, kind: str, raw: bytes) -> object:
    # the pattern's stamp is a real date and time (:func:`_stamp_ok`)
    stamp, sal, temp, depth, c = g[0], float(g[1]), float(g[2]), float(g[3]), float(g[4])
    if (
        _SAL[0] <= sal <= _SAL[1]
        and _TEMP[0] <= temp <= _TEMP[1]
        and _C[0] <= c <= _C[1]
        and _DEPTH[0] <= depth <= _DEPTH[1]
    ):
        return stamp, sal, temp, depth, c, int(g[5])
    return _environment(stamp, sal, temp, depth, c, int(g[5]), raw)


def _ra(g: _Groups, kind: str, raw: bytes) -> object:
    p, *r = map(float, g)
    return _ranges(p, r, raw)


def _vel3(g: _Groups, kind: str, raw: bytes) -> object:
    x, y, z, status = int(g[0]), int(g[1]), int(g[2]), g[3]
    if status == "A" and min(x, y, z) > INVALID and max(x, y, z) <= MAX_MMS:
        return Velocity(x / 1000.0, y / 1000.0, z / 1000.0)
    return _velocity_of((x, y, z), status == "V", kind, raw)


def _vel4(g: _Groups, kind: str, raw: bytes) -> object:
    return _velocity_of((int(g[0]), int(g[1]), int(g[2]), int(g[3])), g[4] == "V", kind, raw)


def _dmg_line(g: _Groups, kind: str, raw: bytes) -> object:
    e, n, u, r, dt = map(float, g)
    if r >= 0.0 and dt >= 0.0:
        return DistanceMadeGood(e, n, u, r, dt)
    return _dmg_of(e, n, u, r, dt, kind, raw)


def _pattern(*fields: str) -> Callable[[str], re.Match[str] | None]:
    return re.compile(",".join(fields)).fullmatch


_VEL3 = (_pattern(_I, _I, _I, _STATUS), _vel3)
_VEL4 = (_pattern(_I, _I, _I, _I, _STATUS), _vel4)
_DMG = (_pattern(_D, _D, _D, _D, _D), _dmg_line)
_LINES: dict[str, tuple[Callable[[str], re.Match[str] | None], Callable[..., object]]] = {
    "SA": (_pattern(_D, _D, _D), _sa),
    "TS": (_pattern(_STAMP, _D, _D, _D, _D, _I + "(?:, *[OWX] *)?"), _ts),
    "RA": (_pattern(_D, _D, _D, _D, _D), _ra),
    "WI": _VEL4,
    "BI": _VEL4,
    "WS": _VEL3,
    "WE": _VEL3,
    "BS": _VEL3,
    "BE": _VEL3,
    "WD": _DMG,
    "BD": _DMG,
}
"""The pattern of each line type's fields (after the type's comma) and how its groups
are read."""


def _parse_line(frame: bytes) -> tuple[str, object]:
    """What :meth:`PdAsciiDecoder.parse_line` does: a line whose fields are all good is
    read by its type's pattern, any other by :func:`_parse_fields` (same values, same
    errors)."""
    # latin-1 never fails: a byte beyond ASCII matches no pattern
    kind, _, rest = frame.decode("latin-1")[1:].partition(",")
    fast = _LINES.get(kind)
    if fast is not None:
        pattern, read = fast
        m = pattern(rest)
        if m is not None:
            return kind, read(m.groups(), kind, frame)
    return _parse_fields(frame)


def _parse_fields(frame: bytes) -> tuple[str, object]:
    """The field-by-field path of :meth:`PdAsciiDecoder.parse_line` (every line, any layout)."""
    try:
        text = frame.decode("ascii")
    except UnicodeDecodeError:
        raise FieldError("non-ASCII bytes in the line", frame) from None
    if not text.isprintable():
        raise FieldError("control characters in the line", frame)
    kind, sep, rest = text[1:].partition(",")
    kind = kind.strip()
    if not sep:
        raise FieldError(f"line {text[:8]!r} has no fields", frame)
    parse = _FIELDS.get(kind)
    if parse is None:
        raise UnknownSentenceError(f"line type :{kind[:4]} not decoded", frame)
    return kind, parse(kind, rest.split(","), frame)


def _sa_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:SA``: pitch, roll, heading."""
    if len(fields) != 3:
        raise FieldError(f":SA has {len(fields)} fields, expected 3", frame)
    pitch, roll, heading = (_num(f, ":SA", frame) for f in fields)
    return _attitude(pitch, roll, heading, frame)


def _ts_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:TS``: time, salinity, temperature, depth, sound speed, BIT (and a leak flag)."""
    if len(fields) not in (6, 7):
        raise FieldError(f":TS has {len(fields)} fields, expected 6 or 7", frame)
    stamp = fields[0].strip()
    if len(stamp) != 14 or not stamp.isdigit():
        raise FieldError(f":TS time {stamp!r} is not YYMMDDHHmmsshh", frame)
    sal, temp, depth, c = (_num(f, ":TS", frame) for f in fields[1:5])
    bit = _int(fields[5], ":TS BIT", frame)
    env = _environment(stamp, sal, temp, depth, c, bit, frame)
    if len(fields) == 7 and fields[6].strip() not in ("O", "W", "X"):
        raise FieldError(f":TS leak flag {fields[6]!r}, expected O, W or X", frame)
    return env


def _ra_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:RA``: pressure and the four beams' ranges."""
    if len(fields) != 5:
        raise FieldError(f":RA has {len(fields)} fields, expected 5", frame)
    p, *r = (_num(f, ":RA", frame) for f in fields)
    return _ranges(p, r, frame)


def _instrument_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:WI``/``:BI``: velocities in the instrument frame (four with the error)."""
    return _velocity(fields, 4, kind, frame)


def _frame_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:WS``/``:WE``/``:BS``/``:BE``: three velocities in the ship or earth frame."""
    return _velocity(fields, 3, kind, frame)


def _dmg_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:WD``/``:BD``: the distance made good."""
    return _dmg(fields, kind, frame)


def _health_fields(kind: str, fields: list[str], frame: bytes) -> object:
    """``:HM``: the health fields as they are."""
    return PdHealth(tuple(f.strip() for f in fields))


_FIELDS: dict[str, Callable[[str, list[str], bytes], object]] = {
    "SA": _sa_fields,
    "TS": _ts_fields,
    "RA": _ra_fields,
    "WI": _instrument_fields,
    "BI": _instrument_fields,
    "WS": _frame_fields,
    "WE": _frame_fields,
    "BS": _frame_fields,
    "BE": _frame_fields,
    "WD": _dmg_fields,
    "BD": _dmg_fields,
    "HM": _health_fields,
}
"""The field-by-field parser of each line type."""


@dataclass(slots=True)
class _Block:
    values: list[object]
    """Each line's value at its rank in :data:`ORDER` (:data:`_NOT_SENT` until it comes)."""
    last_rank: int
    damaged: str = ""


class PdAsciiDecoder(FramedDecoder[Pd6Record]):
    """PD6/PD13 decoder (registry names ``pd6`` and ``pd13``; see the module docstring)."""

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


def _mm(v: float | None) -> str:
    return f"{mms(v):+06d}"


def _vel_line(kind: str, values: tuple[float, ...] | None, n: int) -> str:
    if values is None:
        return f":{kind}," + ",".join([_mm(None)] * n) + ",V"
    return f":{kind}," + ",".join(_mm(v) for v in values) + ",A"


def encode_pd6(
    *,
    timestamp: datetime,
    heading_deg: float,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    bottom_ship_mps: tuple[float, float, float] | None = None,
    range_m: float | None = None,
    water_ship_mps: tuple[float, float, float] | None = None,
    salinity_ppt: float = 35.0,
    temperature_c: float = 15.0,
    depth_m: float = 0.0,
    sound_speed_mps: float = 1500.0,
    bottom_dmg_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    time_since_good_s: float = 0.0,
) -> list[str]:
    """The PD6 lines of one ensemble (without CR LF), TRDI widths.

    Sends ``:SA :TS :BI :BS :BE :BD``, plus the water-mass lines when
    ``water_ship_mps`` is given. Ship-frame vectors are (T, L, N): + starboard,
    + forward, + away from the bottom (vessel motion). The instrument frame is taken
    aligned with the ship (X = T, Y = L); the earth frame is the ship frame rotated
    by the heading (pitch and roll ignored). ``None`` sends −32768 with status V.

    Raises:
        ValueError: non-finite values.
    """
    psi = math.radians(heading_deg)

    def earth(v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is None:
            return None
        t, lo, n = v
        return (lo * math.sin(psi) + t * math.cos(psi), lo * math.cos(psi) - t * math.sin(psi), n)

    lines = [
        f":SA,{pitch_deg:+06.2f},{roll_deg:+06.2f},{heading_deg % 360.0:06.2f}",
        f":TS,{timestamp:%y%m%d%H%M%S}{timestamp.microsecond // 10000:02d},{salinity_ppt:04.1f},"
        f"{temperature_c:+05.1f},{depth_m:06.1f},{sound_speed_mps:06.1f},000",
    ]
    if water_ship_mps is not None:
        lines += [
            _vel_line("WI", (*water_ship_mps, 0.0), 4),
            _vel_line("WS", water_ship_mps, 3),
            _vel_line("WE", earth(water_ship_mps), 3),
            ":WD,+0000.00,+0000.00,+0000.00,0000.00,000.00",
        ]
    e, n, u = bottom_dmg_m
    rng = 0.0 if range_m is None else range_m
    lines += [
        _vel_line("BI", None if bottom_ship_mps is None else (*bottom_ship_mps, 0.0), 4),
        _vel_line("BS", bottom_ship_mps, 3),
        _vel_line("BE", earth(bottom_ship_mps), 3),
        f":BD,{e:+011.2f},{n:+011.2f},{u:+011.2f},{rng:07.2f},{time_since_good_s:06.2f}",
    ]
    return lines
