"""``emlogd import``: the logs people already have, turned into captures.

Both formats stream (constant memory, any file size, ``.gz`` read through gzip), write
the capture in time order, and count what they skipped by reason (a line, row or cell
is never silently dropped). The capture is written next to its final name and moved
there only when the import succeeds.

**NMEA 0183 logs without receive times** (a chart plotter's or a logger's file):
every line must be a complete sentence with a valid checksum (checked as the
decoders do); the rest is counted by reason. Time comes from the fixes: the UTC date
and time of RMC, else ZDA, else GGA's time of day with a date given by ``--date`` (or
learnt from an earlier RMC/ZDA of the log). A fix whose time does not increase is no
time source, nor is one outside :data:`YEARS`. The sentences between two fixes are
spread evenly, in their order, over the interval up to the next fix. Sentences before the first fix and after the last
have no time and are counted (``before_first_fix``, ``after_last_fix``): times are
never extrapolated past the last fix. Two fixes more than :data:`MAX_FIX_GAP_S` apart
(a logger paused, files joined) leave the sentences between them without a time
(``fix_gap``), as does a stretch of more than :data:`MAX_PENDING_LINES` sentences
without a fix.

**CSV/TSV exports** of navigation software and loggers: a column map (``key=Column``
for ``time``, ``date``, ``stw``, ``heading``, ``sog``, ``cog``, ``lat``, ``lon``,
``set``, ``drift``, ``variation``; a column may be written ``A|B`` — the first
present in the header — and ``Name?`` when it may be absent; speeds in knots unless
written ``Name[mps]``), or a preset chosen by the header (:data:`PRESETS`). The
delimiter (comma, tab, semicolon, bar) and the header line are found in the file:
the header is the first of the first :data:`HEADER_SCAN_LINES` lines that holds the
mapped columns, so a banner before it is passed over (and counted). Column names
match in any case; with a delimiter other than the comma, a comma in a number is a
decimal comma. Times are OLE dates (days since 1899-12-30: Excel, Expedition), ISO
8601, epoch seconds, or a
``strptime`` pattern; with a ``date`` column, date and time are joined with a space
before parsing. Times without a zone are UTC unless ``--utc-offset`` says the logger
kept local time. Positions are decimal degrees or ``ddmm.mmmmN``/``dddmm.mmmmE``.

Every cell is checked against the range a boat can produce (:data:`LIMITS`); a bad
or impossible cell is counted in ``cells`` by column and reason and is not used —
the rest of its row still is. A row that gives no sentence is counted in ``skipped``:
``no_time`` (empty), ``bad_time`` (unreadable), ``time_out_of_range`` (outside
:data:`YEARS`), ``time_going_back``, ``no_new_value`` (every cell empty or a repeat),
``bad_cell`` (its new cells all bad), ``incomplete`` (a new cell whose sample lacks
its other cells: a heading without any speed within ``carry_s``).

**Only cells actually written become samples.** The cells form three samples: the
water (``stw``, ``heading``), the fix's velocity (``sog``, ``cog``; the position and
the variation go with it without making one) and the logging software's current
(``set``, ``drift``). An empty cell is no update. A row makes a new sample of a group
when one of the group's cells is written with a value that differs from the last one
written. A cell written equal to the previous value is either the export carrying
the last value forward (Expedition writes every column on every row: in the Valencia
log half the ``Sog`` and ``iSet`` cells repeat the row before, ``Bsp`` to 0.001 kn
under 1 %) or the instrument reading the same again; the file tells them apart by its
own update rate: the group's period is the median interval between its changes (the
last :data:`PERIOD_WINDOW`), and a repeat is a new sample only when it comes at least
:data:`REPEAT_PERIOD_FRACTION` of a period after the group's last sample — a
carried-forward cell comes sooner. The repeats are counted in ``notes``
(``water_repeat``, ``fix_repeat``, ``current_repeat``; those taken as samples
``…_repeat_kept``): the file's evidence. A sample takes the group's other cells as last
written, for at most ``carry_s`` seconds. Each sample becomes one sentence at its
row's time: RMC for a fix (speed and course over ground, the position when mapped,
the variation when known), VHW for the water (speed and heading, true or magnetic),
VDR for the current (set towards, drift in knots). Within a row RMC comes first, so
the variation it carries is known when the VHW's magnetic heading arrives.

The variation for a magnetic heading: a ``variation`` column, else ``--variation
DEG``; without either the RMC has none, and calibration takes the IGRF model's at
the fix's position and date (:mod:`emlogd.pipeline.variation`). The import runs the
heading-against-course check of that module on the rows (``heading_check``), so a
magnetic heading imported as true, or a wrong compass, shows at once.
"""

