"""The perturbation suite's rewrites of an NMEA log's lines (docs/real_variants.py), as
loggers and plotters other than the source's write them: a receive time before each
sentence in other formats (ISO 8601, epoch seconds, a clock time alone, tab-separated,
in brackets), NMEA 4 tag blocks, NULs padding the lines and the file, sentences split
over two lines, AIS sentences mixed in, every line logged twice, RMC without its date
(with ``--date``, also across midnight) and RMC across midnight with its dates; two
sessions of one day in one file, a receiver's clock set back an hour, midnight with
RMC's date advancing late, a leap second at midnight, fix times a second late
now and then, an hour moored before the start, variations signed without E/W, VHW in
km/h alone, HDM with the variation in RMC alone."""

from __future__ import annotations

import math
from collections.abc import Callable
from datetime import UTC, datetime, timedelta

from variants_nmea import (
    _fix_seconds,
    _hhmmss,
    _line_times,
    _rmc_time,
    _shift_to_midnight,
    checksum,
    fields,
    kind_of,
    map_nmea,
    sentence,
)

SPLIT_EVERY = 7
"""The split variant cuts every this-many-th sentence in two lines."""

AIS_EVERY = 5
"""The AIS variant writes an AIS sentence after every this-many-th line."""

AIS_PAYLOAD = "!AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0"
"""An AIS position report's sentence without its checksum (the one the AIS variant
mixes in)."""

NUL_PAD = 16
"""The NUL variant pads every line with this many NULs (and the file with 64 times as
many)."""


def _newline(text: str) -> str:
    return "\r\n" if "\r\n" in text[:4096] else "\n"


def _filled_times(lines: list[str]) -> list[float]:
    """:func:`variants_nmea._line_times`, the lines before the first fix given its time
    and those after the last the last fix's (a logger's clock runs there too)."""
    times = _line_times(lines)
    known = [t for t in times if not math.isnan(t)]
    if not known:
        return [0.0] * len(lines)
    out, last = [], known[0]
    for t in times:
        last = last if math.isnan(t) else t
        out.append(last)
    return out


STAMPS: dict[str, Callable[[float], str]] = {
    "iso": lambda t: datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")[:-6] + "Z ",
    "epoch": lambda t: f"{t:.3f} ",
    "clock": lambda t: datetime.fromtimestamp(t, UTC).strftime("%H:%M:%S.%f")[:-3] + " ",
    "tab": lambda t: f"{t:.3f}\t",
    "bracket": lambda t: (
        "[" + datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + "] "
    ),
    "angle": lambda t: f"<{round(t * 1000.0)}> ",
    "tag-block": lambda t: f"\\{(b := f's:GP0001,c:{int(t)}')}*{checksum(b)}\\",
}
"""The receive-time prefixes, by name (a function of the line's epoch seconds)."""


def stamped(name: str) -> Callable[[str], str]:
    """Each line with the receive time :data:`STAMPS` names before its sentence."""
    stamp = STAMPS[name]

    def apply(text: str) -> str:
        nl = _newline(text)
        lines = text.splitlines()
        return (
            nl.join(stamp(t) + ln for t, ln in zip(_filled_times(lines), lines, strict=True)) + nl
        )

    return apply


OPENCPN_HEADER = (
    "# timestamp_format: EPOCH_MILLIS",
    "received_at,protocol,msg_type,source,raw_data",
)
"""The first lines of OpenCPN's data log in CSV (its time format, then the columns)."""


def opencpn_csv(text: str) -> str:
    """The log as OpenCPN's data log in CSV: a row per sentence of its receive time in
    epoch milliseconds, the protocol, the sentence's address, the source, and the
    sentence last, quoted (it holds the delimiter)."""
    nl = _newline(text)
    lines = text.splitlines()
    rows = [
        f'{round(t * 1000.0)},NMEA0183,{ln[1:6]},ttyUSB0,"{ln}"'
        for t, ln in zip(_filled_times(lines), lines, strict=True)
    ]
    return nl.join([*OPENCPN_HEADER, *rows]) + nl


def nul_padded(text: str) -> str:
    """:data:`NUL_PAD` NULs after every line, and a block of NULs ending the file (a
    logger's buffer and its file written in fixed blocks)."""
    nl = _newline(text)
    pad = "\x00" * NUL_PAD
    return nl.join(ln + pad for ln in text.splitlines()) + nl + pad * 64


