"""``emlogd import``: the logs people already have, turned into captures.

Both formats stream (constant memory, any file size, ``.gz`` read through gzip, UTF-16 told by its byte-order mark), write
the capture in time order, and count what they skipped by reason (a line, row or cell
is never silently dropped). The capture is written next to its final name and moved
there only when the import succeeds.

**NMEA 0183 logs without receive times** (a chart plotter's or a logger's file):
every line must be a complete sentence with a valid checksum (checked as the
decoders do); the rest is counted by reason. A log written without checksums (more
of its sentences so far without one than with one) has each well-formed sentence
taken with its checksum added (``checksum_added`` in ``notes``); in a log with
checksums a line without one is a cut line (``missing_checksum``). A line with
something before its sentence (a logger's receive time, a tag) is read from its
first ``$`` or ``!`` that starts a well-formed address (``line_prefix`` in
``notes``), and one with something after its checksum past a blank, a comma, a
semicolon or a bar (a receive time written after it) to its checksum (``line_suffix``);
the fixes still time it. NULs and a Ctrl-Z at a line's ends are no part
of it; sentences run together on one line (a line end lost) are split after each
checksum a sentence's address follows (``sentences_run_together``); a sentence cut
over two lines is joined when the two together pass its checksum (``lines_joined``).
VHW or VBW from two talkers or more, each a tenth of them or more, is noted
``water_talkers II+VW`` (two logs on one port: both are kept, and calibration takes
them as one log). Time comes from
the fixes: the UTC date and time of RMC, else ZDA, else a time of day (GGA's, an
RMC's without its date, or a valid GLL's while no fix of another kind has come: a GNSS
sending GLL and VTG alone) with a date
given by ``--date`` (or learnt from an earlier RMC/ZDA of the log; in a log with no
dated fix at all, the date its file's name holds, else the day the file was last
written, noted ``date_from_file_name`` or ``date_from_file_time``); a time of day
:data:`DAY_ROLLOVER_S` or more before the last fix is the next day's (midnight passed).
A fix whose time does not increase is no
time source, nor is one outside :data:`YEARS`, unless fixes going back follow one
another (:data:`emlogd.offline.importnmea.RESET_FIXES` of them: a receiver reset, a
date not advancing at midnight): they are then a new time base, shifted to follow the
one before — by whole days when the jump back is one, the sentences between then
kept; else to come a fix interval after its last fix, the sentences between counted
``time_reset`` (noted ``time_base_reset``); a fix jumping forward back onto an earlier
base takes that base's shift again (``time_base_returned``). An RMC whose course field is empty takes the bearing between the positions of the
fixes before and after it when their spacing and its speed allow it
(:mod:`emlogd.offline.importcourse`). The sentences between two fixes are
spread evenly, in their order, over the interval up to the next fix. Sentences before the first fix and after the last
have no time and are counted (``before_first_fix``, ``after_last_fix``): times are
never extrapolated past the last fix. Two fixes more than :data:`MAX_FIX_GAP_S` apart
(a logger paused, files joined) leave the sentences between them without a time
(``fix_gap``), as does a stretch of more than :data:`MAX_PENDING_LINES` sentences
without a fix.

**CSV/TSV exports** of navigation software and loggers: a column map (``key=Column``
for ``time``, ``date``, ``stw``, ``heading``, ``heading_mag``, ``sog``, ``cog``,
``lat``, ``lon``, ``set``, ``drift``, ``variation``; a column may be written ``A|B`` — the first
present in the header — and ``Name?`` when it may be absent; speeds in knots unless
written ``Name[mps]``), or a preset chosen by the header (:data:`PRESETS`). The
delimiter (comma, tab, semicolon, bar) and the header line are found in the file:
the header is the first of the first :data:`HEADER_SCAN_LINES` lines that holds the
mapped columns, so a banner before it is passed over (and counted). Column names
match in any case, with spaces or hyphens for underscores (``Boat Speed``), and with a unit after them (``Bsp (kn)``, ``SOG [m/s]``,
``stw_kn``: :data:`emlogd.offline.csvmaps.HEADER_UNITS`; a speed's unit is then the
column's; ``Hdg (rad)``: an angle in radians, ``--map`` ``Name[rad]``); a row of units
under the header (no cell a number or a time) sets the mapped columns' units, and a
unit it gives not known for its column stops the import naming the column
(:func:`emlogd.offline.csvmaps.units_row`); with a delimiter other than the comma, a comma in a number is a decimal
comma. Times are OLE dates (days since 1899-12-30: Excel, Expedition), ISO
8601, epoch seconds or milliseconds, Windows FILETIME ticks, a day-first date and time
or a month-first one with AM/PM (:data:`emlogd.offline.csvmaps.DATE_TIME_PATTERNS`; each
of these told by the first time cell), or a ``strptime`` pattern; with a ``date``
column, a time cell holding a time of day alone is joined to the date with a space
before parsing; without one, to ``--date``, else to the date the file's name holds,
else to the day the file was last written (noted ``date_from_file_name`` or
``date_from_file_time``) (the next day once a time of day comes
:data:`DAY_ROLLOVER_S` or more before the row before: midnight passed). When no row
gives a time, the error quotes the first time cell and asks for ``--time-format`` (for
times of day alone, for the date). Times without a zone are UTC unless ``--utc-offset`` says
the logger kept local time. Positions are decimal degrees,
``ddmm.mmmmN``/``dddmm.mmmmE``, or degrees and minutes (and seconds) with their signs
and a hemisphere letter (``45°40.8145'N``, ``N 45 40.8145``); one without its letter
is no position.
Expedition's own sparse log (a ``!Boat`` line of names, a ``!boat`` line of channel
numbers, rows of ``channel,value`` pairs) is told by its header and read as the rows
of its flat export (:mod:`emlogd.offline.importer_sparse`); its times are OLE dates or
Windows FILETIME ticks.

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

A ``heading_mag`` column (a compass's magnetic heading under a name that says so:
``HdgMag``, ``heading_magnetic``) is the heading when no ``heading`` column is mapped,
read as magnetic; a heading whose name says its reference (``Hdg (°M)``, ``HDG_mag``,
``Heading (°T)``, ``HDG_true``) is read in it, over the preset's, unless
``--heading-ref`` is given; a table with neither writes VHW with the speed alone, counted
``no_heading_column`` in ``notes`` (calibrating against GNSS then needs a heading from
elsewhere); one without a speed or a course over ground column writes no RMC,
counted ``no_sog_cog_column`` (its fixes give no ground velocity: the positions alone
are not differenced into one, and calibrating against GNSS needs one from elsewhere). The variation for a magnetic heading: a ``variation`` column, else ``--variation
DEG``; without either the RMC has none, and calibration takes the IGRF model's at
the fix's position and date (:mod:`emlogd.pipeline.variation`). The import runs the
heading-against-course check of that module on the rows (``heading_check``), so a
magnetic heading imported as true, or a wrong compass, shows at once.
"""