from __future__ import annotations

import csv
import gzip
import io
import math
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, timedelta
from pathlib import Path
from typing import Literal, TextIO

from drivers import make_decoder
from drivers.errors import EmlogdError, FrameError
from drivers.framing import split_nmea
from drivers.io.capture import CaptureWriter
from drivers.nmea0183 import Gga, NmeaRecord, Rmc, Zda, encode_rmc, encode_vhw
from drivers.records import KNOT_MPS, Rejected
from emlogd.offline import ProgressFn
from emlogd.pipeline.sentences import encode_vdr
from emlogd.pipeline.variation import CourseOffsetCheck, model_variation

HeadingRef = Literal["true", "magnetic"]

OLE_EPOCH = datetime(1899, 12, 30, tzinfo=UTC)
"""Day 0 of OLE automation dates (Excel, Expedition)."""

CARRY_S = 10.0
"""A group's other cells are taken as last written for at most this long, s."""

MAX_FIX_GAP_S = 60.0
"""NMEA: fixes further apart than this leave the sentences between them untimed, s
(spread evenly over a longer gap they could be off by minutes)."""

MAX_PENDING_LINES = 100_000
"""NMEA: sentences waiting for the next fix, at most (constant memory)."""

HEADER_SCAN_LINES = 50
"""CSV: the header must be among the first this many lines (a banner before it)."""

DELIMITERS = (",", "\t", ";", "|")
"""CSV: the delimiters the header is tried with."""

MAX_SPEED_KN = 80.0
"""A speed through the water or over the ground above this is not a boat's, kn."""

MAX_DRIFT_KN = 15.0
"""A current above this is not the sea's (the strongest tidal races run near 10 kn), kn."""

YEARS = (1980, 2100)
"""A row or fix time outside these years is a misread time (GPS-era logs only)."""
_YEAR_LO = datetime(YEARS[0], 1, 1, tzinfo=UTC).timestamp()
_YEAR_HI = datetime(YEARS[1], 1, 1, tzinfo=UTC).timestamp()

LIMITS: dict[str, tuple[float, float]] = {
    "stw": (0.0, MAX_SPEED_KN * KNOT_MPS),
    "sog": (0.0, MAX_SPEED_KN * KNOT_MPS),
    "heading": (-360.0, 360.0),
    "cog": (-360.0, 360.0),
    "set": (-360.0, 360.0),
    "drift": (0.0, MAX_DRIFT_KN * KNOT_MPS),
    "lat": (-90.0, 90.0),
    "lon": (-180.0, 180.0),
    "variation": (-90.0, 90.0),
}
"""Each column's plausible range after unit conversion (m/s, degrees; angles wrapped
after the check)."""

ANGLES = ("heading", "cog", "set")
SPEEDS = ("stw", "sog", "drift")
CSV_KEYS = (
    "time",
    "date",
    "stw",
    "heading",
    "sog",
    "cog",
    "lat",
    "lon",
    "set",
    "drift",
    "variation",
)
GROUPS: dict[str, tuple[str, ...]] = {
    "fix": ("sog", "cog"),
    "water": ("stw", "heading"),
    "current": ("set", "drift"),
}
"""The samples a row's cells form (module docstring), in the order they are written; the
position and the variation go with the fix without making one."""

REPEAT_PERIOD_FRACTION = 0.9
"""A repeated value is a new sample when it comes this fraction of the group's update
period (or more) after the group's last sample."""

PERIOD_WINDOW = 64
"""The update period is the median of this many last intervals between changes."""

