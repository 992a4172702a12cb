"""CSV/TSV exports: the column maps and presets, the header, and each cell read into SI
units within the range a boat can produce (:mod:`emlogd.offline.importer` writes the rows).
"""

from __future__ import annotations

import csv
import math
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Literal

from drivers.nmea0183.parsing import MAX_SPEED_MPS
from drivers.records import KNOT_MPS
from emlogd.offline.importbase import ImportFormatError, ImportReport, what_it_looks_like

HeadingRef = Literal["true", "magnetic"]
"""A heading column's reference."""

OLE_EPOCH = datetime(1899, 12, 30, tzinfo=UTC)
"""Day 0 of OLE automation dates (Excel, Expedition)."""

FILETIME_TICK_S = 1e-7
"""A Windows FILETIME tick (Expedition's ``!log=v3`` times), s."""

FILETIME_EPOCH_S = -11_644_473_600.0
"""FILETIME's day 0 (1601-01-01) in epoch seconds."""

HEADER_SCAN_LINES = 200
"""The header must be among the first this many lines (a banner before it: a logger
may write its settings, damping and calibration tables first)."""

NO_VALUE = frozenset({"-", "--", "---", "nan", "n/a", "na", "null", "none"})
"""Cells that say "no value", in any case (a logger's dash before its estimate is known,
the ``NaN`` of a pandas or MATLAB export, a spreadsheet's ``N/A``, a database's
``NULL``): empty, so not counted as bad cells."""

DELIMITERS = (",", "\t", ";", "|")
"""The delimiters the header is tried with."""

MAX_DRIFT_KN = 15.0
"""A current above this is not the sea's (the strongest tidal races run near 10 kn), kn."""

LIMITS: dict[str, tuple[float, float]] = {
    "stw": (0.0, MAX_SPEED_MPS),
    "sog": (0.0, MAX_SPEED_MPS),
    "heading": (-360.0, 360.0),
    "heading_mag": (-360.0, 360.0),
    "cog": (-360.0, 360.0),
    "set": (-360.0, 360.0),
    "drift": (0.0, MAX_DRIFT_KN * KNOT_MPS),
    "lat": (-90.0, 90.0),
    "lon": (-180.0, 180.0),
    "variation": (-90.0, 90.0),
}
"""Each column's plausible range after unit conversion (m/s, degrees; angles wrapped
after the check)."""

ANGLES = ("heading", "heading_mag", "cog", "set")
SPEEDS = ("stw", "sog", "drift")
CSV_KEYS = (
    "time",
    "date",
    "stw",
    "heading",
    "heading_mag",
    "sog",
    "cog",
    "lat",
    "lon",
    "set",
    "drift",
    "variation",
)


@dataclass(frozen=True)
class Preset:
    """A known export: its columns, how it keeps time, its heading's reference.

    Attributes:
        name: the ``--preset`` name.
        columns: the column map (``A|B`` alternatives, ``?`` optional).
        time_format: ``ole``, ``iso``, ``epoch``, ``epoch_ms``, ``filetime``, ``auto``
            (told by the first time cell) or a ``strptime`` pattern.
        heading_ref: the heading's reference.
        local_time: whether the times are the logger's local clock (then
            ``--utc-offset`` is needed, and its absence is noted).
        doc: one line for people.
    """

    name: str
    columns: Mapping[str, str]
    time_format: str
    heading_ref: HeadingRef
    local_time: bool
    doc: str


EXPEDITION: dict[str, str] = {
    "time": "Utc",
    "stw": "Bsp",
    "heading": "Hdg|HdgTrue|TrueHdg|HDT|Heading|HeadingTrue|TrueHeading?",
    "heading_mag": "HdgMag|MagHdg|Hdg_M|HdgM?",
    "variation": "Var|MagVar|Variation|Decl?",
    "sog": "Sog?",
    "cog": "Cog?",
    "lat": "Lat?",
    "lon": "Lon|Long?",
    "set": "iSet|Set?",
    "drift": "iDrift|Drift?",
}
"""Expedition's columns (its ``Hdg`` is a true heading, as are the other names a
re-export gives it: ``HdgTrue``, ``Hdg_true``, ``TrueHdg``, ``HDT``, ``Heading``;
times are OLE dates, or FILETIME ticks in its ``!log=v3`` logs). Its exports
name the current ``iSet``/``iDrift`` or ``Set``/``Drift``, or leave it out. An export
without ``Hdg`` may hold the compass's magnetic heading (``HdgMag`` and its spellings,
with a variation column ``Var`` or ``MagVar``), or no heading at all (then its water
sentences carry the speed alone, and the import says so)."""

