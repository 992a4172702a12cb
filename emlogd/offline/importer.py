"""``emlogd import``: the logs people already have, turned into captures.

Two formats, each counting and reporting what it skipped (a line or row is never
silently dropped):

- **NMEA 0183 logs without receive times** (a chart plotter's or a voyage data
  recorder's file): every line must be a complete sentence with a valid checksum
  (checked as the decoders do); the rest is counted by reason. Time comes from the
  fixes: the UTC date and time of RMC, else ZDA, else GGA's time of day with a date
  given by ``--date`` (or learnt from an earlier RMC/ZDA of the log). A fix whose time
  does not increase is not a time source. The sentences between two fixes are spread
  evenly, in their order, over the interval that ends at the next fix; those after
  the last fix continue at the previous interval's rate; those before the first fix
  have no time and are counted.
- **CSV exports** of navigation software: a column map
  (``time=Utc,stw=Bsp,heading=Hdg,sog=Sog,cog=Cog``; optional ``lat``, ``lon``,
  ``set``, ``drift``, ``variation``), a time format (``ole``: days since 1899-12-30,
  ``iso``, ``epoch`` seconds), knots and degrees unless a column is written
  ``Name[mps]``, and whether the heading is true or magnetic. Each row with a time
  becomes NMEA sentences on one port: VHW (speed through the water and the heading),
  RMC (speed and course over ground, and the position when mapped), VDR (the logging
  software's own current estimate, when mapped: set towards, drift in knots).
  Sparse rows (Expedition writes a column only when it changes) carry the last value
  of each column forward for at most ``carry_s`` seconds.

The output is a capture v1 file with one port (default ``nmea``, protocol
``nmea0183``), sorted by time.
"""

from __future__ import annotations

import csv
import gzip
import math
from collections import Counter
from collections.abc import Iterable, Sequence
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

TimeFormat = Literal["ole", "iso", "epoch"]
HeadingRef = Literal["true", "magnetic"]

OLE_EPOCH = datetime(1899, 12, 30, tzinfo=UTC)
"""Day 0 of OLE automation dates (Excel, Expedition)."""

CARRY_S = 10.0
"""A sparse CSV column's last value is carried forward at most this long, s."""

EXPEDITION: dict[str, str] = {
    "time": "Utc",
    "stw": "Bsp",
    "heading": "Hdg",
    "sog": "Sog",
    "cog": "Cog",
    "lat": "Lat",
    "lon": "Lon",
    "set": "iSet",
    "drift": "iDrift",
}
"""Expedition's column names (its ``Hdg`` is a true heading; times are OLE dates)."""

CSV_KEYS = ("time", "stw", "heading", "sog", "cog", "lat", "lon", "set", "drift", "variation")


class ImportFormatError(EmlogdError):
    """An import cannot run (a bad map, no time source, an unreadable file)."""


@dataclass
class ImportReport:
    """What an import did.

    Attributes:
        files: the input files.
        out: the capture written.
        port: its port name.
        lines: input lines (NMEA) or rows (CSV) read.
        written: sentences written.
        skipped: lines or rows not used, by reason.
        notes: what was met but did not cost a line (a fix whose time does not
            increase is kept as a sentence but not used as a time source).
        sentences: sentences written, by type.
        t_start: first record time, s since the epoch (nan when none).
        t_end: last record time, s.
    """

    files: list[str]
    out: str
    port: str
    lines: int = 0
    written: int = 0
    skipped: Counter[str] = field(default_factory=Counter)
    notes: Counter[str] = field(default_factory=Counter)
    sentences: Counter[str] = field(default_factory=Counter)
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
            "notes": dict(sorted(self.notes.items())),
            "sentences": dict(sorted(self.sentences.items())),
            "t_start": None if math.isnan(self.t_start) else self.t_start,
            "t_end": None if math.isnan(self.t_end) else self.t_end,
            "span_s": None if math.isnan(self.t_start) else round(self.t_end - self.t_start, 3),
        }


def _write(out: str | Path, port: str, records: list[tuple[float, str]], comment: str) -> None:
    """Write sorted records as a capture (``.gz`` names are gzip-compressed)."""
    records.sort(key=lambda r: r[0])
    with CaptureWriter(out, {port: "nmea0183"}) as w:
        w.comment(comment)
        for t, line in records:
            w.write_line(t, port, line.encode("ascii"))