PERIOD_MIN_INTERVALS = 8
"""Intervals needed before the update period is known (until then a repeat is none)."""


class _Group:
    """One sample group's timing: its last change, its last sample, its update period."""

    def __init__(self, keys: tuple[str, ...]) -> None:
        self.keys = keys
        self.t_change = -math.inf
        self.t_sample = -math.inf
        self.intervals: deque[float] = deque(maxlen=PERIOD_WINDOW)

    def changed(self, t: float) -> None:
        if math.isfinite(self.t_change):
            self.intervals.append(t - self.t_change)
        self.t_change = t

    def repeat_is_sample(self, t: float) -> bool:
        """Whether a repeat at ``t`` comes a full update period after the last sample."""
        if len(self.intervals) < PERIOD_MIN_INTERVALS:
            return False
        period = sorted(self.intervals)[len(self.intervals) // 2]
        return t - self.t_sample >= REPEAT_PERIOD_FRACTION * period


@dataclass(frozen=True)
class Preset:
    """A known export: its columns, how it keeps time, its heading's reference.

    Attributes:
        name: the ``--preset`` name.
        columns: the column map (``A|B`` alternatives, ``?`` optional).
        time_format: ``ole``, ``iso``, ``epoch`` or a ``strptime`` pattern.
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
    "heading": "Hdg",
    "sog": "Sog?",
    "cog": "Cog?",
    "lat": "Lat?",
    "lon": "Lon|Long?",
    "set": "iSet|Set?",
    "drift": "iDrift|Drift?",
}
"""Expedition's columns (its ``Hdg`` is a true heading; times are OLE dates). Its exports
name the current ``iSet``/``iDrift`` or ``Set``/``Drift``, or leave it out."""

LOGGER_TSV: dict[str, str] = {
    "date": "Date",
    "time": "Time",
    "stw": "Boatspeed",
    "heading": "Heading",
    "sog": "Ext_SOG?",
    "cog": "Ext_COG?",
    "lat": "Latitudine?",
    "lon": "Longitudine?",
    "set": "SET?",
    "drift": "DRIFT?",
}
"""An Italian race logger's tab-separated export (``Date`` dd/mm/yy, ``Time`` of its
clock, magnetic ``Heading``, ``ddmm.mmmmN`` positions)."""

PRESETS: dict[str, Preset] = {
    "expedition": Preset(
        "expedition", EXPEDITION, "ole", "true", False, "Expedition CSV (Utc, Bsp, Hdg...)"
    ),
    "logger-tsv": Preset(
        "logger-tsv",
        LOGGER_TSV,
        "%d/%m/%y %H:%M:%S",
        "magnetic",
        True,
        "race logger TSV (Date, Time, Boatspeed, Heading, Ext_SOG...)",
    ),
}
"""The presets, tried in this order against the header when none is named."""


class ImportFormatError(EmlogdError):
    """An import cannot run (a bad map, no time source, an unreadable file)."""


@dataclass
class ImportReport:
    """What an import did.

    Attributes:
        files: the input files.
        out: the capture written.
        port: its port name.
        lines: input lines (NMEA) or data rows (CSV) read.
        written: sentences written.
        skipped: lines or rows that gave no sentence, by reason.
        cells: CSV cells not used, by ``column: reason``.
        notes: what was met but did not cost a line (a fix whose time does not
            increase; a carried-forward cell; banner lines; an assumed time zone).
        sentences: sentences written, by type.
        preset: the CSV preset used (None with a plain map or NMEA).
        heading_ref: the CSV heading's reference.
        heading_check: the CSV heading against the course over ground (the check of
            :mod:`emlogd.pipeline.variation`, ``CourseOffsetCheck.as_dict``), None without
            heading and course.
        variation: where a CSV magnetic heading's variation comes from (``column``,
            ``option``, ``model`` at calibration from the positions, ``none``: give
            ``--variation``), None for a true heading.
        t_start: first record time, s since the epoch (nan when none).
        t_end: last record time, s.
    """

    files: list[str]
    out: str
    port: str
    lines: int = 0
    written: int = 0
    skipped: Counter[str] = field(default_factory=Counter)
    cells: Counter[str] = field(default_factory=Counter)
    notes: Counter[str] = field(default_factory=Counter)
    sentences: Counter[str] = field(default_factory=Counter)
    preset: str | None = None
    heading_ref: str | None = None
    variation: str | None = None
    heading_check: dict[str, object] | None = None
    t_start: float = math.nan
    t_end: float = math.nan

    def to_dict(self) -> dict[str, object]:
        """Plain types (``import --json``)."""
        return {
            "files": self.files,
            "out": self.out,
            "port": self.port,
            "lines": self.lines,
            "written": self.written,
            "skipped": dict(sorted(self.skipped.items())),
            "cells": dict(sorted(self.cells.items())),
            "notes": dict(sorted(self.notes.items())),
            "sentences": dict(sorted(self.sentences.items())),
            "preset": self.preset,
            "heading_ref": self.heading_ref,
            "variation": self.variation,
            "heading_check": self.heading_check,
            "t_start": None if math.isnan(self.t_start) else self.t_start,
            "t_end": None if math.isnan(self.t_end) else self.t_end,
            "span_s": None if math.isnan(self.t_start) else round(self.t_end - self.t_start, 3),
        }


class _Out:
    """The capture being written: a temporary file renamed into place on success."""

    def __init__(self, out: str | Path, port: str, comment: str, report: ImportReport) -> None:
        self.path = Path(out)
        self.tmp = self.path.with_name(self.path.name + ".part" + _gz(self.path))
        self.port = port
        self.report = report
        self.check = CourseOffsetCheck()
        try:
            self.w = CaptureWriter(self.tmp, {port: "nmea0183"})
            self.w.comment(comment.encode("ascii", "replace").decode("ascii"))
        except OSError as exc:
            raise ImportFormatError(f"{out}: cannot write: {exc.strerror or exc}") from None

    def write(self, t: float, line: str) -> None:
        self.w.write_line(t, self.port, line.encode("ascii"))
        r = self.report
        r.written += 1
        r.sentences[_kind(line)] += 1
        if r.written == 1:
            r.t_start = t
        r.t_end = t

    def commit(self) -> None:
        self.w.close()
        self.tmp.replace(self.path)

    def abort(self) -> None:
        self.w.close()
        self.tmp.unlink(missing_ok=True)


def _gz(path: Path) -> str:
    return ".gz" if path.name.endswith(".gz") else ""


def _count(counter: Counter[str], key: str, n: int) -> None:
    """Add ``n`` to a counter's ``key`` (no zero entries)."""
    if n:
        counter[key] += n


