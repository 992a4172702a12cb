"""The perturbation suite: each real recording rewritten as a held-out log of its kind
plausibly differs, and run through the same commands as docs/real_data.py.

Usage: ``python docs/real_variants.py DIR [--only NAME ...] [--variant V ...] [--out DIR] [--json]``.

A variant is a pure function of the source file's text (:data:`VARIANTS`): the GNSS
thinned to 0.5 and 0.2 Hz, fix times of 1-s and 10-s resolution; a magnetic heading
without any variation in the log (HDG with empty variation fields, HDM, VHW magnetic
only); other sentences and talkers (GGA + VTG instead of RMC, ZDA + GLL + VTG, RMC
without a course at low speed, VLW, MWV with nonsense, proprietary ``$P`` lines),
lines without checksums, CRLF or LF endings, a truncated last line, a gap of minutes,
a midnight crossed by GGA times of day; the log 2 s behind or ahead of the GNSS, at
half or twice its rate, silent (or the GNSS silent) 30 s every 5 minutes; THS or
$PASHR the only heading; VBW instead of VHW; Expedition exports with other column sets
(``Set``/``Drift``, no current, upper-case names, another order, extra columns,
``;`` with decimal commas, quoted cells, a byte-order mark, ``Utc`` as US-English
text, ``Date`` and ``Time`` columns) and Expedition's own sparse log (``!Boat``
header, channel numbers, ``channel,value`` pairs); the logger's TSV without its
banner, with its local time given by ``--utc-offset``, with rows every 5 s, under its
other firmware's column names after a banner of settings, with its date in full or
year first, its time with tenths;
and a strong tidal current (:func:`tide`) added to the GNSS of an NMEA log (also at
3 kn, and with the GNSS at 0.5 Hz) and of an Expedition export: the water-frame
calibration should not move.

Each variant is imported, calibrated (LS and KF, ``--ref-field gnss --current``, no
``--variation``) and replayed (``examples/emlogd-gnss.yaml``, ``lag: auto``), and its
row set beside the unperturbed recording's: the effective scale at the unperturbed
median speed (LS and KF, and their change), the replay's emitted/raw RMSE against
the GNSS water speed and its worst 5-min ratio. :func:`verdict` names what moved: a
step that failed, a scale more than :data:`MAX_SCALE_SHIFT` from the unperturbed run,
a replay worse than raw over the log, a 5-min window worse than both the unperturbed
run's and :data:`WINDOW_TOLERANCE` by more than :data:`WINDOW_SLACK`.
"""

from __future__ import annotations

import argparse
import bisect
import importlib
import itertools
import json
import math
import re
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from functools import reduce
from pathlib import Path
from types import ModuleType
from typing import Any

import variants_csv as vcsv
from variants_csv import add_current

ROOT = Path(__file__).resolve().parents[1]


def _real_data() -> ModuleType:
    """docs/real_data.py as a module (its functions run each step)."""
    here = str(ROOT / "docs")
    if here not in sys.path:
        sys.path.insert(0, here)
    return importlib.import_module("real_data")


MAX_SCALE_SHIFT = 0.05
"""A variant whose effective scale at the median speed moves more than this from the
unperturbed run's has changed the result materially."""

WORSE_THAN_RAW = 1.01
"""A replay whose emitted RMSE over the log exceeds raw's by this factor is worse than
raw (below it, the sentences' rounding to 0.01 kn)."""

WINDOW_TOLERANCE = 1.10
"""A 5-min window of the replay up to this times raw's RMSE is within the suite's
tolerance (docs/REAL_DATA.md)."""

WINDOW_SLACK = 0.05
"""A variant's worst 5-min window is flagged when it exceeds both
:data:`WINDOW_TOLERANCE` and the unperturbed run's worst by more than this."""

GAP_S = 300.0
"""The gap variant removes this many seconds of the log's middle."""

LAG_MATCH_S = 1.5
"""The lag variants take the reading nearest the lagged time within this, s."""

DROPOUT_EVERY_S = 300.0
"""The dropout variants lose their sentences once every this many seconds, s."""

DROPOUT_S = 30.0
"""For this long, s."""

# ------------------------------------------------------------------ NMEA helpers

SENTENCE = re.compile(r"^([$!])([^*\r\n]*)(?:\*([0-9A-Fa-f]{2}))?\s*$")


def checksum(body: str) -> str:
    """The XOR checksum of a sentence's body (between ``$`` and ``*``), two hex digits."""
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def sentence(body: str, lead: str = "$") -> str:
    """A complete sentence from its body."""
    return f"{lead}{body}*{checksum(body)}"


