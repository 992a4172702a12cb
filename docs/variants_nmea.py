"""The perturbation suite's rewrites of NMEA logs (docs/real_variants.py): sentences
split and rebuilt with their checksums, the GNSS thinned or its times coarsened, a
magnetic heading without variation, other sentences and talkers, lines without
checksums or cut, gaps and a midnight, the log lagged, thinned, doubled or silent, THS,
$PASHR or VBW in place of what the log sent, and the tidal current's RMC."""

from __future__ import annotations

import bisect
import itertools
import math
import re
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from functools import reduce

from variants_csv import add_current

GAP_S = 300.0
"""The gap variant removes this many seconds of the log's middle."""

LAG_MATCH_S = 1.5
"""The lag variants take the reading nearest the lagged time within this, s."""

DROPOUT_EVERY_S = 300.0
"""The dropout variants lose their sentences once every this many seconds, s."""

DROPOUT_S = 30.0
"""For this long, s."""

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


def map_nmea(text: str, fn: Callable[[list[str]], list[str] | None]) -> str:
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


def thin_gnss(period_s: float) -> Callable[[str], str]:
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

        return map_nmea(text, fn)

    return apply


def coarse_times(resolution_s: float) -> Callable[[str], str]:
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

    return lambda text: map_nmea(text, fn)


def no_variation(f: list[str]) -> list[str]:
    """Every variation field emptied (HDG's deviation and variation, RMC's)."""
    k, g = kind_of(f), list(f)
    if k == "HDG":
        g[2:6] = ["", "", "", ""][: len(g[2:6])]
    elif k == "RMC" and len(g) > 11:
        g[10], g[11] = "", ""
    return g


def hdm(f: list[str]) -> list[str] | None:
    """HDG → HDM (the magnetic heading alone); other variations emptied."""
    if kind_of(f) == "HDG":
        return [f[0][:2] + "HDM", f[1], "M"]
    return no_variation(f)


def vhw_magnetic_only(f: list[str]) -> list[str] | None:
    """No heading sentence; VHW's true heading emptied; no variation anywhere."""
    k = kind_of(f)
    if k in ("HDG", "HDT", "HDM"):
        return None
    if k == "VHW" and len(f) > 2:
        g = list(f)
        g[1], g[2] = "", ""
        return no_variation(g)
    return no_variation(f)


def rmc_to(kinds: tuple[str, ...]) -> Callable[[list[str]], list[str] | None]:
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
        # several sentences from one: joined with a marker split by expand
        return ["\x00".join(",".join(x) for x in out)]

    return fn


def expand(text: str) -> str:
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


def other_sentences(text: str) -> str:
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


def rmc_course_empty_slow(f: list[str]) -> list[str]:
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


def rmc_course_empty(f: list[str]) -> list[str]:
    """RMC's course left empty at every speed (a receiver that never sends it)."""
    if kind_of(f) == "RMC" and len(f) > 8:
        g = list(f)
        g[8] = ""
        return g
    return f


def prefixed(text: str) -> str:
    """A receive time (ms since the log's start) and a tag before each sentence, as
    some loggers write them."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    return nl.join(f"{100 * i};N;{ln}" for i, ln in enumerate(text.splitlines())) + nl


def no_checksums(text: str) -> str:
    return re.sub(r"\*[0-9A-Fa-f]{2}(?=\r?$)", "", text, flags=re.MULTILINE)


def line_endings(nl: str) -> Callable[[str], str]:
    return lambda text: nl.join(text.splitlines()) + nl


def truncated(text: str) -> str:
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


def gap(text: str) -> str:
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

    return map_nmea(text, fn), t0 + shift


def midnight_gga(text: str) -> str:
    """The log across midnight with GGA + VTG fixes only (times of day, no date)."""
    shifted, _ = _shift_to_midnight(text)
    return expand(map_nmea(shifted, rmc_to(("GGA", "VTG"))))


def midnight_date(text: str) -> str:
    """The UTC date of :func:`midnight_gga`'s first fix (its ``--date``)."""
    return _shift_to_midnight(text)[1].date().isoformat()


def first_date(text: str) -> str:
    """The UTC date of the log's first RMC (``--date`` for a GGA-only variant)."""
    first = next(_fix_seconds(text), None)
    t = datetime.fromtimestamp(first[1], UTC) if first else datetime(2000, 1, 1, tzinfo=UTC)
    return t.date().isoformat()