LOGGER_TSV: dict[str, str] = {
    "date": "Date",
    "time": "Time",
    "stw": "Boatspeed|BS",
    "heading": "Heading|HDG",
    "sog": "Ext_SOG|SOG?",
    "cog": "Ext_COG|COG?",
    "lat": "Latitudine|Lat?",
    "lon": "Longitudine|Lon?",
    "set": "SET?",
    "drift": "DRIFT?",
}
"""An Italian race logger's tab-separated export (``Date`` dd/mm/yy, ``Time`` of its
clock, told by the first row as any ``auto`` time: another firmware or a spreadsheet
may write the year in full, year first, or fractions of a second; magnetic ``Heading``, ``ddmm.mmmmN`` positions), under the names of both its
firmwares (``Boatspeed``/``Heading``/``Ext_SOG`` or ``BS``/``HDG``/``SOG``)."""

GENERIC: dict[str, str] = {
    "time": "time|timestamp|datetime|date_time|utc|utctime|utc_time|time_utc",
    "date": "date|utcdate|utc_date|date_utc?",
    "stw": "stw|speed|bsp|boatspeed|boat_speed|speed_through_water|sow|water_speed|log",
    "heading": "hdg|heading|heading_true|hdt|hdgtrue|hdg_true|true_heading|truehdg|true_hdg?",
    "heading_mag": "heading_magnetic|magnetic_heading|hdg_mag|mag_hdg|hdm|hdgmag?",
    "variation": "variation|magvar|mag_var|var|declination?",
    "sog": "sog|speed_over_ground?",
    "cog": "cog|course_over_ground?",
    "lat": "lat|latitude?",
    "lon": "lon|lng|long|longitude?",
    "set": "set|current_set|iset|tideset|tide_set?",
    "drift": "drift|current_drift|idrift|tiderate|tide_rate?",
}
"""A plain table of the usual short names (a processed log, a spreadsheet): one time
column (told by its first cell; a ``date`` column beside a time of day is joined to it), the speed through the water in knots (``speed`` is
taken for it: a table that names its speed over ground ``sog``; the NMEA field names
``STW`` and ``SOW``, and an ECDIS logbook's ``Log``, too), a true heading (``HDG``, ``HDT``, ``HdgTrue``) or a magnetic one
(``HDM``, ``HdgMag``)."""

PRESETS: dict[str, Preset] = {
    "expedition": Preset(
        "expedition", EXPEDITION, "auto", "true", False, "Expedition CSV (Utc, Bsp, Hdg...)"
    ),
    "logger-tsv": Preset(
        "logger-tsv",
        LOGGER_TSV,
        "auto",
        "magnetic",
        True,
        "race logger TSV (Date, Time, Boatspeed, Heading, Ext_SOG...)",
    ),
    "generic": Preset(
        "generic", GENERIC, "auto", "true", False, "a plain table (time, stw|speed, hdg, sog...)"
    ),
}
"""The presets, tried in this order against the header when none is named."""

MapChoice = tuple[Preset | None, Mapping[str, str]]
"""A preset (None for a plain map) and the column map it gives with the user's."""


def parse_map(spec: str) -> dict[str, str]:
    """``key=Column,key=Column`` → a dict; keys among :data:`CSV_KEYS`.

    Raises:
        ImportFormatError: a malformed item or an unknown key.
    """
    out: dict[str, str] = {}
    for item in filter(None, (x.strip() for x in spec.split(","))):
        key, sep, col = item.partition("=")
        if not sep or not col:
            raise ImportFormatError(f"--map item {item!r} is not key=Column")
        if key not in CSV_KEYS:
            raise ImportFormatError(f"--map key {key!r} is not one of {', '.join(CSV_KEYS)}")
        out[key] = col
    return out