def _kind(line: str) -> str:
    """The sentence type (``RMC``, ``VHW``; a proprietary one by its address)."""
    address = line[1:].split(",", 1)[0]
    return address if address.startswith("P") else address[2:]


def _open_text(path: str | Path) -> TextIO:
    """A text stream of a file, through gzip when it starts with gzip's magic."""
    try:
        raw = open(path, "rb")  # noqa: SIM115
    except OSError as exc:
        raise ImportFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if raw.peek(2)[:2] == b"\x1f\x8b":
        raw.close()
        return gzip.open(path, "rt", encoding="utf-8-sig", errors="replace")
    return io.TextIOWrapper(raw, encoding="utf-8-sig", errors="replace")


# ------------------------------------------------------------------ NMEA logs


def _fix_time(rec: NmeaRecord | Rejected, day: date | None) -> tuple[float | None, date | None]:
    """(epoch seconds of a fix, the date it implies) for an RMC, ZDA or GGA record."""
    if isinstance(rec, Rmc | Zda) and rec.time_utc is not None:
        return rec.time_utc.timestamp(), rec.time_utc.date()
    if isinstance(rec, Gga) and rec.time_of_day_s is not None and day is not None:
        base = datetime(day.year, day.month, day.day, tzinfo=UTC)
        return (base + timedelta(seconds=rec.time_of_day_s)).timestamp(), day
    return None, day