# ------------------------------------------------------------------ NMEA logs


def _fix_time(rec: NmeaRecord | Rejected, day: date | None) -> tuple[float | None, date | None]:
    """(epoch seconds of a fix, the date it implies) for an RMC, ZDA or GGA record."""
    if isinstance(rec, Rmc | Zda) and rec.time_utc is not None:
        return rec.time_utc.timestamp(), rec.time_utc.date()
    if isinstance(rec, Gga) and rec.time_of_day_s is not None and day is not None:
        base = datetime(day.year, day.month, day.day, tzinfo=UTC)
        return (base + timedelta(seconds=rec.time_of_day_s)).timestamp(), day
    return None, day


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
    lines: list[tuple[str, float | None]] = []
    current_day = day
    for i, path in enumerate(paths):
        for raw in _read_lines(path):
            report.lines += 1
            text = raw.strip()
            if not text:
                report.skipped["empty"] += 1
                continue
            if text[0] not in "$!":
                report.skipped["not_nmea"] += 1
                continue
            try:
                split_nmea(text.encode("ascii", "replace"), required=True)
            except FrameError as exc:
                report.skipped[exc.reason] += 1
                continue
            fix: float | None = None
            try:
                decoded = decoder.decode_all((text + "\r\n").encode("ascii", "replace"))
            except FrameError:
                decoded = []  # a sentence the decoders do not parse is still kept
            for rec in decoded:
                fix, current_day = _fix_time(rec, current_day)
            lines.append((text, fix))
        if progress is not None:
            progress(f"import {Path(path).name}", (i + 1) / len(paths))
    stamped = _spread(lines, report)
    if not stamped:
        raise ImportFormatError(
            "no sentence could be given a time: the log needs RMC or ZDA fixes "
            "(or GGA with --date YYYY-MM-DD)"
        )
    for _, line in stamped:
        report.sentences[_kind(line)] += 1
    report.written = len(stamped)
    report.t_start, report.t_end = stamped[0][0], stamped[-1][0]
    _write(out, port, stamped, f"emlogd import --format nmea: {', '.join(report.files)}")
    return report


def _read_lines(path: str | Path) -> Iterable[str]:
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ImportFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    return raw.decode("ascii", "replace").splitlines()


def _kind(line: str) -> str:
    """The sentence type (``RMC``, ``VHW``; a proprietary one by its address)."""
    address = line[1:].split(",", 1)[0]
    return address if address.startswith("P") else address[2:]


def _spread(lines: list[tuple[str, float | None]], report: ImportReport) -> list[tuple[float, str]]:
    """Give every sentence a time from the fixes around it (module docstring)."""
    fixes: list[tuple[int, float]] = []
    for i, (_, t) in enumerate(lines):
        if t is None:
            continue
        if fixes and t <= fixes[-1][1]:
            report.notes["fix_time_not_increasing"] += 1
            continue
        fixes.append((i, t))
    if not fixes:
        report.skipped["no_time"] += len(lines)
        return []
    report.skipped["before_first_fix"] += fixes[0][0]
    out: list[tuple[float, str]] = []
    step = 1.0  # a lone fix: one sentence per second after it
    for k, (i, t_fix) in enumerate(fixes):
        if k + 1 < len(fixes):
            end, t_next = fixes[k + 1]
            step = (t_next - t_fix) / (end - i)
        else:
            end = len(lines)  # after the last fix: the previous interval's rate
        for j in range(i, end):
            out.append((t_fix + step * (j - i), lines[j][0]))
    return out


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


def _column(spec: str) -> tuple[str, float]:
    """``Bsp`` or ``Bsp[mps]`` → (name, factor to m/s); degrees have factor 1."""
    if spec.endswith("[mps]"):
        return spec[:-5], 1.0
    if spec.endswith("[kn]"):
        return spec[:-4], KNOT_MPS
    return spec, KNOT_MPS


def _time(value: str, fmt: TimeFormat) -> float:
    if fmt == "ole":
        return (OLE_EPOCH + timedelta(days=float(value))).timestamp()
    if fmt == "epoch":
        return float(value)
    t = datetime.fromisoformat(value)
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).timestamp()