def fields(line: str) -> list[str] | None:
    """A sentence's fields (address first), or None for a line that is no sentence."""
    m = SENTENCE.match(line)
    return m.group(2).split(",") if m else None


def kind_of(f: list[str]) -> str:
    return f[0][2:] if len(f[0]) >= 5 else f[0]


def _rmc_time(f: list[str]) -> datetime | None:
    """An RMC's UTC time, or None."""
    try:
        hh, mm, ss = int(f[1][0:2]), int(f[1][2:4]), float(f[1][4:])
        dd, mo, yy = int(f[9][0:2]), int(f[9][2:4]), int(f[9][4:6])
    except (ValueError, IndexError):
        return None
    base = datetime(2000 + yy if yy < 80 else 1900 + yy, mo, dd, hh, mm, tzinfo=UTC)
    return base + timedelta(seconds=ss)


def _hhmmss(t: datetime, decimals: int) -> str:
    s = t.second + t.microsecond / 1e6
    sec = f"{s:0{3 + decimals}.{decimals}f}" if decimals else f"{int(s):02d}"
    return f"{t.hour:02d}{t.minute:02d}{sec}"


def _map_nmea(text: str, fn: Callable[[list[str]], list[str] | None]) -> str:
    """Each sentence through ``fn`` (its fields → new fields, or None to drop it); other
    lines kept. The line ending of the source is kept."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    out: list[str] = []
    for line in text.splitlines():
        f = fields(line)
        if f is None:
            out.append(line)
            continue
        g = fn(f)
        if g is not None:
            out.append(sentence(",".join(g), line[0]))
    return nl.join(out) + nl


def _thin_gnss(period_s: float) -> Callable[[str], str]:
    """GNSS sentences (RMC, GGA, VTG, GLL, ZDA) kept only at fixes ``period_s`` apart."""

    def apply(text: str) -> str:
        state = {"kept": -math.inf, "on": True}

        def fn(f: list[str]) -> list[str] | None:
            k = kind_of(f)
            if k == "RMC":
                t = _rmc_time(f)
                if t is not None:
                    x = t.timestamp()
                    state["on"] = x >= state["kept"] + period_s - 1e-3
                    if state["on"]:
                        state["kept"] = x
            if k in ("RMC", "GGA", "VTG", "GLL", "ZDA"):
                return f if state["on"] else None
            return f

        return _map_nmea(text, fn)

    return apply


def _coarse_times(resolution_s: float) -> Callable[[str], str]:
    """RMC (and GGA, GLL, ZDA) times floored to ``resolution_s``."""

    def fn(f: list[str]) -> list[str]:
        k = kind_of(f)
        idx = {"RMC": 1, "GGA": 1, "GLL": 5, "ZDA": 1}.get(k)
        if idx is None or idx >= len(f) or len(f[idx]) < 6:
            return f
        try:
            secs = int(f[idx][0:2]) * 3600 + int(f[idx][2:4]) * 60 + float(f[idx][4:])
        except ValueError:
            return f
        secs = math.floor(secs / resolution_s) * resolution_s
        g = list(f)
        g[idx] = f"{int(secs // 3600):02d}{int(secs % 3600 // 60):02d}{int(secs % 60):02d}"
        return g

    return lambda text: _map_nmea(text, fn)


def _no_variation(f: list[str]) -> list[str]:
    """Every variation field emptied (HDG's deviation and variation, RMC's)."""
    k, g = kind_of(f), list(f)
    if k == "HDG":
        g[2:6] = ["", "", "", ""][: len(g[2:6])]
    elif k == "RMC" and len(g) > 11:
        g[10], g[11] = "", ""
    return g


def _hdm(f: list[str]) -> list[str] | None:
    """HDG → HDM (the magnetic heading alone); other variations emptied."""
    if kind_of(f) == "HDG":
        return [f[0][:2] + "HDM", f[1], "M"]
    return _no_variation(f)


def _vhw_magnetic_only(f: list[str]) -> list[str] | None:
    """No heading sentence; VHW's true heading emptied; no variation anywhere."""
    k = kind_of(f)
    if k in ("HDG", "HDT", "HDM"):
        return None
    if k == "VHW" and len(f) > 2:
        g = list(f)
        g[1], g[2] = "", ""
        return _no_variation(g)
    return _no_variation(f)