class _Spreader:
    """Sentences timed from the fixes around them, written as each next fix arrives."""

    def __init__(self, out: _Out, report: ImportReport) -> None:
        self.out = out
        self.report = report
        self.fix: float | None = None  # the last fix's time
        self.pending: list[str] = []  # the last fix's sentence, then those after it
        self.overflow = 0

    def add(self, text: str, t_fix: float | None) -> None:
        r = self.report
        if t_fix is not None and not _YEAR_LO <= t_fix < _YEAR_HI:
            r.notes["fix_time_out_of_range"] += 1
            t_fix = None
        if t_fix is not None and self.fix is not None and t_fix <= self.fix:
            r.notes["fix_time_not_increasing"] += 1
            t_fix = None
        if t_fix is None:
            if self.fix is None:
                r.skipped["before_first_fix"] += 1
            elif len(self.pending) >= MAX_PENDING_LINES:
                self.overflow += 1
            else:
                self.pending.append(text)
            return
        if self.fix is not None:
            self._release(t_fix)
        self.fix = t_fix
        self.pending = [text]

    def _release(self, t_next: float) -> None:
        assert self.fix is not None
        r = self.report
        if t_next - self.fix > MAX_FIX_GAP_S or self.overflow:
            self.out.write(self.fix, self.pending[0])
            _count(r.skipped, "fix_gap", len(self.pending) - 1 + self.overflow)
        else:
            step = (t_next - self.fix) / len(self.pending)
            for j, line in enumerate(self.pending):
                self.out.write(self.fix + step * j, line)
        self.overflow = 0

    def finish(self) -> None:
        if self.fix is None:
            return
        self.out.write(self.fix, self.pending[0])
        _count(self.report.skipped, "after_last_fix", len(self.pending) - 1 + self.overflow)


def import_nmea(
    paths: Sequence[str | Path],
    out: str | Path,
    *,
    port: str = "nmea",
    day: date | None = None,
    progress: ProgressFn | None = None,
) -> ImportReport:
    """Import NMEA 0183 logs without receive times (see the module docstring).

    Args:
        paths: the log files, in time order (their sentences are concatenated).
        out: the capture to write.
        port: its port name.
        day: the UTC date for GGA times when no RMC or ZDA gives one.
        progress: called after each file.

    Raises:
        ImportFormatError: a file cannot be read, or no sentence has a time.
    """
    report = ImportReport([str(p) for p in paths], str(out), port)
    decoder = make_decoder("nmea0183", port, errors="raise")
    sink = _Out(out, port, f"emlogd import --format nmea: {', '.join(report.files)}", report)
    spread = _Spreader(sink, report)
    current_day = day
    try:
        for i, path in enumerate(paths):
            with _open_text(path) as f:
                for raw in f:
                    report.lines += 1
                    text = raw.strip()
                    if not text:
                        report.skipped["empty"] += 1
                        continue
                    if text[0] not in "$!" or not text.isascii():
                        report.skipped["not_nmea"] += 1
                        continue
                    try:
                        split_nmea(text.encode("ascii"), required=True)
                    except FrameError as exc:
                        report.skipped[exc.reason] += 1
                        continue
                    fix: float | None = None
                    try:
                        decoded = decoder.decode_all((text + "\r\n").encode("ascii"))
                    except FrameError:
                        decoded = []  # a sentence the decoders do not parse is still kept
                    for rec in decoded:
                        fix, current_day = _fix_time(rec, current_day)
                    spread.add(text, fix)
            if progress is not None:
                progress(f"import {Path(path).name}", (i + 1) / len(paths))
        spread.finish()
        if report.written == 0:
            raise ImportFormatError(
                "no sentence could be given a time: the log needs RMC or ZDA fixes "
                "(or GGA with --date YYYY-MM-DD)"
            )
    except BaseException:
        sink.abort()
        raise
    sink.commit()
    return report


# ------------------------------------------------------------------ CSV exports


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
class _Col:
    """A mapped column: its index and the factor to SI."""

    key: str
    index: int
    factor: float


