"""``emlogd import --format nmea``: NMEA 0183 logs without receive times, timed from
their own fixes (the rules are in :mod:`emlogd.offline.importer`'s docstring): the
UTC date and time of RMC or ZDA, else a time of day (GGA's, an RMC's without its date,
or GLL's while no other fix has come: its fix then written as a GGA after it too) on
the date ``--date`` gives, else an earlier
fix's date, else the date the file's name holds (``2014-06-27``, ``20140627``), else
the day the file was last written (the last two noted in the report)."""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Sequence
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

from drivers import make_decoder
from drivers.errors import FrameError
from drivers.framing import split_nmea, with_checksum
from drivers.nmea0183 import Gga, Gll, NmeaDecoder, NmeaRecord, Rmc, Zda, parse_gll
from drivers.records import Rejected
from emlogd.offline import ProgressFn
from emlogd.offline.csvmaps import reasons
from emlogd.offline.importbase import (
    CaptureSink,
    ImportFormatError,
    ImportReport,
    SentenceCheck,
    bounded_lines,
    count,
    not_a_sentence,
    open_text,
    sentence_kind,
    what_it_looks_like,
    within_years,
)
from emlogd.offline.importcourse import CourseFill

MAX_FIX_GAP_S = 60.0
"""NMEA: fixes further apart than this leave the sentences between them untimed, s
(spread evenly over a longer gap they could be off by minutes)."""

MAX_PENDING_LINES = 100_000
"""NMEA: sentences waiting for the next fix, at most (constant memory)."""

LINE_PADDING = ' \t\r\n\x00\x1a"'
"""Stripped from both ends of a log line: blanks, line ends, the NULs a logger pads its
buffer with, the DOS end-of-file mark (Ctrl-Z), and the quote closing a CSV cell that
holds the sentence (OpenCPN's data log: ``received_at,protocol,msg_type,source,raw_data``
with the sentence quoted last, read from its ``$`` as any prefixed line)."""


# ------------------------------------------------------------------ NMEA logs


DAY_ROLLOVER_S = 43_200.0
"""NMEA: a GGA time of day this much (or more) before the last fix is the next day's
(midnight passed in a log without a date in its fixes), s."""


def _fix_time(
    rec: NmeaRecord | Gll | Rejected, day: date | None, last: float | None = None
) -> tuple[float | None, date | None]:
    """(epoch seconds of a fix, the date it implies) for an RMC, ZDA, GGA or GLL record;
    a time of day alone (GGA, GLL, or an RMC whose date field is empty) takes ``day``,
    and :data:`DAY_ROLLOVER_S` before the ``last`` fix moves to the next day."""
    if isinstance(rec, Rmc | Zda) and rec.time_utc is not None:
        return rec.time_utc.timestamp(), rec.time_utc.date()
    tod = rec.time_of_day_s if isinstance(rec, Gga | Rmc | Gll) else None
    if tod is not None and day is not None:
        base = datetime(day.year, day.month, day.day, tzinfo=UTC)
        t = (base + timedelta(seconds=tod)).timestamp()
        if last is not None and last - t >= DAY_ROLLOVER_S:
            day = day + timedelta(days=1)
            t += 86_400.0
        return t, day
    return None, day


RESET_FIXES = 3
"""NMEA: a fix time that goes back (a receiver reset, a midnight rolled without the date
advancing) starts a new time base once this many fixes, the first included, follow one
another on it — each later than the one before by at most :data:`MAX_FIX_GAP_S`, none
at or after the last fix of the base before. Until then the fixes going back time
nothing (``fix_time_not_increasing``), and a fix of the base before ends them."""

DAY_S = 86_400.0