@dataclass(frozen=True)
class Col:
    """A mapped column: its index and the factor to SI."""

    key: str
    index: int
    factor: float
    ref: HeadingRef | None = None
    """A heading's reference as its name says it (``Hdg (°M)``: magnetic), else None."""


DEG_PER_RAD = 180.0 / math.pi

MAP_UNITS: dict[str, float] = {"[mps]": 1.0, "[kn]": KNOT_MPS, "[rad]": DEG_PER_RAD}
"""Units a ``--map`` column may be written with: a speed's factor to m/s, or (``[rad]``)
an angle's to degrees."""


def _spec(spec: str) -> tuple[list[tuple[str, float | None]], bool]:
    """``A[mps]|B?`` → ([(name, factor of its unit, None without one)...], optional)."""
    optional = spec.endswith("?")
    names: list[tuple[str, float | None]] = []
    for alt in (spec[:-1] if optional else spec).split("|"):
        alt = alt.strip()
        unit = alt[alt.rindex("[") :] if alt.endswith("]") and "[" in alt else ""
        if unit and unit not in MAP_UNITS:
            raise ImportFormatError(
                f"--map column {alt!r}: the unit {unit} is not known (a speed column's "
                "unit: [mps] or [kn]; an angle's: [rad])"
            )
        names.append((alt[: len(alt) - len(unit)], MAP_UNITS[unit] if unit else None))
    return names, optional


HEADER_UNITS: dict[str, float | None] = {
    "kn": KNOT_MPS,
    "kt": KNOT_MPS,
    "kts": KNOT_MPS,
    "knot": KNOT_MPS,
    "knots": KNOT_MPS,
    "m/s": 1.0,
    "mps": 1.0,
    "km/h": 1.0 / 3.6,
    "kmh": 1.0 / 3.6,
    "kph": 1.0 / 3.6,
    "mph": 0.44704,
    "deg": None,
    "degt": None,
    "deg t": None,
    "degtrue": None,
    "°t": None,
    "°true": None,
    "true": None,
    "degrees": None,
    "°": None,
    "˚": None,
    "º": None,
}
"""Units a column name may carry (``Bsp (kn)``, ``SOG [m/s]``, ``stw_kn``, ``SOG kts``;
in any case): a speed's factor to m/s (it overrides the map's), or None for an
angle's (the degree sign, or the ring ``˚`` or ordinal ``º`` written for it; ``°T``,
``true``: a true heading; a magnetic one, ``°M``, ``degM``, ``mag``, is
:data:`MAGNETIC_UNITS`). A heading's name that says its reference gives it
(:attr:`Col.ref`): ``Hdg (°M)`` is read as magnetic whatever the preset's reference,
``Heading (°T)`` as true, unless ``--heading-ref`` is given."""

MAGNETIC_UNITS = frozenset(
    {"degm", "deg m", "°m", "°mag", "degmag", "deg mag", "mag", "magnetic", "˚m", "ºm"}
)
"""Units that say a heading is magnetic (``°M``, ``degM``, ``Hdg (mag)``, ``HDG_mag``),
in a column's name or in a units row's cell."""

TRUE_UNITS = frozenset({"°t", "degt", "deg t", "degtrue", "°true", "true", "˚t", "ºt"})
"""Units that say a heading is true (``°T``, ``Hdg (true)``, ``HDG_true``)."""

ANGLE_UNITS: dict[str, float] = {"rad": DEG_PER_RAD, "radian": DEG_PER_RAD, "radians": DEG_PER_RAD}
"""Angle units a column name may carry besides degrees (``Hdg (rad)``, ``COG [rad]``,
``heading_rad``: a logger writing Signal K's SI units): the factor to degrees (an
angle column's)."""

_UNIT_IN_NAME = re.compile(
    r"(?P<name>.+?)(?:\s*[(\[](?P<a>[^)\]]+)[)\]]|[_ ](?P<b>[a-z/°]+))", re.IGNORECASE
)


def _bare(name: str) -> tuple[str, str | None]:
    """A column name without a unit it carries (:data:`HEADER_UNITS`,
    :data:`ANGLE_UNITS`), folded, and the unit (None: none known)."""
    m = _UNIT_IN_NAME.fullmatch(name.strip())
    unit = (m.group("a") or m.group("b")).strip().casefold() if m else ""
    if m is None or not _known_unit(unit):
        return name.strip().casefold(), None
    return m.group("name").strip().casefold(), unit