def _spec(spec: str) -> tuple[list[tuple[str, float]], bool]:
    """``A[mps]|B?`` → ([(name, factor to m/s)...], optional)."""
    optional = spec.endswith("?")
    names: list[tuple[str, float]] = []
    for alt in (spec[:-1] if optional else spec).split("|"):
        alt = alt.strip()
        if alt.endswith("[mps]"):
            names.append((alt[:-5], 1.0))
        elif alt.endswith("[kn]"):
            names.append((alt[:-4], KNOT_MPS))
        else:
            names.append((alt, KNOT_MPS))
    return names, optional


def _resolve(mapping: Mapping[str, str], header: list[str]) -> tuple[dict[str, _Col], list[str]]:
    """Map keys to header columns; (columns found, required columns missing)."""
    stripped = [h.strip() for h in header]
    folded = [h.casefold() for h in stripped]
    cols: dict[str, _Col] = {}
    missing: list[str] = []
    for key, spec in mapping.items():
        names, optional = _spec(spec)
        for name, factor in names:
            # the exact name, else the name in any case (BSP, bsp, Bsp)
            at = stripped.index(name) if name in stripped else None
            if at is None and name.casefold() in folded:
                at = folded.index(name.casefold())
            if at is not None:
                cols[key] = _Col(key, at, factor if key in SPEEDS else 1.0)
                break
        else:
            if not optional:
                missing.append(" or ".join(repr(n) for n, _ in names) + f" for {key}")
    return cols, missing


def _split(line: str, delimiter: str) -> list[str]:
    return next(csv.reader([line], delimiter=delimiter), [])


def _find_header(
    lines: list[str], maps: Sequence[tuple[Preset | None, Mapping[str, str]]]
) -> tuple[int, str, Preset | None, dict[str, _Col]] | None:
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


def _parse_time(value: str, fmt: str) -> float:
    """One time cell (or date + space + time) → epoch seconds, naive times as UTC."""
    if fmt == "ole":
        return (OLE_EPOCH + timedelta(days=float(value))).timestamp()
    if fmt == "epoch":
        return float(value)
    t = datetime.fromisoformat(value) if fmt == "iso" else datetime.strptime(value, fmt)
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).timestamp()


def _guess_time_format(value: str) -> str | None:
    """``auto``: epoch seconds, an OLE date or ISO 8601, told by the first time cell."""
    try:
        x = float(value)
    except ValueError:
        try:
            datetime.fromisoformat(value)
        except ValueError:
            return None
        return "iso"
    if 1e8 < x < 1e10:
        return "epoch"
    if 20_000.0 < x < 80_000.0:
        return "ole"
    return None


def _position(cell: str, key: str) -> float:
    """Decimal degrees, or ``ddmm.mmmm`` / ``dddmm.mmmm`` with a hemisphere letter."""
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


