"""What both imports share (:mod:`emlogd.offline.importer`): the report, the error, the
capture being written, the input opened through gzip, the years a time may name, and
the check of an NMEA log's lines (:class:`SentenceCheck`), its lines read with a bound
(:func:`bounded_lines`)."""

from __future__ import annotations

import contextlib
import gzip
import io
import math
import re
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal, TextIO

from drivers.errors import EmlogdError, FrameError
from drivers.framing import nmea_checksum, split_nmea
from drivers.io.capture import CaptureWriter
from emlogd.fileio import part_path, replaceable
from emlogd.pipeline.variation import CourseOffsetCheck

ImportFormat = Literal["nmea", "csv", "json", "n2k"]
"""What an import reads: NMEA 0183 logs (:mod:`emlogd.offline.importnmea`), a CSV export
(:mod:`emlogd.offline.importer`), Signal K or canboat analyzer JSON and canboat's plain
text of NMEA 2000 (:mod:`emlogd.offline.importjson`)."""

YEARS = (1980, 2100)
"""A row or fix time outside these years is a misread time (GPS-era logs only)."""
_YEAR_LO = datetime(YEARS[0], 1, 1, tzinfo=UTC).timestamp()
_YEAR_HI = datetime(YEARS[1], 1, 1, tzinfo=UTC).timestamp()


MAX_LINE_CHARS = 1 << 16
"""A log line or CSV row longer than this many characters is skipped (counted
``too_long``), read in pieces of this size: a file of one huge line (a binary dump, a
lost newline) costs no more memory than this, and the CSV reader never meets a field
past its own limit."""


def bounded_lines(f: TextIO, skipped: Counter[str]) -> Iterator[str]:
    """The lines of ``f`` (each with its line ending) up to :data:`MAX_LINE_CHARS`
    characters; a longer one is read to its end in pieces, never held, and counted
    ``too_long`` in ``skipped``. A gzip stream cut short ends the lines, counted
    ``truncated``."""
    try:
        yield from _bounded_lines(f, skipped)
    except (EOFError, gzip.BadGzipFile, zlib.error):
        skipped["truncated"] += 1


def _bounded_lines(f: TextIO, skipped: Counter[str]) -> Iterator[str]:
    while line := f.readline(MAX_LINE_CHARS):
        if len(line) < MAX_LINE_CHARS or line.endswith("\n"):
            yield line
            continue
        rest = f.readline(MAX_LINE_CHARS)
        if rest.strip("\r\n") == "":  # the line ends right at the bound
            yield line + rest
            continue
        while rest and not rest.endswith("\n"):
            rest = f.readline(MAX_LINE_CHARS)
        skipped["too_long"] += 1


def within_years(t: float) -> bool:
    """Whether epoch seconds ``t`` fall within :data:`YEARS`."""
    return _YEAR_LO <= t < _YEAR_HI


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
        heading_ref: the CSV heading's reference (None without a heading column).
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


class CaptureSink:
    """The capture being written: a temporary file renamed into place on success."""

    def __init__(self, out: str | Path, port: str, comment: str, report: ImportReport) -> None:
        self.path = Path(out)
        # a device or a pipe (--out /dev/stdout) is written into, never renamed over
        self.tmp = part_path(self.path) if replaceable(self.path) else self.path
        self.port = port
        self.report = report
        self.check = CourseOffsetCheck()
        self.water_talkers: Counter[str] = Counter()  # VHW/VBW written, by talker
        try:
            self.w = CaptureWriter(self.tmp, {port: "nmea0183"})
            self.w.comment(comment.encode("ascii", "replace").decode("ascii"))
        except OSError as exc:
            raise ImportFormatError(f"{out}: cannot write: {exc.strerror or exc}") from None

    def write(self, t: float, line: str) -> None:
        self.w.write_line(t, self.port, line.encode("ascii"))
        r = self.report
        r.written += 1
        kind = sentence_kind(line)
        r.sentences[kind] += 1
        if kind in ("VHW", "VBW"):
            self.water_talkers[line[1:3]] += 1
        if r.written == 1:
            r.t_start = t
        r.t_end = t

    def commit(self) -> None:
        self.w.close()
        if self.tmp != self.path:
            self.tmp.replace(self.path)

    def abort(self) -> None:
        self.w.close()
        if self.tmp != self.path:
            self.tmp.unlink(missing_ok=True)