TIME_ZONE_UNITS = frozenset({"utc", "gmt"})
"""What a time or date column's name may say after it (``Time (UTC)``, ``Date [GMT]``):
its zone, UTC, as times without a zone are taken."""


def _known_unit(unit: str) -> bool:
    """Whether a unit (folded) is one a column's name may carry."""
    return (
        unit in HEADER_UNITS
        or unit in ANGLE_UNITS
        or unit in MAGNETIC_UNITS
        or unit in TIME_ZONE_UNITS
    )


def _ref(key: str, unit: str | None) -> HeadingRef | None:
    """A heading column's reference as the unit in its name says it, else None."""
    if key not in ("heading", "heading_mag") or unit is None:
        return None
    return "magnetic" if unit in MAGNETIC_UNITS else "true" if unit in TRUE_UNITS else None


def _factor(key: str, given: float | None, unit: str | None) -> float:
    """A column's factor to SI: a speed's to m/s (the unit in its name, else the map's,
    else knots), an angle's to degrees (radians in its name or the map's ``[rad]``),
    else 1."""
    if key in SPEEDS:
        named = HEADER_UNITS.get(unit or "")
        return named or (given if given in (1.0, KNOT_MPS) else KNOT_MPS)
    if key in ANGLES:
        return ANGLE_UNITS.get(unit or "") or (given if given == DEG_PER_RAD else 1.0)
    return 1.0


def _fold(name: str) -> str:
    """A column name compared: in any case, its spaces and hyphens as underscores."""
    return re.sub(r"[\s\-]+", "_", name.strip().casefold())


def _resolve(mapping: Mapping[str, str], header: list[str]) -> tuple[dict[str, Col], list[str]]:
    """Map keys to header columns; (columns found, required columns missing)."""
    stripped = [h.strip() for h in header]
    folded = [_fold(h) for h in stripped]
    bare = [_bare(h) for h in stripped]
    bare_names = [_fold(b) for b, _ in bare]
    cols: dict[str, Col] = {}
    missing: list[str] = []
    for key, spec in mapping.items():
        names, optional = _spec(spec)
        for name, given in names:
            unit = None
            # the exact name, else the name in any case and with spaces or hyphens for
            # its underscores (BSP, bsp, Boat Speed), else the name with a unit after it
            # (Bsp (kn), SOG [m/s]: a speed unit is the column's)
            at = stripped.index(name) if name in stripped else None
            if at is None and _fold(name) in folded:
                at = folded.index(_fold(name))
            if at is None and _fold(name) in bare_names:
                at = bare_names.index(_fold(name))
                unit = bare[at][1]
            if at is not None:
                cols[key] = Col(key, at, _factor(key, given, unit), _ref(key, unit))
                break
        else:
            if not optional:
                missing.append(" or ".join(repr(n) for n, _ in names) + f" for {key}")
    return cols, missing


def _split(line: str, delimiter: str) -> list[str]:
    return next(csv.reader([line], delimiter=delimiter), [])


def find_header(
    lines: list[str], maps: Sequence[MapChoice]
) -> tuple[int, str, Preset | None, dict[str, Col]] | None:
    """(header line index, delimiter, preset, columns) of the first line that holds a
    map's required columns."""
    for i, line in enumerate(lines):
        for delim in DELIMITERS:
            if delim not in line:
                continue
            header = _split(line, delim)
            for preset, mapping in maps:
                cols, missing = _resolve(mapping, header)
                if not missing:
                    return i, delim, preset, cols
    return None


def parse_time(value: str, fmt: str) -> float:
    """One time cell (or date + space + time) → epoch seconds, naive times as UTC."""
    if fmt == "ole":
        return (OLE_EPOCH + timedelta(days=float(value))).timestamp()
    if fmt == "filetime":
        return int(value) * FILETIME_TICK_S + FILETIME_EPOCH_S
    if fmt == "epoch":
        return float(value)
    if fmt == "epoch_ms":
        return float(value) / 1000.0
    t = datetime.fromisoformat(value) if fmt == "iso" else datetime.strptime(value, fmt)
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).timestamp()