class _Spreader:
    """Sentences timed from the fixes around them, written as each next fix arrives.

    A fix time going back is judged (:data:`RESET_FIXES`): a new time base is shifted
    to follow the one before (:meth:`_accept`) — by whole days when it is the base
    before less whole days (a date that did not advance at midnight), else to come one
    fix interval after that base's last fix, the sentences between counted
    ``time_reset``. A fix that then jumps forward onto a base before (the date caught
    up, the receiver's own time back) takes that base's shift again."""

    def __init__(self, out: CaptureSink, report: ImportReport) -> None:
        self.out = out
        self.report = report
        self.fix: float | None = None  # the last fix's time (shifted)
        self.interval = 1.0  # the time between the last two fixes
        self.pending: list[str] = []  # the last fix's sentence, then those after it
        self.overflow = 0
        self.shift = 0.0  # added to the fix times of the present base
        self.shifts: list[float] = []  # the shifts of the bases before
        self.back: list[tuple[str, float | None]] = []  # a new base being judged
        self.back_fixes: list[float] = []

    @property
    def raw_fix(self) -> float | None:
        """The last fix's time as the log wrote it (the day rollover's ``last``)."""
        return None if self.fix is None else self.fix - self.shift

    def add(self, text: str, t_fix: float | None) -> None:
        r = self.report
        if t_fix is not None and not within_years(t_fix):
            r.notes["fix_time_out_of_range"] += 1
            t_fix = None
        if t_fix is not None:
            t_fix = self._onto_base(t_fix)
        if self.back:
            if self._judge(text, t_fix):
                return
        elif t_fix is not None and self.fix is not None and t_fix < self.fix:
            r.notes["fix_time_not_increasing"] += 1
            self.back, self.back_fixes = [(text, t_fix)], [t_fix]
            return
        self._place(text, t_fix)

    def _onto_base(self, t_raw: float) -> float:
        """A fix time on the present base, or on a base before when it jumps forward
        past :data:`MAX_FIX_GAP_S` on the present one and follows the last fix on that
        one (the base taken again)."""
        t = t_raw + self.shift
        if self.fix is None or t - self.fix <= MAX_FIX_GAP_S:
            return t
        for k in range(len(self.shifts) - 1, -1, -1):
            if 0.0 < t_raw + self.shifts[k] - self.fix <= MAX_FIX_GAP_S:
                self.shift = self.shifts[k]
                del self.shifts[k:]
                self.report.notes["time_base_returned"] += 1
                return t_raw + self.shift
        return t

    def _judge(self, text: str, t_fix: float | None) -> bool:
        """Another sentence while a new base is judged: whether it was taken (held, or
        the base accepted); False once the judged fixes are given up (the sentence is
        then placed as any)."""
        assert self.fix is not None
        last = self.back_fixes[-1]
        if t_fix is None and len(self.back) < MAX_PENDING_LINES:
            self.back.append((text, None))
            return True
        if t_fix is not None and last < t_fix < self.fix and t_fix - last <= MAX_FIX_GAP_S:
            self.report.notes["fix_time_not_increasing"] += 1
            self.back.append((text, t_fix))
            self.back_fixes.append(t_fix)
            if len(self.back_fixes) >= RESET_FIXES:
                self._accept()
            return True
        held, self.back, self.back_fixes = self.back, [], []
        for line, _ in held:  # no new base: the fixes going back timed nothing
            self._place(line, None)
        if t_fix is not None and t_fix < self.fix:  # going back again: judged anew
            self.report.notes["fix_time_not_increasing"] += 1
            self.back, self.back_fixes = [(text, t_fix)], [t_fix]
            return True
        return False

    def _accept(self) -> None:
        """The judged fixes are a new time base: shifted to follow the base before."""
        assert self.fix is not None
        r = self.report
        first = self.back_fixes[0]
        days = round((self.fix - first) / DAY_S)
        step = days * DAY_S
        if days < 1 or not 0.0 < first + step - self.fix <= MAX_FIX_GAP_S:
            step = self.fix + self.interval - first
            self.out.write(self.fix, self.pending[0])
            count(r.skipped, "time_reset", len(self.pending) - 1 + self.overflow)
            self.fix, self.pending, self.overflow = None, [], 0
        count(r.notes, "fix_time_not_increasing", -len(self.back_fixes))
        if r.notes["fix_time_not_increasing"] <= 0:
            del r.notes["fix_time_not_increasing"]
        r.notes["time_base_reset"] += 1
        self.shifts.append(self.shift)
        self.shift += step
        held, self.back, self.back_fixes = self.back, [], []
        for line, t in held:
            self._place(line, None if t is None else t + step)

    def _place(self, text: str, t_fix: float | None) -> None:
        """A sentence on the present base: a fix later than the last times it, any
        other waits for the next fix."""
        r = self.report
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
            self.interval = min(t_fix - self.fix, MAX_FIX_GAP_S)
            self._release(t_fix)
        self.fix = t_fix
        self.pending = [text]

    def _release(self, t_next: float) -> None:
        assert self.fix is not None
        r = self.report
        if t_next - self.fix > MAX_FIX_GAP_S or self.overflow:
            self.out.write(self.fix, self.pending[0])
            count(r.skipped, "fix_gap", len(self.pending) - 1 + self.overflow)
        else:
            step = (t_next - self.fix) / len(self.pending)
            for j, line in enumerate(self.pending):
                self.out.write(self.fix + step * j, line)
        self.overflow = 0

    def finish(self) -> None:
        held, self.back, self.back_fixes = self.back, [], []
        for line, _ in held:
            self._place(line, None)
        if self.fix is None:
            return
        self.out.write(self.fix, self.pending[0])
        count(self.report.skipped, "after_last_fix", len(self.pending) - 1 + self.overflow)