from __future__ import annotations

import csv
import math
from collections import Counter, deque
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, date, datetime, timedelta
from pathlib import Path
from typing import TextIO

from drivers.nmea0183 import encode_rmc, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline import ProgressFn
from emlogd.offline.csvmaps import (
    CSV_KEYS,
    EXPEDITION,
    HEADER_SCAN_LINES,
    LIMITS,
    LOGGER_TSV,
    PRESETS,
    TIME_OF_DAY,
    Col,
    HeadingRef,
    Preset,
    UnitsRow,
    candidate_maps,
    cell,
    cell_value,
    find_header,
    guess_time_format,
    line_unknown_units,
    no_header,
    parse_map,
    parse_time,
    reasons,
    units_row,
)
from emlogd.offline.importbase import (
    MAX_LINE_CHARS,
    YEARS,
    CaptureSink,
    ImportFormatError,
    ImportReport,
    bounded_lines,
    count,
    open_text,
    within_years,
)
from emlogd.offline.importer_sparse import SparseLog
from emlogd.offline.importnmea import (
    DAY_ROLLOVER_S,
    MAX_FIX_GAP_S,
    MAX_PENDING_LINES,
    file_day,
    import_nmea,
)
from emlogd.pipeline.sentences import encode_vdr
from emlogd.pipeline.variation import model_variation

__all__ = [
    "CARRY_S",
    "CSV_KEYS",
    "EXPEDITION",
    "LIMITS",
    "LOGGER_TSV",
    "MAX_FIX_GAP_S",
    "MAX_PENDING_LINES",
    "PRESETS",
    "YEARS",
    "HeadingRef",
    "ImportFormatError",
    "ImportReport",
    "Preset",
    "import_csv",
    "import_nmea",
    "parse_map",
]