def split_lines(text: str) -> str:
    """Every :data:`SPLIT_EVERY`-th sentence cut in two lines at its middle (a buffer
    flushed mid-sentence)."""
    nl = _newline(text)
    out: list[str] = []
    for i, ln in enumerate(text.splitlines()):
        if i % SPLIT_EVERY == 0 and fields(ln) is not None and len(ln) > 12:
            half = len(ln) // 2
            out += [ln[:half], ln[half:]]
        else:
            out.append(ln)
    return nl.join(out) + nl


def with_ais(text: str) -> str:
    """An AIS sentence (``!AIVDM``) after every :data:`AIS_EVERY`-th line."""
    nl = _newline(text)
    ais = f"{AIS_PAYLOAD}*{checksum(AIS_PAYLOAD[1:])}"
    out: list[str] = []
    for i, ln in enumerate(text.splitlines()):
        out.append(ln)
        if i % AIS_EVERY == 0:
            out.append(ais)
    return nl.join(out) + nl


def doubled(text: str) -> str:
    """Every line logged twice (two inputs of one multiplexer logged together)."""
    nl = _newline(text)
    return nl.join(ln + nl + ln for ln in text.splitlines()) + nl


def _no_date(f: list[str]) -> list[str]:
    if kind_of(f) != "RMC" or len(f) < 10:
        return f
    return [*f[:9], "", *f[10:]]


def rmc_no_date(text: str) -> str:
    """RMC's date field empty (a receiver or a converter that leaves it out)."""
    return map_nmea(text, _no_date)


def midnight_rmc(text: str) -> str:
    """The log across midnight, RMC with its dates (a recording over two days)."""
    return _shift_to_midnight(text)[0]


def midnight_rmc_no_date(text: str) -> str:
    """The log across midnight, RMC without its date (``--date`` the first fix's)."""
    return map_nmea(_shift_to_midnight(text)[0], _no_date)


SESSION_GAP_S = 3 * 3600.0
"""The two-sessions variant starts its second half this much later, s."""

LATE_FIX_EVERY = 5
"""The late-fix variant labels every this-many-th fix a second late (a receiver's time
tag jittering by a second)."""

MOORED_S = 3600.0
"""The moored variant adds this long at rest before the log's first fix, s."""


def _decimals(hms: str) -> int:
    """The decimals of a time field (``132220.50``: 2)."""
    return len(hms.partition(".")[2])


def _retimed(text: str, when: Callable[[int, datetime], datetime]) -> str:
    """Each RMC's time and date replaced by ``when`` (of the fix's index and time); GGA,
    GLL and ZDA left out (their times would contradict)."""
    count = [0]

    def fn(f: list[str]) -> list[str] | None:
        k = kind_of(f)
        if k in ("GGA", "GLL", "ZDA"):
            return None
        t = _rmc_time(f) if k == "RMC" else None
        if t is None:
            return f
        count[0] += 1
        new = when(count[0] - 1, t)
        g = list(f)
        g[1] = _hhmmss(new, _decimals(f[1]))
        g[9] = f"{new.day:02d}{new.month:02d}{new.year % 100:02d}"
        return g

    return map_nmea(text, fn)