def _rmc_to(kinds: tuple[str, ...]) -> Callable[[list[str]], list[str] | None]:
    """RMC replaced by the named sentences (GGA, VTG, GLL, ZDA) of the same fix."""

    def fn(f: list[str]) -> list[str] | None:
        if kind_of(f) in ("GGA", "VTG", "GLL", "ZDA"):
            return None  # the log's own: the variant's replace them
        if kind_of(f) != "RMC" or len(f) < 10:
            return f
        t = _rmc_time(f)
        if t is None or f[2] != "A":
            return None
        hms = _hhmmss(t, 2)
        talker = f[0][:2]
        out: list[list[str]] = []
        for k in kinds:
            if k == "GGA":
                out.append([talker + "GGA", hms, *f[3:7], "1", "08", "1.0", "10.0", "M"] + [""] * 4)
            elif k == "VTG":
                kmh = f"{float(f[7] or 0) * 1.852:.1f}" if f[7] else ""
                out.append([talker + "VTG", f[8], "T", "", "M", f[7], "N", kmh, "K", "A"])
            elif k == "GLL":
                out.append([talker + "GLL", *f[3:7], hms, "A", "A"])
            elif k == "ZDA":
                out.append(
                    [talker + "ZDA", hms, f"{t.day:02d}", f"{t.month:02d}", f"{t.year}", "", ""]
                )
        # several sentences from one: joined with a marker split by _expand
        return ["\x00".join(",".join(x) for x in out)]

    return fn


def _expand(text: str) -> str:
    """Sentences the maps joined with NUL written one per line with their checksums."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    out: list[str] = []
    for line in text.splitlines():
        if "\x00" not in line:
            out.append(line)
            continue
        body = line[1 : line.index("*")]
        out.extend(sentence(part) for part in body.split("\x00"))
    return nl.join(out) + nl


def _other_sentences(text: str) -> str:
    """Other talkers (GP for the fix, HC for the compass, VW for the log), VLW, nonsense
    MWV and proprietary lines between the sentences."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    out: list[str] = []
    for i, line in enumerate(text.splitlines()):
        f = fields(line)
        if f is not None and len(f[0]) == 5:
            k = kind_of(f)
            talker = {"RMC": "GP", "GGA": "GP", "VTG": "GP", "HDG": "HC", "HDM": "HC"}
            talker |= {"HDT": "HE", "VHW": "VW"}
            if k in talker:
                f = [talker[k] + k, *f[1:]]
            line = sentence(",".join(f), line[0])
        out.append(line)
        if i % 7 == 3:
            out.append(sentence("VWVLW,1554.2,N,12.3,N"))
        if i % 11 == 5:
            out.append(sentence("WIMWV,999,R,-5.0,N,V"))
            out.append(sentence("WIMWV,,,,,"))
        if i % 13 == 6:
            out.append(sentence("PGRME,15.0,M,45.0,M,25.0,M"))
            out.append("$PSRT,GARBAGE LINE WITHOUT CHECKSUM")
    return nl.join(out) + nl


def _rmc_course_empty_slow(f: list[str]) -> list[str]:
    """RMC's course left empty below 1 kn (receivers drop it at low speed)."""
    if kind_of(f) == "RMC" and len(f) > 8:
        try:
            slow = float(f[7]) < 1.0
        except ValueError:
            slow = True
        if slow:
            g = list(f)
            g[8] = ""
            return g
    return f


def _prefixed(text: str) -> str:
    """A receive time (ms since the log's start) and a tag before each sentence, as
    some loggers write them."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    return nl.join(f"{100 * i};N;{ln}" for i, ln in enumerate(text.splitlines())) + nl


def _no_checksums(text: str) -> str:
    return re.sub(r"\*[0-9A-Fa-f]{2}(?=\r?$)", "", text, flags=re.MULTILINE)


def _line_endings(nl: str) -> Callable[[str], str]:
    return lambda text: nl.join(text.splitlines()) + nl


def _truncated(text: str) -> str:
    """The last line cut halfway (a logger switched off), and one line in the middle
    cut and run into the next (a reset)."""
    lines = text.splitlines(keepends=True)
    mid = len(lines) // 2
    lines[mid] = lines[mid][: len(lines[mid]) // 2]
    last = lines[-1].rstrip("\r\n")
    lines[-1] = last[: len(last) // 2]
    return "".join(lines)


def _fix_seconds(text: str) -> Iterator[tuple[int, float]]:
    """(line index, epoch seconds) of each RMC fix."""
    for i, line in enumerate(text.splitlines()):
        f = fields(line)
        if f is not None and kind_of(f) == "RMC":
            t = _rmc_time(f)
            if t is not None:
                yield i, t.timestamp()


def _gap(text: str) -> str:
    """:data:`GAP_S` of the log's middle removed (a logger paused)."""
    fixes = list(_fix_seconds(text))
    if len(fixes) < 10:
        return text
    t_mid = (fixes[0][1] + fixes[-1][1]) / 2.0
    i0 = next(i for i, t in fixes if t >= t_mid)
    i1 = next((i for i, t in fixes if t >= t_mid + GAP_S), fixes[-1][0])
    lines = text.splitlines(keepends=True)
    return "".join(lines[:i0] + lines[i1:])