def count(counter: Counter[str], key: str, n: int) -> None:
    """Add ``n`` to a counter's ``key`` (no zero entries)."""
    if n:
        counter[key] += n


def sentence_kind(line: str) -> str:
    """The sentence type (``RMC``, ``VHW``; a proprietary one by its address)."""
    address = line[1:].split(",", 1)[0]
    return address if address.startswith("P") else address[2:]


UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
"""The byte-order marks of UTF-16 (little- and big-endian): a file that starts with one
is read as UTF-16 (a spreadsheet saved as "Unicode text")."""


SNIFF_BYTES = 1 << 16
"""The first this many bytes of a file tell its encoding (:func:`open_text`)."""

LEGACY_ENCODING = "cp1252"
"""A file whose first bytes are not UTF-8 is read in Windows' Western code page (an
export written on Windows: ``Hdg (°T)``, ``Zeit``, ``Geschw.`` with its 8-bit letters),
which decodes Latin-1's letters too."""


def open_text(path: str | Path) -> TextIO:
    """A text stream of a file, through gzip when it starts with gzip's magic; UTF-16
    when it starts with that one's byte-order mark, else UTF-8 (its byte-order mark
    dropped) when its first :data:`SNIFF_BYTES` decode as UTF-8, else
    :data:`LEGACY_ENCODING`."""
    try:
        raw: io.BufferedReader | gzip.GzipFile = io.BufferedReader(
            io.FileIO(path, "rb"), SNIFF_BYTES
        )
        head = raw.peek(SNIFF_BYTES)[:SNIFF_BYTES]
        if head[:2] == b"\x1f\x8b":
            raw.close()
            raw = gzip.GzipFile(path, "rb")
            head = _gzip_head(path)
    except OSError as exc:
        raise ImportFormatError(
            f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}"
        ) from None
    if head[:2] in UTF16_BOMS:
        return io.TextIOWrapper(raw, encoding="utf-16", errors="replace")
    return io.TextIOWrapper(raw, encoding=_encoding(head), errors="replace")


def _gzip_head(path: str | Path) -> bytes:
    """A gzip file's first :data:`SNIFF_BYTES` decompressed (those there are when it
    is cut short: reading it says so, counted ``truncated``)."""
    with gzip.GzipFile(path, "rb") as gz:
        out = b""
        with contextlib.suppress(EOFError, zlib.error, gzip.BadGzipFile):
            while len(out) < SNIFF_BYTES and (chunk := gz.read(SNIFF_BYTES - len(out))):
                out += chunk
    return out


def _encoding(head: bytes) -> str:
    """UTF-8 (``utf-8-sig``) when ``head`` decodes as UTF-8 but for a character cut at
    its end, else :data:`LEGACY_ENCODING`."""
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 3 or exc.reason != "unexpected end of data":
            return LEGACY_ENCODING
    return "utf-8-sig"


def not_a_sentence(text: str) -> str | None:
    """Why a log line is no complete NMEA sentence with a valid checksum (checked as the
    decoders do), or None when it is one."""
    if not text:
        return "empty"
    if text[0] not in "$!" or not text.isascii():
        return "not_nmea"
    try:
        split_nmea(text.encode("ascii"), required=True)
    except FrameError as exc:
        return exc.reason
    return None