def two_sessions(text: str) -> str:
    """The log's second half :data:`SESSION_GAP_S` later (two sessions of one day logged
    into one file)."""
    fixes = [t for _, t in _fix_seconds(text)]
    mid = fixes[len(fixes) // 2] if fixes else 0.0
    gap = timedelta(seconds=SESSION_GAP_S)
    return _retimed(text, lambda _i, t: t + gap if t.timestamp() >= mid else t)


RESET_BACK_S = 3600.0
"""The time-reset variant's fixes go back this much from the log's middle on, s."""

DATE_LATE_S = 5.0
"""The midnight-date-late variant's RMC keep the day before's date this long after
midnight, s."""


def time_reset(text: str) -> str:
    """From the log's middle on, every fix :data:`RESET_BACK_S` earlier (a receiver reset
    that set its clock back, with its date)."""
    fixes = [t for _, t in _fix_seconds(text)]
    mid = fixes[len(fixes) // 2] if fixes else 0.0
    back = timedelta(seconds=RESET_BACK_S)
    return _retimed(text, lambda _i, t: t - back if t.timestamp() >= mid else t)


def _across_midnight(text: str) -> tuple[str, datetime | None]:
    """The log shifted to cross midnight (:func:`_shift_to_midnight`) and its first fix's
    time (None: no fix)."""
    shifted, _ = _shift_to_midnight(text)
    fixes = [t for _, t in _fix_seconds(shifted)]
    return shifted, datetime.fromtimestamp(fixes[0], UTC) if fixes else None


def midnight_date_late(text: str) -> str:
    """The log across midnight, RMC's date advancing only :data:`DATE_LATE_S` after it
    (a receiver latching the date late: its time rolls over, its date stays)."""
    shifted, t0 = _across_midnight(text)
    if t0 is None:
        return shifted
    midnight = datetime(t0.year, t0.month, t0.day, tzinfo=UTC) + timedelta(days=1)
    late = midnight + timedelta(seconds=DATE_LATE_S)

    def fn(f: list[str]) -> list[str] | None:
        t = _rmc_time(f) if kind_of(f) == "RMC" else None
        if t is None or not midnight <= t < late:
            return f
        g = list(f)
        g[9] = f"{t0.day:02d}{t0.month:02d}{t0.year % 100:02d}"
        return g

    return map_nmea(shifted, fn)


def leap_second(text: str) -> str:
    """The log across midnight with a leap second: ``23:59:60`` between ``23:59:59``
    and ``00:00:00``, the later fixes labelled a second earlier."""
    shifted, t0 = _across_midnight(text)
    if t0 is None:
        return shifted
    midnight = datetime(t0.year, t0.month, t0.day, tzinfo=UTC) + timedelta(days=1)

    def fn(f: list[str]) -> list[str] | None:
        t = _rmc_time(f) if kind_of(f) == "RMC" else None
        if t is None or t < midnight:
            return f
        g, n = list(f), _decimals(f[1])
        t = t - timedelta(seconds=1)
        if t < midnight:  # the inserted second: 23:59:60 of the day before
            g[1] = _hhmmss(t, n).replace("235959", "235960", 1)
            g[9] = f"{t.day:02d}{t.month:02d}{t.year % 100:02d}"
        else:
            g[1] = _hhmmss(t, n)
        return g

    return map_nmea(shifted, fn)


def late_fixes(text: str) -> str:
    """Every :data:`LATE_FIX_EVERY`-th fix's time a second late (equal to the next
    fix's at 1 Hz)."""
    late = timedelta(seconds=1)
    return _retimed(text, lambda i, t: t + late if i % LATE_FIX_EVERY == 2 else t)


def moored(text: str) -> str:
    """:data:`MOORED_S` at rest before the first fix: each second the first fix's
    sentences again, the speeds over ground and through the water 0, the heading and
    position the first fix's."""
    lines = text.splitlines()
    at = [i for i, _ in _fix_seconds(text)]
    if len(at) < 2:
        return text
    first = _rmc_time(fields(lines[at[0]]) or [])
    if first is None:
        return text
    cycle = [fields(ln) for ln in lines[at[0] : at[1]]]
    out: list[str] = []
    for k in range(int(MOORED_S)):
        t = first - timedelta(seconds=MOORED_S - k)
        for f in cycle:
            if f is None:
                continue
            g, kind = list(f), kind_of(f)
            if kind == "RMC":
                g[1], g[7] = _hhmmss(t, _decimals(f[1])), "0.0"
                g[9] = f"{t.day:02d}{t.month:02d}{t.year % 100:02d}"
            elif kind == "VHW" and len(g) > 7:
                g[5] = "00.0" if g[5] else g[5]
                g[7] = "0.0" if g[7] else g[7]
            out.append(sentence(",".join(g)))
    nl = _newline(text)
    return nl.join(out) + nl + text


def signed_variation(f: list[str]) -> list[str]:
    """RMC's and HDG's variation written signed (west negative), the E/W field empty."""
    g = list(f)
    at = {"RMC": 10, "HDG": 4}.get(kind_of(f))
    if at is not None and len(g) > at + 1 and g[at]:
        g[at], g[at + 1] = ("-" if g[at + 1] == "W" else "") + g[at], ""
    return g


def vhw_kmh_only(f: list[str]) -> list[str]:
    """VHW's speed in its km/h field alone (the knots field empty)."""
    if kind_of(f) != "VHW" or len(f) < 9 or not f[5]:
        return f
    return [*f[:5], "", "", f"{float(f[5]) * 1.852:.1f}", "K", *f[9:]]


def hdm_rmc_variation(f: list[str]) -> list[str] | None:
    """HDG sent as HDM (its variation lost) and VHW without headings: the magnetic
    heading alone, the variation only in RMC's field."""
    k = kind_of(f)
    if k == "HDG":
        return [f[0][:2] + "HDM", f[1], "M"]
    if k == "VHW" and len(f) > 4:
        return [f[0], "", "", "", "", *f[5:]]
    return f