def _shift_to_midnight(text: str) -> tuple[str, datetime]:
    """RMC times and dates shifted so that midnight falls halfway between the first fix
    and the last; (the text, the first fix's new date)."""
    fixes = [t for _, t in _fix_seconds(text)]
    if not fixes:
        return text, datetime(2000, 1, 1, tzinfo=UTC)
    t0 = datetime.fromtimestamp(fixes[0], UTC)
    midnight = datetime(t0.year, t0.month, t0.day, tzinfo=UTC) + timedelta(days=1)
    shift = midnight - t0 - timedelta(seconds=(fixes[-1] - fixes[0]) / 2.0)

    def fn(f: list[str]) -> list[str] | None:
        k = kind_of(f)
        if k in ("GGA", "GLL", "ZDA"):
            return None
        if k != "RMC":
            return f
        t = _rmc_time(f)
        if t is None:
            return f
        t = t + shift
        g = list(f)
        g[1] = _hhmmss(t, 2)
        g[9] = f"{t.day:02d}{t.month:02d}{t.year % 100:02d}"
        return g

    return _map_nmea(text, fn), t0 + shift


def _midnight_gga(text: str) -> str:
    """The log across midnight with GGA + VTG fixes only (times of day, no date)."""
    shifted, _ = _shift_to_midnight(text)
    return _expand(_map_nmea(shifted, _rmc_to(("GGA", "VTG"))))


def midnight_date(text: str) -> str:
    """The UTC date of :func:`_midnight_gga`'s first fix (its ``--date``)."""
    return _shift_to_midnight(text)[1].date().isoformat()


def first_date(text: str) -> str:
    """The UTC date of the log's first RMC (``--date`` for a GGA-only variant)."""
    first = next(_fix_seconds(text), None)
    t = datetime.fromtimestamp(first[1], UTC) if first else datetime(2000, 1, 1, tzinfo=UTC)
    return t.date().isoformat()


def _tidal_rmc(f: list[str], scale: float = 1.0) -> list[str]:
    """RMC's speed and course over ground with :func:`tide`'s current (times ``scale``)
    added."""
    if kind_of(f) != "RMC" or len(f) < 9:
        return f
    t = _rmc_time(f)
    try:
        sog, cog = float(f[7]), float(f[8])
    except ValueError:
        return f
    if t is None:
        return f
    v, c = add_current(sog, cog, t.timestamp(), scale)
    g = list(f)
    g[7], g[8] = f"{v:.2f}", f"{c:.1f}"
    return g


STRONG_TIDE = 2.0
"""The ``tide-strong`` variant's current, times the ``tide`` variant's (3 kn)."""


def _line_times(lines: list[str]) -> list[float]:
    """Each line's time as ``emlogd import`` gives it: spread evenly between the RMC
    fixes around it (nan before the first fix and after the last)."""
    fixes = [(i, t) for i, t in _fix_seconds("\n".join(lines))]
    out = [math.nan] * len(lines)
    for (i0, t0), (i1, t1) in itertools.pairwise(fixes):
        for i in range(i0, i1):
            out[i] = t0 + (t1 - t0) * (i - i0) / (i1 - i0)
    return out


def _lagged(lag_s: float) -> Callable[[str], str]:
    """The log's speed (VHW knots and km/h) replaced by its reading ``lag_s`` earlier
    (a log that lags the GNSS by ``lag_s``; negative: one that leads it), the nearest
    VHW within :data:`LAG_MATCH_S`; a VHW without one is dropped."""

    def apply(text: str) -> str:
        nl = "\r\n" if "\r\n" in text[:4096] else "\n"
        lines = text.splitlines()
        times = _line_times(lines)
        vhw = [
            (times[i], f)
            for i, ln in enumerate(lines)
            if (f := fields(ln)) is not None and kind_of(f) == "VHW" and math.isfinite(times[i])
        ]
        vt = [t for t, _ in vhw]
        out: list[str] = []
        for i, ln in enumerate(lines):
            f = fields(ln)
            if f is None or kind_of(f) != "VHW" or not math.isfinite(times[i]):
                out.append(ln)
                continue
            want = times[i] - lag_s
            k = bisect.bisect_left(vt, want)
            near = min((j for j in (k - 1, k) if 0 <= j < len(vt)), key=lambda j: abs(vt[j] - want))
            if abs(vt[near] - want) > LAG_MATCH_S:
                continue
            g, src = list(f), vhw[near][1]
            g[5:9] = src[5:9]
            out.append(sentence(",".join(g), ln[0]))
        return nl.join(out) + nl

    return apply