def import_csv(
    path: str | Path,
    out: str | Path,
    mapping: dict[str, str],
    *,
    time_format: TimeFormat = "ole",
    heading_ref: HeadingRef = "true",
    port: str = "nmea",
    carry_s: float = CARRY_S,
    progress: ProgressFn | None = None,
) -> ImportReport:
    """Import a CSV export (see the module docstring).

    Raises:
        ImportFormatError: an unreadable file, a map without time/stw, a mapped column
            missing from the header.
    """
    for key in ("time", "stw"):
        if key not in mapping:
            raise ImportFormatError(
                f"the column map needs {key}= (has {', '.join(mapping) or 'none'})"
            )
    report = ImportReport([str(path)], str(out), port)
    try:
        f: TextIO = open(path, encoding="utf-8-sig", newline="")  # noqa: SIM115
    except OSError as exc:
        raise ImportFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    records: list[tuple[float, str]] = []
    with f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            raise ImportFormatError(f"{path}: empty file")
        index: dict[str, tuple[int, float]] = {}
        for key, spec in mapping.items():
            name, factor = _column(spec)
            if name not in header:
                raise ImportFormatError(f"{path}: no column {name!r} for {key} (see the header)")
            index[key] = (header.index(name), factor if key in ("stw", "sog", "drift") else 1.0)
        last: dict[str, tuple[float, float]] = {}
        for row in reader:
            report.lines += 1
            t = _row_time(row, index["time"][0], time_format)
            if t is None:
                report.skipped["no_time"] += 1
                continue
            values: dict[str, float] = {}
            bad = False
            for key, (col, factor) in index.items():
                if key == "time":
                    continue
                cell = row[col].strip() if col < len(row) else ""
                if cell:
                    try:
                        x = float(cell)
                    except ValueError:
                        bad = True
                        continue
                    if not math.isfinite(x):
                        bad = True
                        continue
                    last[key] = (t, x * factor)
                held = last.get(key)
                if held is not None and t - held[0] <= carry_s:
                    values[key] = held[1]
            if "stw" not in values:
                report.skipped["bad_number" if bad else "no_speed"] += 1
                continue
            if bad:
                report.notes["bad_cell_ignored"] += 1
            records.extend(_row_sentences(t, values, heading_ref, report))
        if progress is not None:
            progress(f"import {Path(path).name}", 1.0)
    if not records:
        raise ImportFormatError(f"{path}: no row with a time and a speed through the water")
    report.written = len(records)
    report.t_start = min(t for t, _ in records)
    report.t_end = max(t for t, _ in records)
    _write(out, port, records, f"emlogd import --format csv: {path}")
    return report


def _row_time(row: list[str], col: int, fmt: TimeFormat) -> float | None:
    if col >= len(row) or not row[col].strip():
        return None
    try:
        t = _time(row[col].strip(), fmt)
    except (ValueError, OverflowError):
        return None
    return t if math.isfinite(t) else None


def _row_sentences(
    t: float, v: dict[str, float], heading_ref: HeadingRef, report: ImportReport
) -> list[tuple[float, str]]:
    out: list[tuple[float, str]] = []
    stw = v["stw"]
    if stw < 0.0:
        report.skipped["negative_speed"] += 1
        return out
    hdg = v.get("heading")
    true_h = hdg if heading_ref == "true" else None
    mag_h = hdg if heading_ref == "magnetic" else None
    out.append((t, encode_vhw(stw, heading_true_deg=true_h, heading_mag_deg=mag_h, talker="II")))
    report.sentences["VHW"] += 1
    if "sog" in v and "cog" in v:
        stamp = datetime.fromtimestamp(t, UTC)
        out.append(
            (
                t,
                encode_rmc(
                    stamp,
                    v["sog"],
                    v["cog"],
                    lat_deg=v.get("lat"),
                    lon_deg=v.get("lon"),
                    variation_deg=v.get("variation"),
                    talker="GP",
                ),
            )
        )
        report.sentences["RMC"] += 1
    if "set" in v and "drift" in v:
        out.append((t, encode_vdr(v["set"], None, v["drift"] / KNOT_MPS, "II")))
        report.sentences["VDR"] += 1
    return out