DATE_TIME_PATTERNS = (
    "%d/%m/%Y %H:%M:%S",
    "%d/%m/%Y %H:%M:%S.%f",
    "%d/%m/%y %H:%M:%S",
    "%d/%m/%y %H:%M:%S.%f",
    "%d.%m.%Y %H:%M:%S",
    "%d.%m.%Y %H:%M:%S.%f",
    "%d-%m-%Y %H:%M:%S",
    "%d-%m-%Y %H:%M:%S.%f",
    "%d-%m-%y %H:%M:%S",
    "%d-%m-%y %H:%M:%S.%f",
    "%Y/%m/%d %H:%M:%S",
    "%Y/%m/%d %H:%M:%S.%f",
    "%m/%d/%Y %I:%M:%S %p",
    "%m/%d/%Y %I:%M:%S.%f %p",
)
"""The date-and-time cells ``auto`` recognises besides ISO 8601, tried in this order on
the first time cell: day first, as European loggers and spreadsheets write it (``/``, ``.`` or ``-`` between), and
month first only with a 12-hour clock's AM/PM (as US-English Windows writes a date;
another month-first file needs ``--time-format``)."""

TIME_OF_DAY = re.compile(r"\d{1,2}:\d{2}(:\d{2}([.,]\d+)?)?")
"""A cell that holds a time of day alone (to be joined to a ``date`` column's cell)."""


def guess_time_format(value: str) -> str | None:
    """``auto``: epoch seconds or milliseconds (a JavaScript or Signal K export), an OLE
    date, Windows FILETIME ticks (100 ns since 1601), ISO 8601 or one of
    :data:`DATE_TIME_PATTERNS`, told by the first time cell."""
    try:
        x = float(value)
    except ValueError:
        try:
            datetime.fromisoformat(value)
        except ValueError:
            return _date_time_pattern(value)
        return "iso"
    if 1e8 < x < 1e10:
        return "epoch"
    if 1e11 < x < 1e13:
        return "epoch_ms"
    if 1e17 < x < 1e18 and value.isdigit():
        return "filetime"
    if 20_000.0 < x < 80_000.0:
        return "ole"
    return None


def _date_time_pattern(value: str) -> str | None:
    """The first of :data:`DATE_TIME_PATTERNS` that reads ``value``, or None."""
    for pattern in DATE_TIME_PATTERNS:
        try:
            datetime.strptime(value, pattern)
        except ValueError:
            continue
        return pattern
    return None


DEGREES_MINUTES = re.compile(
    r"(?P<pre>[NSEW])?\s*(?P<deg>\d{1,3})\s*[°º˚\s]\s*(?P<min>\d{1,2}(?:\.\d+)?)\s*['′]?"
    r"(?:\s*(?P<sec>\d{1,2}(?:\.\d+)?)\s*(?:\"|″|'')?)?\s*(?P<post>[NSEW])?",
    re.IGNORECASE,
)
"""A position written in degrees and minutes (and seconds) with its signs, and a
hemisphere letter before or after: ``45°40.8145'N``, ``N 45° 40.8145'``, ``013 41.0614
E``, ``45°40'48.9"N``."""


def _degrees_minutes(m: re.Match[str], key: str) -> float:
    """:data:`DEGREES_MINUTES`' match → signed degrees.

    Raises:
        ValueError: no hemisphere letter, or two, or one of the other axis; minutes or
            seconds of 60 or more.
    """
    hemis = [h.upper() for h in (m["pre"], m["post"]) if h]
    if len(hemis) != 1 or (key == "lat") != (hemis[0] in "NS"):
        raise ValueError(f"hemisphere {''.join(hemis) or 'missing'} in a {key} cell")
    minutes, seconds = float(m["min"]), float(m["sec"] or 0.0)
    if minutes >= 60.0 or seconds >= 60.0:
        raise ValueError(f"{minutes} minutes, {seconds} seconds")
    x = int(m["deg"]) + minutes / 60.0 + seconds / 3600.0
    return -x if hemis[0] in "SW" else x