def _dropouts(kinds: frozenset[str]) -> Callable[[str], str]:
    """The named sentences left out for the last :data:`DROPOUT_S` of every
    :data:`DROPOUT_EVERY_S` (a log or a receiver losing its output a while)."""

    def apply(text: str) -> str:
        nl = "\r\n" if "\r\n" in text[:4096] else "\n"
        lines = text.splitlines()
        times = _line_times(lines)
        t0 = next((t for t in times if math.isfinite(t)), 0.0)
        out = [
            ln
            for ln, t in zip(lines, times, strict=True)
            if not (
                (f := fields(ln)) is not None
                and kind_of(f) in kinds
                and math.isfinite(t)
                and (t - t0) % DROPOUT_EVERY_S > DROPOUT_EVERY_S - DROPOUT_S
            )
        ]
        return nl.join(out) + nl

    return apply


def _vhw_every(n: int) -> Callable[[str], str]:
    """Every ``n``-th VHW kept (a log at 1/n of its rate)."""

    def apply(text: str) -> str:
        seen = [0]

        def fn(f: list[str]) -> list[str] | None:
            if kind_of(f) != "VHW":
                return f
            seen[0] += 1
            return f if seen[0] % n == 0 else None

        return _map_nmea(text, fn)

    return apply


def _vhw_twice(text: str) -> str:
    """Each fix interval's first VHW sent again halfway through the interval's lines (a
    log at twice the GNSS's rate)."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    out: list[str] = []
    block: list[str] = []

    def flush() -> None:
        again = [ln for ln in block if (f := fields(ln)) is not None and kind_of(f) == "VHW"]
        mid = len(block) // 2
        out.extend(block[:mid] + again[:1] + block[mid:])

    for ln in text.splitlines():
        f = fields(ln)
        if f is not None and kind_of(f) == "RMC":
            flush()
            block = []
        block.append(ln)
    flush()
    return nl.join(out) + nl


def _true_heading_as(make: Callable[[float], list[str]]) -> Callable[[list[str]], list[str] | None]:
    """The heading as one true-heading sentence alone (``make`` of the heading): HDG
    made true with its variation (none taken as 0), HDT/HDM dropped, VHW's headings
    emptied."""

    def fn(f: list[str]) -> list[str] | None:
        k = kind_of(f)
        if k == "HDG":
            try:
                hdg = float(f[1])
                var = float(f[4]) * (-1.0 if f[5] == "W" else 1.0) if f[4] else 0.0
            except (ValueError, IndexError):
                return None
            return make((hdg + var) % 360.0)
        if k in ("HDT", "HDM"):
            return None
        if k == "VHW" and len(f) > 4:
            return [f[0], "", "", "", "", *f[5:]]
        return f

    return fn


def _ths_of(hdg: float) -> list[str]:
    return ["GPTHS", f"{hdg:.1f}", "A"]


def _pashr_of(hdg: float) -> list[str]:
    return ["PASHR", "", f"{hdg:.2f}", "T", "0.00", "0.00", "0.00", "0.1", "0.1", "0.2", "1", "0"]


def _vbw(f: list[str]) -> list[str]:
    """VHW's speed sent as VBW's longitudinal water speed (the ground pair empty)."""
    if kind_of(f) == "VHW" and len(f) > 5 and f[5]:
        return [f[0][:2] + "VBW", f[5], "0.00", "A", "", "", "V"]
    return f


# ------------------------------------------------------------------ the variants


@dataclass(frozen=True)
class Variant:
    """One perturbation: the kind of log it applies to, the rewrite, what it tests, and
    any import options it needs (a function of the source text)."""

    name: str
    kind: str
    make: Callable[[str], str]
    tests: str
    options: Callable[[str], list[str]] = lambda _text: []


def _nm(fn: Callable[[list[str]], list[str] | None]) -> Callable[[str], str]:
    return lambda text: _expand(_map_nmea(text, fn))


VARIANTS: tuple[Variant, ...] = (
    Variant(
        "gnss-0.5hz",
        "nmea",
        _thin_gnss(2.0),
        "a GNSS at 0.5 Hz: alignment at the reference's cadence",
    ),
    Variant("gnss-0.2hz", "nmea", _thin_gnss(5.0), "a GNSS at 0.2 Hz"),
    Variant(
        "fix-1s", "nmea", _coarse_times(1.0), "fix times of 1-s resolution (repeated at > 1 Hz)"
    ),
    Variant("fix-10s", "nmea", _coarse_times(10.0), "fix times of 10-s resolution"),
    Variant(
        "hdg-no-var",
        "nmea",
        _nm(_no_variation),
        "HDG and RMC with empty variation: the IGRF model's",
    ),
    Variant("hdm", "nmea", _nm(_hdm), "HDM, a magnetic heading alone"),
    Variant("vhw-mag", "nmea", _nm(_vhw_magnetic_only), "VHW's magnetic heading the only heading"),
    Variant(
        "gga-vtg",
        "nmea",
        _nm(_rmc_to(("GGA", "VTG"))),
        "GGA + VTG instead of RMC, the date given by --date",
        lambda text: ["--date", first_date(text)],
    ),
    Variant(
        "zda-gll-vtg", "nmea", _nm(_rmc_to(("ZDA", "GLL", "VTG"))), "ZDA + GLL + VTG instead of RMC"
    ),
    Variant(
        "rmc-slow-no-course", "nmea", _nm(_rmc_course_empty_slow), "RMC without a course below 1 kn"
    ),
    Variant(
        "other-sentences",
        "nmea",
        _other_sentences,
        "other talkers, VLW, nonsense MWV, proprietary lines",
    ),
    Variant("no-checksum", "nmea", _no_checksums, "sentences without checksums"),
    Variant("prefixed", "nmea", _prefixed, "a receive time and a tag before each sentence"),
    Variant("crlf", "nmea", _line_endings("\r\n"), "CRLF line endings"),
    Variant("lf", "nmea", _line_endings("\n"), "LF line endings"),
    Variant("truncated", "nmea", _truncated, "a truncated last line and a line cut by a reset"),
    Variant("gap", "nmea", _gap, "a gap of minutes"),
    Variant(
        "midnight-gga",
        "nmea",
        _midnight_gga,
        "midnight crossed with GGA times of day and no ZDA",
        lambda text: ["--date", midnight_date(text)],
    ),
    Variant("tide", "nmea", _nm(_tidal_rmc), "a 1.5-kn tidal current turning over 12.42 h"),
    Variant(
        "tide-strong",
        "nmea",
        _nm(lambda f: _tidal_rmc(f, STRONG_TIDE)),
        "a 3-kn tidal current (a tidal race, a fjord's narrows)",
    ),
    Variant(
        "tide-gnss-0.5hz",
        "nmea",
        lambda text: _thin_gnss(2.0)(_nm(_tidal_rmc)(text)),
        "the 1.5-kn tide with a GNSS at 0.5 Hz",
    ),
    Variant("log-lags-2s", "nmea", _lagged(2.0), "the log 2 s behind the GNSS"),
    Variant("log-leads-2s", "nmea", _lagged(-2.0), "the log 2 s ahead of the GNSS"),
    Variant("log-half-rate", "nmea", _vhw_every(2), "every other VHW: the log at half its rate"),
    Variant("log-twice", "nmea", _vhw_twice, "a VHW twice per fix: the log at twice its rate"),
    Variant(
        "log-dropouts", "nmea", _dropouts(frozenset({"VHW"})), "the log silent 30 s every 5 min"
    ),
    Variant(
        "gnss-dropouts",
        "nmea",
        _dropouts(frozenset({"RMC", "GGA", "GLL", "VTG", "ZDA"})),
        "the GNSS silent 30 s every 5 min",
    ),
    Variant(
        "ths",
        "nmea",
        _nm(_true_heading_as(_ths_of)),
        "THS, a GNSS compass's true heading, the only heading",
    ),
    Variant(
        "pashr",
        "nmea",
        _nm(_true_heading_as(_pashr_of)),
        "$PASHR, an INS's attitude, the only heading",
    ),
    Variant("vbw", "nmea", _nm(_vbw), "VBW instead of VHW (a log sending VBW alone)"),
    Variant(
        "set-drift",
        "expedition-csv",
        vcsv.rename({"iSet": "Set", "iDrift": "Drift"}),
        "Set/Drift for iSet/iDrift",
    ),
    Variant("no-current", "expedition-csv", vcsv.drop({"iSet", "iDrift"}), "no current columns"),
    Variant(
        "upper-case",
        "expedition-csv",
        vcsv.rename({"Bsp": "BSP", "Hdg": "HDG", "Sog": "SOG", "Cog": "COG", "Utc": "UTC"}),
        "Expedition 10+'s upper-case names",
    ),
    Variant("reordered", "expedition-csv", vcsv.columns(vcsv.reverse), "another column order"),
    Variant("extra-columns", "expedition-csv", vcsv.columns(vcsv.extra), "extra columns"),
    Variant("semicolon", "expedition-csv", vcsv.semicolon, "';' delimiter and decimal commas"),
    Variant("quoted", "expedition-csv", vcsv.quoted, "every cell quoted"),
    Variant("bom-crlf", "expedition-csv", vcsv.bom_crlf, "a byte-order mark and CRLF"),
    Variant(
        "sog-0.5hz",
        "expedition-csv",
        vcsv.sparse_gnss(2.0),
        "Sog/Cog written every 2 s (a 0.5 Hz GNSS)",
    ),
    Variant("sog-0.2hz", "expedition-csv", vcsv.sparse_gnss(5.0), "Sog/Cog written every 5 s"),
    Variant("tide", "expedition-csv", vcsv.columns(vcsv.tidal_cells), "a 1.5-kn tidal current"),
    Variant(
        "utc-text-us",
        "expedition-csv",
        vcsv.columns(vcsv.utc_text("%m/%d/%Y %I:%M:%S %p")),
        "Utc as US-English Windows writes a date and time (month first, AM/PM)",
    ),
    Variant(
        "date-time-columns",
        "expedition-csv",
        vcsv.columns(vcsv.date_time_columns),
        "Date and Time columns instead of Utc (a spreadsheet's re-export)",
    ),
    Variant(
        "sparse-log",
        "expedition-csv",
        vcsv.expedition_log,
        "Expedition's own sparse log (channel, value pairs)",
    ),
    Variant("no-banner", "logger-tsv", vcsv.no_banner, "the logger's TSV without its banner"),
    Variant(
        "utc-offset",
        "logger-tsv",
        lambda text: text,
        "the logger's local time given as --utc-offset 2",
        lambda _text: ["--utc-offset", "2"],
    ),
    Variant(
        "logger-firmware",
        "logger-tsv",
        vcsv.logger_firmware,
        "the logger's other firmware: BS/HDG/SOG/COG names, a settings banner, '-' cells",
    ),
    Variant("rows-0.2hz", "logger-tsv", vcsv.thin_rows(5.0), "the logger's rows every 5 s"),
    Variant(
        "date-in-full", "logger-tsv", vcsv.tsv_dates("%d/%m/%Y"), "the logger's date dd/mm/yyyy"
    ),
    Variant(
        "date-year-first", "logger-tsv", vcsv.tsv_dates("%Y/%m/%d"), "the logger's date yyyy/mm/dd"
    ),
    Variant("time-fraction", "logger-tsv", vcsv.tsv_fraction, "the logger's time with tenths"),
)
"""Every variant (module docstring), by the kind of log it rewrites."""


# ------------------------------------------------------------------ running


def import_options(kind: str, extra: list[str]) -> list[list[str]]:
    """The import attempts of real_data.run_import, with the variant's options."""
    base = {"nmea": [["--format", "nmea"]], "expedition-csv": [["--format", "csv"]]}
    return [a + extra for a in base.get(kind, [["--format", "csv"]])]