RUN_TOGETHER = re.compile(r"(?<=\*[0-9A-Fa-f]{2})(?=[$!][A-Z0-9]{5},)")
"""Where one sentence ends (its checksum) and the next begins on the same line."""


def run_together(text: str, report: ImportReport) -> list[str]:
    """A line's sentences: several written on one line (a line end lost) split after
    each checksum that a sentence's address follows (counted ``sentences_run_together``
    in ``notes``)."""
    parts = RUN_TOGETHER.split(text)
    count(report.notes, "sentences_run_together", len(parts) - 1)
    return parts


class _Joiner:
    """Sentences split over two lines (a logger's buffer flushed mid-sentence) joined
    again: a line that starts a sentence but fails its check is held for one line, and
    taken with the next when that line starts no sentence and the two together pass
    (counted ``lines_joined`` in ``notes``); otherwise counted by its reason."""

    def __init__(self, checks: SentenceCheck, report: ImportReport) -> None:
        self.checks = checks
        self.report = report
        self.held: tuple[str, str] | None = None  # (a cut line, why it failed)

    def lines(self, text: str) -> list[str]:
        """The sentence a log line gives (with the held line before it when they join),
        as a list of none or one."""
        out: list[str] = []
        if self.held is not None:
            cut, why = self.held
            self.held = None
            if text[:1] not in ("$", "!", "\\") and not_a_sentence(cut + text) is None:
                self.report.notes["lines_joined"] += 1
                line, reason = self.checks.line(cut + text)
                if line is not None:
                    return [line]
            self.report.skipped[why] += 1
        line, reason = self.checks.line(text)
        if line is not None:
            out.append(line)
        elif text[:1] in ("$", "!") and "*" not in text:
            self.held = (text, reason or "empty")
        else:
            self.report.skipped[reason or "empty"] += 1
        return out

    def flush(self) -> None:
        """The end of a file: a held line is counted by its reason."""
        if self.held is not None:
            self.report.skipped[self.held[1]] += 1
            self.held = None