def import_csv(
    path: str | Path,
    out: str | Path,
    mapping: Mapping[str, str] | None = None,
    *,
    preset: str | None = None,
    time_format: str | None = None,
    heading_ref: HeadingRef | None = None,
    utc_offset_h: float | None = None,
    variation_deg: float | None = None,
    port: str = "nmea",
    carry_s: float = CARRY_S,
    progress: ProgressFn | None = None,
) -> ImportReport:
    """Import a CSV/TSV export (see the module docstring).

    Args:
        path: the export.
        out: the capture to write.
        mapping: the column map (added to, and overriding, the preset's).
        preset: a name of :data:`PRESETS`, ``auto`` (the first whose columns the header
            has), or None (``auto`` without a map, else none).
        time_format: ``ole``, ``iso``, ``epoch``, a ``strptime`` pattern, or None (the
            preset's; without one ``auto``: told by the first time cell).
        heading_ref: the heading's reference (default: the preset's, else true).
        utc_offset_h: the logger's clock minus UTC, hours (times are UTC without it).
        variation_deg: magnetic variation, east positive, when no column gives one.
        port: the capture's port name.
        carry_s: how long a group's other cells are taken as last written, s.
        progress: called at the end.

    Raises:
        ImportFormatError: an unreadable file, a map without time/stw, a mapped column
            missing from the header, no row with a time and a speed.
    """
    given = dict(mapping or {})
    if preset is None and not given:
        preset = "auto"
    if preset not in (None, "auto") and preset not in PRESETS:
        raise ImportFormatError(f"no preset {preset!r} (presets: {', '.join(PRESETS)})")
    candidates: list[tuple[Preset | None, Mapping[str, str]]]
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
    report = ImportReport([str(path)], str(out), port)
    f = _open_text(path)
    with f:
        head: list[str] = []
        for line in f:
            head.append(line.rstrip("\r\n"))
            if len(head) >= HEADER_SCAN_LINES:
                break
        if not head:
            raise ImportFormatError(f"{path}: empty file")
        found = _find_header(head, candidates)
        if found is None:
            raise ImportFormatError(_no_header(path, head, candidates))
        h_index, delim, chosen, cols = found
        report.preset = chosen.name if chosen is not None else None
        _count(report.notes, "banner_lines", h_index)
        fmt = time_format or (chosen.time_format if chosen is not None else "auto")
        report.heading_ref = href = heading_ref or (
            chosen.heading_ref if chosen is not None else "true"
        )
        if chosen is not None and chosen.local_time and utc_offset_h is None:
            report.notes["local_time_taken_as_utc"] += 1
        if "heading" in cols and href == "magnetic":
            report.variation = (
                "column" if "variation" in cols else "option" if variation_deg is not None else None
            )
            if report.variation is None:
                report.variation = "model" if "lat" in cols and "lon" in cols else "none"
        rows = _chain(head[h_index + 1 :], f)
        sink = _Out(out, port, f"emlogd import --format csv: {path}", report)
        try:
            _csv_rows(
                rows, delim, cols, fmt, href, utc_offset_h or 0.0, variation_deg, carry_s, sink
            )
            if sink.check.n:
                report.heading_check = sink.check.as_dict()
            if report.written == 0:
                raise ImportFormatError(
                    f"{path}: no row with a time and a speed through the water "
                    f"(skipped: {_reasons(report.skipped) or 'none'}; "
                    f"cells: {_reasons(report.cells) or 'none'})"
                )
        except BaseException:
            sink.abort()
            raise
        sink.commit()
    if progress is not None:
        progress(f"import {Path(path).name}", 1.0)
    return report


def _reasons(c: Counter[str]) -> str:
    return ", ".join(f"{k} {v}" for k, v in c.most_common(4))


def _no_header(
    path: str | Path, head: list[str], candidates: Sequence[tuple[Preset | None, Mapping[str, str]]]
) -> str:
    """Why no line is a header: the columns each map lacks, against the likeliest line."""
    line = max(head, key=lambda s: max(s.count(d) for d in DELIMITERS))
    delim = max(DELIMITERS, key=line.count)
    header = _split(line, delim)
    whys = []
    for p, m in candidates:
        _, missing = _resolve(m, header)
        whys.append(f"{p.name if p else 'the map'} lacks {', '.join(missing)}")
    cols = ", ".join(h.strip() for h in header[:12])
    return f"{path}: no header with the mapped columns ({'; '.join(whys)}); the file has {cols}"


def _chain(first: list[str], rest: TextIO) -> Iterator[str]:
    yield from first
    for line in rest:
        yield line.rstrip("\r\n")