def run_one(src: Path, text: str, variant: Variant | None, out: Path) -> dict[str, Any]:
    """Import, calibrate (LS, KF) and replay one variant (None: the unperturbed file)."""
    rd = _real_data()
    tag = f"{src.stem}.{variant.name if variant else 'base'}"
    path = out / f"{tag}{src.suffix}"
    data = variant.make(text) if variant else text
    path.write_bytes(
        data.encode("utf-8") if "\ufeff" in data[:1] else data.encode("latin-1", errors="replace")
    )
    row: dict[str, Any] = {"name": src.stem, "variant": variant.name if variant else "base"}
    what = rd.kind(path)  # the variant's own kind, as docs/real_data.py would tell it
    if what is None:
        row["errors"] = {"kind": "docs/real_data.py does not recognise the file as a log"}
        return row
    cap = out / f"{tag}.cap.gz"
    extra = variant.options(text) if variant else []
    doc: dict[str, Any] | None = None
    why = ""
    for opts in import_options(what or "", extra):
        rc, stdout, err = rd.emlogd(["import", str(path), *opts, "--out", str(cap), "--json"])
        if rc == 0:
            doc = json.loads(stdout)
            break
        why = rd._last_line(err) or f"exit {rc}"
    row["import"] = doc
    if doc is None:
        row["errors"] = {"import": why}
        return row
    row["errors"] = {}
    for method in ("ls", "kf"):
        res, why = rd.run_calibrate(cap, method)
        row[method] = res
        if res is None:
            row["errors"][method] = why
    emitted = out / f"{tag}.emitted.cap.gz"
    rep, why = rd.run_replay(cap, emitted)
    row["replay"] = rep["uuts"]["nmea"] if rep else None
    if rep is None:
        row["errors"]["replay"] = why
    else:
        try:
            row["scores"] = rd.water_scores(cap, emitted)
        except ValueError as exc:
            row["errors"]["scores"] = str(exc)
    return row