def _position(cell: str, key: str) -> float:
    """Decimal degrees, or ``ddmm.mmmm`` / ``dddmm.mmmm`` with a hemisphere letter, or
    degrees and minutes written with their signs (:data:`DEGREES_MINUTES`)."""
    if (m := DEGREES_MINUTES.fullmatch(cell.strip())) is not None:
        return _degrees_minutes(m, key)
    hemi = cell[-1].upper()
    if hemi in "NSEW":
        if (key == "lat") != (hemi in "NS"):
            raise ValueError(f"hemisphere {hemi} in a {key} cell")
        v = float(cell[:-1].strip())
        if not math.isfinite(v) or v < 0.0:
            raise ValueError(cell)
        deg = math.floor(v / 100.0)
        minutes = v - 100.0 * deg
        if minutes >= 60.0:
            raise ValueError(f"{minutes} minutes")
        x = deg + minutes / 60.0
        return -x if hemi in "SW" else x
    return float(cell)


def reasons(c: Counter[str]) -> str:
    return ", ".join(f"{k} {v}" for k, v in c.most_common(4))


def no_header(path: str | Path, head: list[str], candidates: Sequence[MapChoice]) -> str:
    """Why no line is a header: the columns each map lacks, against the likeliest line."""
    line = max(head, key=lambda s: max(s.count(d) for d in DELIMITERS))
    delim = max(DELIMITERS, key=line.count)
    header = _split(line, delim)
    whys = []
    for p, m in candidates:
        _, missing = _resolve(m, header)
        whys.append(f"{p.name if p else 'the map'} lacks {', '.join(missing)}")
    cols = ", ".join(h.strip() for h in header[:12])
    units = unknown_units(header)
    told = (
        f"; units not known in {', '.join(units)} (known: {', '.join(HEADER_UNITS)}): "
        "map the column with its unit, e.g. stw=NAME[mps]"
        if units
        else ""
    )
    first = next((ln for ln in head if ln.strip()), "")
    looks = what_it_looks_like(first)
    if looks and "table" not in looks:  # the file is no table at all
        return f"{path}: no header: the file looks like {looks}; its first line reads {first.strip()[:80]!r}"
    return (
        f"{path}: no header with the mapped columns ({'; '.join(whys)}); the file has {cols}{told}"
    )


def line_unknown_units(line: str, delimiter: str) -> list[str]:
    """:func:`unknown_units` of a header line."""
    return unknown_units(_split(line, delimiter))


def unknown_units(header: list[str]) -> list[str]:
    """The header's names that carry a unit in brackets not in :data:`HEADER_UNITS`
    (``Bsp (furlongs)``), quoted with the unit."""
    out = []
    for h in header:
        m = _UNIT_IN_NAME.fullmatch(h.strip())
        unit = (m.group("a") or "").strip() if m else ""
        if unit and not _known_unit(unit.casefold()):
            out.append(f"{h.strip()!r} ({unit!r})")
    return out


UNIT_KEYS = (*SPEEDS, *ANGLES, "variation")
"""The columns a units row gives a unit to (a time's, a date's or a position's cell is
passed over: ``days``, ``UTC``, ``ddmm.mm``)."""


@dataclass(frozen=True)
class UnitsRow:
    """What a row of units under the header sets: the columns read in its units, the
    headings it says are magnetic."""

    cols: dict[str, Col]
    magnetic: frozenset[str]