def _csv_rows(
    lines: Iterator[str],
    delim: str,
    cols: dict[str, _Col],
    fmt: str,
    href: HeadingRef,
    utc_offset_h: float,
    variation_deg: float | None,
    carry_s: float,
    sink: _Out,
) -> None:
    """Turn the data rows into sentences (module docstring)."""
    report = sink.report
    tcol, dcol = cols["time"], cols.get("date")
    value_cols = [c for k, c in cols.items() if k not in ("time", "date")]
    last: dict[str, tuple[float, float]] = {}  # key → (time written, value)
    groups = {name: _Group(keys) for name, keys in GROUPS.items()}
    t_prev = -math.inf
    for row in csv.reader(lines, delimiter=delim):
        if not row or not any(c.strip() for c in row):
            continue
        report.lines += 1
        stamp = _cell(row, tcol.index)
        if dcol is not None:
            d = _cell(row, dcol.index)
            stamp = f"{d} {stamp}" if d and stamp else ""
        if not stamp:
            report.skipped["no_time"] += 1
            continue
        if fmt in ("ole", "epoch", "auto") and delim != ",":
            stamp = stamp.replace(",", ".")  # a decimal comma
        if fmt == "auto":
            fmt = _guess_time_format(stamp) or "auto"
        try:
            t = _parse_time(stamp, fmt) - utc_offset_h * 3600.0 if fmt != "auto" else math.nan
        except (ValueError, OverflowError, OSError):
            t = math.nan
        if not math.isfinite(t):
            report.skipped["bad_time"] += 1
            continue
        if not _YEAR_LO <= t < _YEAR_HI:
            report.skipped["time_out_of_range"] += 1
            continue
        if t < t_prev:
            report.skipped["time_going_back"] += 1
            continue
        t_prev = t
        new: set[str] = set()
        bad = False
        for c in value_cols:
            cell = _cell(row, c.index)
            if not cell:
                continue
            x = _value(cell, c, report)
            if x is None:
                bad = True
                continue
            held = last.get(c.key)
            if held is None or held[1] != x:
                new.add(c.key)
            last[c.key] = (t, x)
        if not _row_sentences(t, new, last, groups, href, variation_deg, carry_s, sink):
            reason = "incomplete" if new else "bad_cell" if bad else "no_new_value"
            report.skipped[reason] += 1


def _cell(row: list[str], index: int) -> str:
    return row[index].strip() if index < len(row) else ""


def _value(cell: str, c: _Col, report: ImportReport) -> float | None:
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


def _check(
    sink: _Out,
    t: float,
    get: Callable[[str], float | None],
    href: HeadingRef,
    variation_deg: float | None,
    sog: float,
    cog: float,
) -> None:
    """Feed a fix and the heading at its row to the heading-against-course check (a
    magnetic heading made true with the column's, the option's or the model's variation)."""
    hdg = get("heading")
    if hdg is None:
        return
    if href == "magnetic":
        var = get("variation")
        var = var if var is not None else variation_deg
        lat, lon = get("lat"), get("lon")
        if var is None and lat is not None and lon is not None:
            var = model_variation(lat, lon, t)
        if var is None:
            return
        hdg = (hdg + var) % 360.0
    sink.check.add(t, hdg, sog, cog)


def _row_sentences(
    t: float,
    new: set[str],
    last: dict[str, tuple[float, float]],
    groups: dict[str, _Group],
    href: HeadingRef,
    variation_deg: float | None,
    carry_s: float,
    sink: _Out,
) -> bool:
    """Write the samples the row's new cells make; whether any was written."""
    report = sink.report

    def get(key: str) -> float | None:
        held = last.get(key)
        return held[1] if held is not None and t - held[0] <= carry_s else None

    wrote = False
    for group, g in groups.items():
        if not any(k in last and last[k][0] == t for k in g.keys):
            continue  # nothing of the group written in this row
        if new.intersection(g.keys):
            g.changed(t)
        elif g.repeat_is_sample(t):
            report.notes[f"{group}_repeat_kept"] += 1
        else:
            report.notes[f"{group}_repeat"] += 1
            continue
        line: str | None = None
        if group == "fix":
            sog, cog = get("sog"), get("cog")
            if sog is not None and cog is not None:
                var = get("variation")
                line = encode_rmc(
                    datetime.fromtimestamp(t, UTC),
                    sog,
                    cog,
                    lat_deg=get("lat"),
                    lon_deg=get("lon"),
                    variation_deg=var if var is not None else variation_deg,
                    talker="GP",
                )
                _check(sink, t, get, href, variation_deg, sog, cog)
        elif group == "water":
            stw = get("stw")
            if stw is not None:
                hdg = get("heading")
                line = encode_vhw(
                    stw,
                    heading_true_deg=hdg if href == "true" else None,
                    heading_mag_deg=hdg if href == "magnetic" else None,
                    talker="II",
                )
        else:
            set_deg, drift = get("set"), get("drift")
            if set_deg is not None and drift is not None:
                line = encode_vdr(set_deg, None, drift / KNOT_MPS, "II")
        if line is not None:
            sink.write(t, line)
            g.t_sample = t
            wrote = True
    return wrote