def scales(row: dict[str, Any], speed: float) -> tuple[float | None, float | None]:
    """(LS, KF) effective scale at ``speed``."""
    rd = _real_data()
    return rd.effective_scale(row.get("ls"), speed), rd.effective_scale(row.get("kf"), speed)


def verdict(row: dict[str, Any], base: dict[str, Any]) -> str:
    """What moved against the unperturbed run: ``ok`` or the reasons."""
    why: list[str] = []
    for step, msg in row.get("errors", {}).items():
        if step not in base.get("errors", {}):
            why.append(f"{step} fails: {msg}")
    speed = (base.get("scores") or {}).get("median_speed", math.nan)
    for label, a, b in zip(("LS", "KF"), scales(row, speed), scales(base, speed), strict=True):
        if a is not None and b is not None and abs(a - b) > MAX_SCALE_SHIFT:
            why.append(f"{label} scale {a:.3f} against {b:.3f}")
    s = row.get("scores")
    if s and s["rmse_emitted"] > WORSE_THAN_RAW * s["rmse_raw"]:
        why.append(f"replay worse than raw ({s['rmse_emitted']:.3f} > {s['rmse_raw']:.3f})")
    worst = (s or {}).get("worst_5min_ratio")
    was = (base.get("scores") or {}).get("worst_5min_ratio")
    if isinstance(worst, float) and worst > max(WINDOW_TOLERANCE, was or 0.0) + WINDOW_SLACK:
        why.append(f"a 5-min window {worst:.2f} times raw's RMSE (unperturbed {_f(was, '.2f')})")
    return "; ".join(why) or "ok"