def tidal_rmc(
    f: list[str], scale: float = 1.0, phase: float = 0.0, turn_deg: float = 0.0
) -> list[str]:
    """RMC's speed and course over ground with :func:`tide`'s current (times ``scale``,
    at ``phase`` of its cycle, its axis turned ``turn_deg``) added."""
    if kind_of(f) != "RMC" or len(f) < 9:
        return f
    t = _rmc_time(f)
    try:
        sog, cog = float(f[7]), float(f[8])
    except ValueError:
        return f
    if t is None:
        return f
    v, c = add_current(sog, cog, t.timestamp(), scale, phase, turn_deg)
    g = list(f)
    g[7], g[8] = f"{v:.2f}", f"{c:.1f}"
    return g


STRONG_TIDE = 2.0
"""The ``tide-strong`` variant's current, times the ``tide`` variant's (3 kn)."""

TIDE_PHASES = (0.0, 0.25, 0.5, 0.75)
"""The ``tide`` variant's hours met by the ``tide-pNN`` variants: fractions of its
12.42-h cycle later (0: the ``tide`` variant's own)."""

TIDE_TURNS_DEG = (0.0, 90.0)
"""... and its major axis north (``tide``'s) or turned to east (``-r90``)."""


def tide_hours() -> list[tuple[str, Callable[[str], str], str]]:
    """(name, rewrite, description) of the ``tide`` variant at the other phases and axes
    of :data:`TIDE_PHASES` × :data:`TIDE_TURNS_DEG`: one log meets a stream at one hour,
    so a rule chosen on one recording's tide is checked on the same tide met at other
    hours and across."""
    out = []
    for phase in TIDE_PHASES:
        for turn in TIDE_TURNS_DEG:
            if phase or turn:  # (0, 0): the ``tide`` variant
                name = "tide" + (f"-p{round(phase * 100)}" if phase else "")
                name += f"-r{turn:.0f}" if turn else ""

                def rewrite(text: str, p: float = phase, r: float = turn) -> str:
                    return expand(map_nmea(text, lambda f: tidal_rmc(f, 1.0, p, r)))

                doc = f"the 1.5-kn tide {phase:g} of its cycle later, its axis turned {turn:.0f}°"
                out.append((name, rewrite, doc))
    return out


def _line_times(lines: list[str]) -> list[float]:
    """Each line's time as ``emlogd import`` gives it: spread evenly between the RMC
    fixes around it (nan before the first fix and after the last)."""
    fixes = [(i, t) for i, t in _fix_seconds("\n".join(lines))]
    out = [math.nan] * len(lines)
    for (i0, t0), (i1, t1) in itertools.pairwise(fixes):
        for i in range(i0, i1):
            out[i] = t0 + (t1 - t0) * (i - i0) / (i1 - i0)
    return out


def lagged(lag_s: float) -> Callable[[str], str]:
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


def dropouts(kinds: frozenset[str]) -> Callable[[str], str]:
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


def vhw_every(n: int) -> Callable[[str], str]:
    """Every ``n``-th VHW kept (a log at 1/n of its rate)."""

    def apply(text: str) -> str:
        seen = [0]

        def fn(f: list[str]) -> list[str] | None:
            if kind_of(f) != "VHW":
                return f
            seen[0] += 1
            return f if seen[0] % n == 0 else None

        return map_nmea(text, fn)

    return apply


def vhw_twice(text: str) -> str:
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


def vhw_back_to_back(text: str) -> str:
    """Each VHW sent twice, the second right after the first (a log at twice the GNSS's
    rate behind a multiplexer that batches its sentences: two readings one line apart,
    then none until the next fix)."""
    nl = "\r\n" if "\r\n" in text[:4096] else "\n"
    out: list[str] = []
    for ln in text.splitlines():
        out.append(ln)
        f = fields(ln)
        if f is not None and kind_of(f) == "VHW":
            out.append(ln)
    return nl.join(out) + nl


def true_heading_as(make: Callable[[float], list[str]]) -> Callable[[list[str]], list[str] | None]:
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


def ths_of(hdg: float) -> list[str]:
    return ["GPTHS", f"{hdg:.1f}", "A"]


def pashr_of(hdg: float) -> list[str]:
    return ["PASHR", "", f"{hdg:.2f}", "T", "0.00", "0.00", "0.00", "0.1", "0.1", "0.2", "1", "0"]


def vbw(f: list[str]) -> list[str]:
    """VHW's speed sent as VBW's longitudinal water speed (the ground pair empty)."""
    if kind_of(f) == "VHW" and len(f) > 5 and f[5]:
        return [f[0][:2] + "VBW", f[5], "0.00", "A", "", "", "V"]
    return f