# ------------------------------------------------------------------ CSV exports

TIME_FORMATS_TOLD = (
    "epoch seconds or milliseconds, OLE days, FILETIME ticks, ISO 8601, day-first dates "
    "with 24-h times "
    "to the second, month-first dates with AM/PM"
)
"""What ``auto`` tells by itself (:func:`emlogd.offline.csvmaps.guess_time_format`), as
the import's error names it."""

CARRY_S = 10.0
"""A group's other cells are taken as last written for at most this long, s."""

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
        """A cell of the group written at ``t`` with a new value."""
        if math.isfinite(self.t_change):
            self.intervals.append(t - self.t_change)
        self.t_change = t

    def repeat_is_sample(self, t: float) -> bool:
        """Whether a repeat at ``t`` comes a full update period after the last sample."""
        if len(self.intervals) < PERIOD_MIN_INTERVALS:
            return False
        period = sorted(self.intervals)[len(self.intervals) // 2]
        return t - self.t_sample >= REPEAT_PERIOD_FRACTION * period


@dataclass
class _CsvRun:
    """One CSV import while its rows are written: how to read them, and what the rows
    before have left (the cells last written, each group's timing, the last time)."""

    sink: CaptureSink
    delim: str
    cols: dict[str, Col]
    fmt: str
    """The time format; ``auto`` until the first time cell tells it."""
    href: HeadingRef
    utc_offset_h: float
    variation_deg: float | None
    carry_s: float
    day: date | None = None
    """The date of times of day without a date column (``--date``; the next day's
    after midnight)."""
    last: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Column key → (time written, value)."""
    groups: dict[str, _Group] = field(
        default_factory=lambda: {name: _Group(keys) for name, keys in GROUPS.items()}
    )
    day_note: str = ""
    """The note counted when a time of day first takes :attr:`day` not given by
    ``--date`` (the file's: ``date_from_file_name`` or ``date_from_file_time``)."""
    t_prev: float = -math.inf
    bad_stamp: str = ""
    """The first time cell that could not be read (quoted when no row gives a time)."""

    @property
    def report(self) -> ImportReport:
        """The import's report."""
        return self.sink.report

    @property
    def value_cols(self) -> list[Col]:
        """The mapped columns that hold values (not the time or the date)."""
        return [c for k, c in self.cols.items() if k not in ("time", "date")]

    def held(self, key: str, t: float) -> float | None:
        """The value last written in ``key``'s column, when written within ``carry_s``."""
        v = self.last.get(key)
        return v[1] if v is not None and t - v[0] <= self.carry_s else None


def import_csv(
    path: str | Path,
    out: str | Path,
    mapping: Mapping[str, str] | None = None,
    *,
    preset: str | None = None,
    time_format: str | None = None,
    heading_ref: HeadingRef | None = None,
    utc_offset_h: float | None = None,
    day: date | None = None,
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
        heading_ref: the heading's reference (default: as the column's name says it, else
            the preset's, else true).
        utc_offset_h: the logger's clock minus UTC, hours (times are UTC without it).
        day: the date of times of day alone when no date column is mapped.
        variation_deg: magnetic variation, east positive, when no column gives one.
        port: the capture's port name.
        carry_s: how long a group's other cells are taken as last written, s.
        progress: called at the end.

    Raises:
        ImportFormatError: an unreadable file, a map without time/stw, a mapped column
            missing from the header, no row with a time and a speed.
    """
    candidates = candidate_maps(mapping, preset)
    report = ImportReport([str(path)], str(out), port)
    with open_text(path) as f:
        head = _read_head(f, path, report.skipped)
        sparse = SparseLog.detect(head)
        found = find_header([sparse.header] if sparse else head, candidates)
        if found is None:
            raise ImportFormatError(no_header(path, head, candidates))
        h_index, delim, chosen, cols = found
        fmt = time_format or (chosen.time_format if chosen is not None else "auto")
        href = heading_ref or _named_ref(cols) or (chosen.heading_ref if chosen else "true")
        units = None if sparse else _units_row(head, h_index, delim, cols, path)
        if units is not None:
            report.notes["units_row"] += 1
            cols = units.cols
            if units.magnetic and heading_ref is None and "heading" in units.magnetic:
                href = "magnetic"
            found = (h_index, delim, chosen, cols)
        href = _magnetic_column(cols, href, heading_ref is not None)
        _describe(report, found, href, utc_offset_h is not None, variation_deg is not None)
        for name in [] if sparse else line_unknown_units(head[h_index], delim):
            report.notes[f"unit_not_known {name}"] += 1  # a column left out, said
        sink = CaptureSink(out, port, f"emlogd import --format csv: {path}", report)
        run = _CsvRun(
            sink, delim, cols, fmt, href, utc_offset_h or 0.0, variation_deg, carry_s, day
        )
        if day is None and "date" not in cols and (found_day := file_day(path)) is not None:
            run.day, run.day_note = found_day  # for times of day alone, noted when used
        try:
            if sparse is not None:
                report.notes["expedition_sparse_log"] += 1
                rows = sparse.dense(_chain(head[sparse.first_row :], f, report.skipped), report)
            else:
                first = h_index + (2 if units is not None else 1)
                rows = _chain(head[first:], f, report.skipped)
            _csv_rows(rows, run)
            _finish_csv(path, run)
        except BaseException:
            sink.abort()
            raise
        sink.commit()
    if progress is not None:
        progress(f"import {Path(path).name}", 1.0)
    return report


def _read_head(f: TextIO, path: str | Path, skipped: Counter[str]) -> list[str]:
    """The first :data:`HEADER_SCAN_LINES` lines, where the header must be (one too long
    counted in ``skipped``).

    Raises:
        ImportFormatError: the file is empty, or each of its lines too long for a row.
    """
    head: list[str] = []
    for line in bounded_lines(f, skipped):
        head.append(line.rstrip("\r\n"))
        if len(head) >= HEADER_SCAN_LINES:
            break
    if not head and skipped["too_long"]:
        raise ImportFormatError(
            f"{path}: no header: its {skipped['too_long']} line(s) each over "
            f"{MAX_LINE_CHARS} characters (a lost line ending, or not a CSV export)"
        )
    if not head:
        cut = " (a gzip stream cut short or corrupt before its first line)"
        raise ImportFormatError(f"{path}: empty file{cut if skipped['truncated'] else ''}")
    return head


def _units_row(
    head: list[str], h_index: int, delim: str, cols: dict[str, Col], path: str | Path
) -> UnitsRow | None:
    """The line under the header read as a row of units (:func:`units_row`), or None."""
    if h_index + 1 >= len(head):
        return None
    row = next(csv.reader([head[h_index + 1]], delimiter=delim), [])
    return units_row(row, next(csv.reader([head[h_index]], delimiter=delim)), cols, path)


def _named_ref(cols: dict[str, Col]) -> HeadingRef | None:
    """The heading's reference as its column's name says it (``Hdg (°M)``), else None."""
    for key in ("heading", "heading_mag"):
        if key in cols:
            return cols[key].ref
    return None


def _magnetic_column(cols: dict[str, Col], href: HeadingRef, href_given: bool) -> HeadingRef:
    """A ``heading_mag`` column read as the heading when no ``heading`` column is
    mapped (its reference magnetic unless ``--heading-ref`` says otherwise); dropped
    beside one. The heading's reference."""
    mag = cols.pop("heading_mag", None)
    if mag is None or "heading" in cols:
        return href
    cols["heading"] = Col("heading", mag.index, mag.factor)
    return href if href_given else "magnetic"


def _describe(
    report: ImportReport,
    found: tuple[int, str, Preset | None, dict[str, Col]],
    href: HeadingRef,
    offset_given: bool,
    variation_given: bool,
) -> None:
    """What the report says of the header found: the preset, the banner lines before it,
    the heading's reference, a local clock taken as UTC, where a magnetic heading's
    variation comes from."""
    h_index, _, chosen, cols = found
    report.preset = chosen.name if chosen is not None else None
    count(report.notes, "banner_lines", h_index)
    report.heading_ref = href if "heading" in cols else None
    if "heading" not in cols:
        report.notes["no_heading_column"] += 1
    if "sog" not in cols or "cog" not in cols:
        report.notes["no_sog_cog_column"] += 1
    if chosen is not None and chosen.local_time and not offset_given:
        report.notes["local_time_taken_as_utc"] += 1
    if "heading" in cols and href == "magnetic":
        if "variation" in cols:
            report.variation = "column"
        elif variation_given:
            report.variation = "option"
        else:
            report.variation = "model" if "lat" in cols and "lon" in cols else "none"


def _finish_csv(path: str | Path, run: _CsvRun) -> None:
    """The heading check's verdict into the report.

    Raises:
        ImportFormatError: no row gave a sentence.
    """
    report = run.report
    if run.sink.check.n:
        report.heading_check = run.sink.check.as_dict()
    if report.written == 0:
        why = ""
        if report.skipped["bad_time"] and TIME_OF_DAY.fullmatch(run.bad_stamp):
            why = (
                f"; the time cells hold a time of day alone (the first {run.bad_stamp!r}) "
                "and no date column is mapped: a time needs its date (--map date=COLUMN, "
                "or --date YYYY-MM-DD)"
            )
        elif report.skipped["bad_time"] and run.bad_stamp:
            why = (
                f"; the time cells (the first {run.bad_stamp!r}) are in no format told by "
                f"itself ({TIME_FORMATS_TOLD}): give --time-format PATTERN "
                "(a strptime pattern, e.g. '%m/%d/%Y %H:%M:%S')"
            )
        raise ImportFormatError(
            f"{path}: no row with a time and a speed through the water "
            f"(skipped: {reasons(report.skipped) or 'none'}; "
            f"cells: {reasons(report.cells) or 'none'}){why}"
        )


def _chain(first: list[str], rest: TextIO, skipped: Counter[str]) -> Iterator[str]:
    yield from first
    for line in bounded_lines(rest, skipped):
        yield line.rstrip("\r\n")


def _csv_rows(lines: Iterator[str], run: _CsvRun) -> None:
    """Turn the data rows into sentences (module docstring)."""
    report = run.report
    for row in _rows(csv.reader(lines, delimiter=run.delim), report):
        if not row or not any(c.strip() for c in row):
            continue
        report.lines += 1
        t = _row_time(row, run)
        if t is None:
            continue
        new, bad = _row_cells(row, t, run)
        if not _row_sentences(t, new, run):
            reason = "incomplete" if new else "bad_cell" if bad else "no_new_value"
            report.skipped[reason] += 1


def _rows(reader: Iterator[list[str]], report: ImportReport) -> Iterator[list[str]]:
    """The rows of a CSV reader; one it cannot parse (a field past its limit: a quote
    left open) is counted ``csv_error`` and skipped, the reader going on with the next."""
    while True:
        try:
            yield next(reader)
        except StopIteration:
            return
        except csv.Error:
            report.lines += 1
            report.skipped["csv_error"] += 1


def _row_time(row: list[str], run: _CsvRun) -> float | None:
    """The row's time, epoch seconds; None (counted by reason) when it has none, an
    unreadable one, one outside :data:`YEARS` or one before the row before."""
    stamp = cell(row, run.cols["time"].index)
    date_col = run.cols.get("date")
    given = run.day is not None and date_col is None and TIME_OF_DAY.fullmatch(stamp)
    if date_col is not None and TIME_OF_DAY.fullmatch(stamp):
        day = cell(row, date_col.index)
        stamp = f"{day} {stamp}" if day else ""
    elif given and run.day is not None:
        stamp = f"{run.day.isoformat()} {stamp}"
        if run.day_note:
            run.report.notes[run.day_note] += 1
            run.day_note = ""
    t = _stamp_time(stamp, run) if stamp else math.nan
    if given and run.day is not None and run.t_prev - t >= DAY_ROLLOVER_S:
        run.day += timedelta(days=1)  # midnight passed
        t += 86_400.0
    if not stamp:
        reason = "no_time"
    elif not math.isfinite(t):
        reason = "bad_time"
        run.bad_stamp = run.bad_stamp or stamp
    elif not within_years(t):
        reason = "time_out_of_range"
    elif t < run.t_prev:
        reason = "time_going_back"
    else:
        run.t_prev = t
        return t
    run.report.skipped[reason] += 1
    return None


def _stamp_time(stamp: str, run: _CsvRun) -> float:
    """A time cell (or date + space + time) in epoch seconds, UTC; nan when unreadable.
    The first readable cell of an ``auto`` import tells the format."""
    if run.fmt in ("ole", "epoch", "epoch_ms", "auto") and run.delim != ",":
        stamp = stamp.replace(",", ".")  # a decimal comma
    if run.fmt == "auto":
        run.fmt = guess_time_format(stamp) or "auto"
    if run.fmt == "auto":
        return math.nan
    try:
        return parse_time(stamp, run.fmt) - run.utc_offset_h * 3600.0
    except (ValueError, OverflowError, OSError):
        return math.nan


def _row_cells(row: list[str], t: float, run: _CsvRun) -> tuple[set[str], bool]:
    """Read the row's value cells into ``run.last``: (the keys written with a new value,
    whether a cell was bad)."""
    new: set[str] = set()
    bad = False
    for c in run.value_cols:
        text = cell(row, c.index)
        if not text:
            continue
        x = cell_value(text, c, run.report)
        if x is None:
            bad = True
            continue
        held = run.last.get(c.key)
        if held is None or held[1] != x:
            new.add(c.key)
        run.last[c.key] = (t, x)
    return new, bad


def _row_sentences(t: float, new: set[str], run: _CsvRun) -> bool:
    """Write the samples the row's new cells make; whether any was written."""
    wrote = False
    for group, g in run.groups.items():
        if not _is_sample(group, g, t, new, run):
            continue
        line = _SENTENCES[group](t, run)
        if line is not None:
            run.sink.write(t, line)
            g.t_sample = t
            wrote = True
    return wrote


def _is_sample(group: str, g: _Group, t: float, new: set[str], run: _CsvRun) -> bool:
    """Whether the row makes a sample of ``group``: a cell of it written in this row with
    a new value, or a repeat a full update period after its last sample (counted)."""
    if not any(k in run.last and run.last[k][0] == t for k in g.keys):
        return False  # nothing of the group written in this row
    if new.intersection(g.keys):
        g.changed(t)
        return True
    kept = g.repeat_is_sample(t)
    run.report.notes[f"{group}_repeat_kept" if kept else f"{group}_repeat"] += 1
    return kept


def _fix_sentence(t: float, run: _CsvRun) -> str | None:
    """RMC: speed and course over ground, the position when mapped, the variation when
    known; the fix is fed to the heading check."""
    sog, cog = run.held("sog", t), run.held("cog", t)
    if sog is None or cog is None:
        return None
    var = run.held("variation", t)
    line = encode_rmc(
        datetime.fromtimestamp(t, UTC),
        sog,
        cog,
        lat_deg=run.held("lat", t),
        lon_deg=run.held("lon", t),
        variation_deg=var if var is not None else run.variation_deg,
        talker="GP",
    )
    _check(t, sog, cog, run)
    return line


def _water_sentence(t: float, run: _CsvRun) -> str | None:
    """VHW: speed through the water and the heading, true or magnetic."""
    stw = run.held("stw", t)
    if stw is None:
        return None
    hdg = run.held("heading", t)
    return encode_vhw(
        stw,
        heading_true_deg=hdg if run.href == "true" else None,
        heading_mag_deg=hdg if run.href == "magnetic" else None,
        talker="II",
    )


def _current_sentence(t: float, run: _CsvRun) -> str | None:
    """VDR: the current's set (towards) and drift in knots."""
    set_deg, drift = run.held("set", t), run.held("drift", t)
    if set_deg is None or drift is None:
        return None
    return encode_vdr(set_deg, None, drift / KNOT_MPS, "II")


_SENTENCES: dict[str, Callable[[float, _CsvRun], str | None]] = {
    "fix": _fix_sentence,
    "water": _water_sentence,
    "current": _current_sentence,
}
"""The sentence each sample group (:data:`GROUPS`) becomes."""


def _check(t: float, sog: float, cog: float, run: _CsvRun) -> None:
    """Feed a fix and the heading at its row to the heading-against-course check (a
    magnetic heading made true with the column's, the option's or the model's variation)."""
    hdg = run.held("heading", t)
    if hdg is None:
        return
    if run.href == "magnetic":
        var = run.held("variation", t)
        var = var if var is not None else run.variation_deg
        lat, lon = run.held("lat", t), run.held("lon", t)
        if var is None and lat is not None and lon is not None:
            var = model_variation(lat, lon, t)
        if var is None:
            return
        hdg = (hdg + var) % 360.0
    run.sink.check.add(t, hdg, sog, cog)