def _f(x: object, spec: str) -> str:
    return format(x, spec) if isinstance(x, int | float) and math.isfinite(x) else "—"


def markdown(rows: list[dict[str, Any]]) -> str:
    """One line per variant: scales (LS / KF), replay RMSE and worst window, verdict."""
    out = [
        "| recording | variant | import: lines → sentences | scale LS / KF | replay at the end | "
        "emitted / raw RMSE (m/s) | worst 5-min | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    bases = {r["name"]: r for r in rows if r["variant"] == "base"}
    for r in rows:
        base = bases.get(r["name"], r)
        speed = (base.get("scores") or {}).get("median_speed", math.nan)
        ls, kf = scales(r, speed)
        imp = r.get("import")
        imported = f"{imp['lines']} → {imp['written']}" if imp else "fails"
        s = r.get("scores") or {}
        rmse = f"{_f(s.get('rmse_emitted'), '.3f')} / {_f(s.get('rmse_raw'), '.3f')}"
        v = "(reference)" if r is base else verdict(r, base)
        rep = r.get("replay")
        end = "—" if rep is None else "applied" if rep.get("params") else "raw"
        if rep is not None and rep.get("state") == "fault":
            end += " (fault)"
        out.append(
            f"| {r['name']} | {r['variant']} | {imported} | {_f(ls, '.3f')} / {_f(kf, '.3f')} | "
            f"{end} | {rmse} | {_f(s.get('worst_5min_ratio'), '.3f')} | {v} |"
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, run every (recording, variant), print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="the folder of recordings")
    ap.add_argument(
        "--only", nargs="*", default=[], help="recordings whose name contains one of these"
    )
    ap.add_argument("--variant", nargs="*", default=[], help="only these variants")
    ap.add_argument("--out", type=Path, help="keep the files here (default: a temporary folder)")
    ap.add_argument("--json", action="store_true", help="the rows as JSON")
    args = ap.parse_args(argv)
    rd = _real_data()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        for src in sorted(p for p in args.dir.iterdir() if p.is_file()):
            what = rd.kind(src)
            if (
                what is None
                or src.suffix == ".py"
                or (args.only and not any(o in src.stem for o in args.only))
            ):
                continue
            chosen = [
                v
                for v in VARIANTS
                if v.kind == what and (not args.variant or v.name in args.variant)
            ]
            if not chosen:
                continue
            text = src.read_bytes().decode("latin-1")
            for v in [None, *chosen]:
                rd.say(f"{src.stem}: {v.name if v else 'base'}")
                row = run_one(src, text, v, out)
                rows.append(row)
                if args.out is not None:
                    (out / "variants.json").write_text(json.dumps(rows, default=str) + "\n")
    sys.stdout.write(
        (json.dumps(rows, indent=1, default=str) if args.json else markdown(rows)) + "\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