class _Clock:
    """The fixes that time a log: RMC, ZDA and GGA as the decoders read them, GLL's
    time of day (:func:`drivers.nmea0183.parse_gll`, a valid fix only) until a fix of
    another kind has come (a GNSS sending GLL alone; beside RMC, an instrument bus's
    GLL repeats the fix late)."""

    def __init__(self, decoder: NmeaDecoder, day: date | None) -> None:
        self.decoder = decoder
        self.day = day
        self.other_fix = False  # a fix of RMC, ZDA or GGA has come
        self.gga: str | None = None  # the GGA of the GLL that timed the last sentence

    def fix(self, text: str, last: float | None) -> float | None:
        """The time the sentence fixes, or None; ``last`` the time of the fix before.
        A GLL that times it leaves its fix as a GGA in :attr:`gga`."""
        fix: float | None = None
        self.gga = None
        if sentence_kind(text) == "GLL":
            gll = _gll(text)
            if gll is not None and not self.other_fix:
                fix, self.day = _fix_time(gll, self.day, last)
                self.gga = None if fix is None else gga_of_gll(text)
            return fix
        try:
            decoded = self.decoder.decode_all((text + "\r\n").encode("ascii"))
        except FrameError:
            decoded = []  # a sentence the decoders do not parse is still kept
        for rec in decoded:
            fix, self.day = _fix_time(rec, self.day, last)
            self.other_fix = self.other_fix or fix is not None
        return fix


def gga_of_gll(text: str) -> str:
    """The GGA of a valid GLL sentence's fix (its talker, time of day and position,
    quality 1): the pipeline takes a GNSS position (for the variation model's) from
    RMC or GGA, never GLL."""
    f = split_nmea(text.encode("ascii"), required=True).decode("ascii").split(",")
    body = f"{f[0][:2]}GGA,{f[5]},{f[1]},{f[2]},{f[3]},{f[4]},1,,,,M,,M,,"
    return with_checksum(body, text[0])


def _gll(text: str) -> Gll | None:
    """A GLL sentence's valid fix, or None (a void or unreadable one times nothing)."""
    try:
        body = split_nmea(text.encode("ascii"), required=True).decode("ascii")
        rec = parse_gll(body[:2], body.split(",")[1:], text.encode("ascii"))
    except (FrameError, UnicodeDecodeError):
        return None
    return rec if rec.valid else None


DATED_FIX = re.compile(r"[$!]..(?:RMC,(?:[^,*]*,){8}\d{6}|ZDA,[^,*]*,\d{1,2},\d{1,2},\d{4})")
"""An RMC with its date or a ZDA with its date, found in a log's lines before import."""

FILE_NAME_DATE = re.compile(
    r"(?<!\d)((?:19[89]|20\d)\d)[-_.]?(0[1-9]|1[0-2])[-_.]?(0[1-9]|[12]\d|3[01])(?!\d)"
)
"""A date in a log file's name (``2014-06-27``, ``2014_06_27``, ``20140627``)."""


def _dated(paths: Sequence[str | Path]) -> bool:
    """Whether any line of the logs holds a dated fix (:data:`DATED_FIX`): read to the
    first one (a log of times of day alone is read through once more)."""
    for path in paths:
        with open_text(path) as f:
            if any(DATED_FIX.search(line) for line in bounded_lines(f, Counter())):
                return True
    return False


def file_day(path: str | Path) -> tuple[date, str] | None:
    """The date a log file's name holds (``date_from_file_name``), else the UTC day the
    file was last written (``date_from_file_time``), or None when neither is read."""
    m = FILE_NAME_DATE.search(Path(path).name)
    if m is not None:
        try:
            return date(int(m[1]), int(m[2]), int(m[3])), "date_from_file_name"
        except ValueError:
            pass
    try:
        mtime = Path(path).stat().st_mtime
    except OSError:
        return None
    t = datetime.fromtimestamp(mtime, UTC)
    return (t.date(), "date_from_file_time") if within_years(mtime) else None


def _start_day(paths: Sequence[str | Path], day: date | None, report: ImportReport) -> date | None:
    """The date of times of day before any fix dates them: ``day`` (``--date``), else,
    for logs with no dated fix at all, the first file's (:func:`file_day`, noted)."""
    if day is not None or not paths or _dated(paths):
        return day
    found = file_day(paths[0])
    if found is None:
        return None
    report.notes[found[1]] += 1
    return found[0]


