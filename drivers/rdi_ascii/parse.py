"""The checks and readers of each PD6/PD13 line (no checksum: every line is validated:
its type, its field count, numeric syntax, the ``A``/``V`` status and the physical ranges).

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import TypeAlias, TypeVar

from drivers.errors import FieldError, OutOfRangeError, UnknownSentenceError
from drivers.rdi import INVALID, MAX_MMS
from drivers.rdi_ascii.records import (
    DistanceMadeGood,
    Pd6Ensemble,
    PdHealth,
    Velocity,
)
from drivers.records import (
    MAX_DEPTH_M,
    PHYSICAL_RANGES,
    check_ranges,
)

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