class SentenceCheck:
    """Whether the log is written without checksums: a line without one is taken (its
    checksum added) while the log's sentences so far are more often without than with
    one; in a log with checksums it is a cut line (``missing_checksum``)."""

    def __init__(self, report: ImportReport) -> None:
        self.report = report
        self.with_ = 0
        self.without = 0

    def line(self, text: str) -> tuple[str | None, str | None]:
        """(the sentence to write, or None; why the line is skipped, or None). A line
        with something before its sentence (a logger's receive time, a channel tag) is
        read from its first ``$`` or ``!`` (counted as ``line_prefix``); one with
        something after its checksum (a receive time written after the sentence) is read
        to its checksum (``line_suffix``)."""
        start = _sentence_start(text)
        if start > 0:
            self.report.notes["line_prefix"] += 1
            text = text[start:]
        reason = not_a_sentence(text)
        end = SUFFIX_AFTER.search(text) if reason is not None else None
        if end is not None and not_a_sentence(text[: end.start()]) is None:
            self.report.notes["line_suffix"] += 1
            text, reason = text[: end.start()], None
        if reason is None:
            self.with_ += 1
            return text, None
        if reason != "missing_checksum" or not well_formed(text):
            return None, reason
        self.without += 1
        if self.without <= self.with_:
            return None, reason
        self.report.notes["checksum_added"] += 1
        body = text[1:]
        return f"{text[0]}{body}*{nmea_checksum(body.encode('ascii')):02X}", None


SUFFIX_AFTER = re.compile(r"(?<=\*[0-9A-Fa-f]{2})[\s,;|].*\Z", re.DOTALL)
"""What follows a sentence's checksum after a separator (a space, a tab, a comma, a
semicolon, a bar): a logger's receive time written after the sentence."""


def _sentence_start(text: str) -> int:
    """Where a line's sentence starts: 0 when it starts the line, the first ``$`` or
    ``!`` followed by a well-formed address when something comes before it, else 0."""
    if text[:1] in ("$", "!"):
        return 0
    for i, ch in enumerate(text):
        if ch in "$!" and well_formed(text[i:]):
            return i
    return 0


def well_formed(text: str) -> bool:
    """A sentence's address (``$`` or ``!`` and five letters or digits) and a comma."""
    return len(text) > 7 and text[1:6].isalnum() and text[6] == ","


FOREIGN_FORMATS: tuple[tuple[re.Pattern[str], str], ...] = (
    (
        re.compile(r"\(\d+\.\d+\)\s+\w+\s+[0-9A-Fa-f]{3,8}#|\s*\w*can\d\s+[0-9A-Fa-f]{8}\s+\[\d\]"),
        "an NMEA 2000 CAN dump (candump)",
    ),
    (
        re.compile(r"(\d+;A;)?[\d\-T:. Z]{10,30},\d,\d{5,6},\d{1,3},\d{1,3},\d{1,3},"),
        "NMEA 2000 in Actisense/canboat text (time, priority, PGN, source...; import it "
        "with --format n2k)",
    ),
    (
        re.compile(r"[^{]*\{.*\"(updates|context|path)\""),
        "Signal K JSON (import it with --format json)",
    ),
    (
        re.compile(r"[^{]*\{.*\"pgn\""),
        "NMEA 2000 as canboat analyzer JSON (import it with --format json)",
    ),
    (re.compile(r"[^,;\t|$!]*([,;\t|][^,;\t|]*){3,}"), "a table (import it with --format csv)"),
    (re.compile(r"[$!][A-Z0-9]{5},"), "an NMEA 0183 log (import it with --format nmea)"),
)
"""Formats a file given to the wrong import may be, told by its first line: NMEA 2000
(CAN dumps, Actisense/canboat text), Signal K, canboat JSON, a table, NMEA 0183;
``emlogd import`` reads NMEA 0183, tables and JSON lines (``--format json``)."""

BINARY_FRACTION = 0.25
"""A first line with more than this fraction of control or non-ASCII characters is
binary (an NMEA 2000 recorder's .DAT, Actisense's .EBL)."""


def what_it_looks_like(line: str) -> str:
    """What a file whose first line is ``line`` seems to be, in words (empty when not
    told): see :data:`FOREIGN_FORMATS`."""
    text = line.strip("\r\n")
    odd = sum(1 for c in text if not c.isascii() or (not c.isprintable() and c != "\t"))
    if text and odd > BINARY_FRACTION * len(text):
        return "binary data, not text (an NMEA 2000 recorder's or Actisense's file?)"
    for pattern, what in FOREIGN_FORMATS:
        if pattern.match(text):
            return what
    return ""