FIRST_LINE_CHARS = 80
"""A log none of whose lines is a sentence has its first line quoted up to this many
characters in the error."""


def _why_no_time(report: ImportReport, first: str, sentences: int) -> str:
    """The error of an import that wrote nothing: an empty file, no line a sentence
    (what the first line looks like), or sentences without a fix that times them."""
    skipped = reasons(report.skipped) or "none"
    if not first and not report.skipped:
        return f"{', '.join(report.files)}: empty (no line to import)"
    if not first and set(report.skipped) == {"truncated"}:
        return (
            f"{', '.join(report.files)}: a gzip stream cut short or corrupt before its first line"
        )
    if sentences == 0 and first:
        looks = what_it_looks_like(first)
        return (
            f"no line is an NMEA 0183 sentence with its checksum; the first reads {first!r}"
            + (f", which looks like {looks}" if looks else "")
            + f"; skipped: {skipped}"
        )
    return (
        "no sentence could be given a time: the log needs RMC or ZDA fixes with a "
        "date (or GGA, GLL, or RMC without a date, with --date YYYY-MM-DD); skipped: "
        f"{skipped}"
    )


def _add(spread: _Spreader, clock: _Clock, line: str, report: ImportReport) -> None:
    """One sentence into the capture at the time the fixes give it."""
    spread.add(line, clock.fix(line, spread.raw_fix))
    if clock.gga is not None:  # a GLL's position, as GGA
        report.notes["gga_from_gll"] += 1
        spread.add(clock.gga, None)


WATER_TALKER_SHARE = 0.1
"""A talker sending at least this share of a log's VHW and VBW is a speed source of its
own (below it: a few sentences whose address a line error changed)."""


def _note_water_talkers(talkers: Counter[str], report: ImportReport) -> None:
    """Speed through the water from two talkers or more, each with at least
    :data:`WATER_TALKER_SHARE` of it, noted ``water_talkers II+VW``: two logs on one
    port, or one relayed under two talkers; calibration takes them as one log."""
    total = sum(talkers.values())
    many = sorted(t for t, n in talkers.items() if n >= WATER_TALKER_SHARE * total)
    if len(many) > 1:
        report.notes[f"water_talkers {'+'.join(many)}"] += 1


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
        day: the UTC date for times of day alone (GGA, GLL, RMC without a date) when no
            RMC or ZDA gives one (without it, the file's: :func:`file_day`).
        progress: called after each file.

    Raises:
        ImportFormatError: a file cannot be read, or no sentence has a time.
    """
    report = ImportReport([str(p) for p in paths], str(out), port)
    decoder = make_decoder("nmea0183", port, errors="raise")
    sink = CaptureSink(out, port, f"emlogd import --format nmea: {', '.join(report.files)}", report)
    spread = _Spreader(sink, report)
    joiner = _Joiner(SentenceCheck(report), report)
    course = CourseFill(report)
    first = ""  # the first line, quoted when no line is a sentence
    sentences = 0
    try:
        clock = _Clock(decoder, _start_day(paths, day, report))
        for i, path in enumerate(paths):
            with open_text(path) as f:
                for raw in bounded_lines(f, report.skipped):
                    report.lines += 1
                    first = first or raw.strip()[:FIRST_LINE_CHARS]
                    for part in run_together(raw.strip(LINE_PADDING), report):
                        for cut in joiner.lines(part):
                            sentences += 1
                            for line in course.lines(cut):
                                _add(spread, clock, line, report)
            joiner.flush()
            if progress is not None:
                progress(f"import {Path(path).name}", (i + 1) / len(paths))
        for line in course.flush():
            _add(spread, clock, line, report)
        spread.finish()
        if report.written == 0:
            raise ImportFormatError(_why_no_time(report, first, sentences))
        _note_water_talkers(sink.water_talkers, report)
    except BaseException:
        sink.abort()
        raise
    sink.commit()
    return report