def units_row(
    row: list[str], header: list[str], cols: Mapping[str, Col], path: str | Path
) -> UnitsRow | None:
    """The row under the header read as its units (Expedition's and several loggers'
    second header line), or None when it is data: a units row has no cell that is a
    number or a time, and a unit known in a mapped column's cell. Each speed or angle column
    with a unit cell is read in that unit (:data:`HEADER_UNITS`, :data:`ANGLE_UNITS`;
    ``°M`` or ``degM`` for a heading: magnetic); an empty cell leaves the column as it
    was.

    Raises:
        ImportFormatError: a mapped column's unit not known for its kind (a speed's,
            an angle's), or one that contradicts the unit in the column's name; the error
            names the column.
    """
    cells = [c.strip() for c in row]
    if not any(cells) or any(_is_value(c) for c in cells):
        return None
    given = [_unit_cell(cell(row, c.index)) for k, c in cols.items() if k in UNIT_KEYS]
    if not any(u in HEADER_UNITS or u in ANGLE_UNITS or u in MAGNETIC_UNITS for u in given):
        return None  # no unit known in a mapped column: a row of text, not of units
    out = dict(cols)
    magnetic: set[str] = set()
    for key, c in cols.items():
        text = cell(row, c.index)
        unit = _unit_cell(text)
        if key not in UNIT_KEYS or not unit:
            continue
        name = header[c.index].strip() if c.index < len(header) else key
        where = f"{path}: column {name!r} ({key})"
        if key in SPEEDS:
            factor = HEADER_UNITS.get(unit)
            kinds = ", ".join(u for u, f in HEADER_UNITS.items() if f is not None)
        elif unit in MAGNETIC_UNITS and key in ("heading", "heading_mag"):
            factor, kinds = 1.0, ""
            magnetic.add(key)
        else:
            degrees = unit in HEADER_UNITS and HEADER_UNITS[unit] is None
            factor = ANGLE_UNITS.get(unit) or (1.0 if degrees else None)
            kinds = ", ".join([*(u for u, f in HEADER_UNITS.items() if f is None), *ANGLE_UNITS])
        if factor is None:
            kind = "a speed" if key in SPEEDS else "an angle"
            raise ImportFormatError(
                f"{where}: the units row under the header gives it the unit {text!r}, "
                f"not known for {kind} (known: {kinds}): correct the row, or remove it and "
                f"map the column with its unit (--map {key}={name}[{'mps' if key in SPEEDS else 'rad'}])"
            )
        named = _bare(name)[1]
        if named is not None and _factor(key, None, named) != factor:
            raise ImportFormatError(
                f"{where}: the units row under the header says {text!r}, its name {named!r}"
            )
        out[key] = replace(c, factor=factor)
    return UnitsRow(out, frozenset(magnetic))


def _unit_cell(text: str) -> str:
    """A units row's cell compared: in any case, without brackets around it."""
    return text.strip("()[] ").casefold()


def _is_value(text: str) -> bool:
    """Whether a cell holds a number, a position or a time (a data row's cell)."""
    try:
        float(text.replace(",", "."))
    except ValueError:
        return bool(guess_time_format(text) or TIME_OF_DAY.fullmatch(text)) or bool(
            re.fullmatch(r"\d+(\.\d+)?\s*[NSEW]", text)
        )
    return True


def cell(row: list[str], index: int) -> str:
    """A row's cell, stripped; empty when absent or a :data:`NO_VALUE`."""
    text = row[index].strip() if index < len(row) else ""
    return "" if text.casefold() in NO_VALUE else text


def cell_value(cell: str, c: Col, report: ImportReport) -> float | None:
    """A cell's value in SI units, or None (counted) when it is no number or out of range.
    A comma in a cell is a decimal comma (the delimiter is then not a comma)."""
    cell = cell.replace(",", ".")
    try:
        x = _position(cell, c.key) if c.key in ("lat", "lon") else float(cell) * c.factor
    except (ValueError, IndexError):
        report.cells[f"{c.key}: not_a_number"] += 1
        return None
    lo, hi = LIMITS[c.key]
    if not (math.isfinite(x) and lo <= x <= hi):
        report.cells[f"{c.key}: out_of_range"] += 1
        return None
    return x % 360.0 if c.key in ANGLES else x


def candidate_maps(mapping: Mapping[str, str] | None, preset: str | None) -> list[MapChoice]:
    """The column maps a header is tried against: each preset's for ``auto`` (the default
    without a map), the named preset's, or the plain map; the user's columns added to,
    and overriding, a preset's.

    Raises:
        ImportFormatError: an unknown preset, or a map without ``time`` or ``stw``.
    """
    given = dict(mapping or {})
    if preset is None and not given:
        preset = "auto"
    if preset not in (None, "auto") and preset not in PRESETS:
        raise ImportFormatError(f"no preset {preset!r} (presets: {', '.join(PRESETS)})")
    candidates: list[MapChoice]
    if preset == "auto":
        candidates = [(p, {**p.columns, **given}) for p in PRESETS.values()]
    elif preset is not None:
        candidates = [(PRESETS[preset], {**PRESETS[preset].columns, **given})]
    else:
        candidates = [(None, given)]
    for _, m in candidates:
        for key in ("time", "stw"):
            if key not in m:
                raise ImportFormatError(
                    f"the column map needs {key}= (has {', '.join(m) or 'none'})"
                )
    return candidates
