"""The perturbation suite's rewrites of an NMEA log's lines (docs/real_variants.py), as
loggers and plotters other than the source's write them: a receive time before each
sentence in other formats (ISO 8601, epoch seconds, a clock time alone, tab-separated,
in brackets), NMEA 4 tag blocks, NULs padding the lines and the file, sentences split
over two lines, AIS sentences mixed in, every line logged twice, RMC without its date
(with ``--date``, also across midnight) and RMC across midnight with its dates."""

from __future__ import annotations

import math
from collections.abc import Callable
from datetime import UTC, datetime

from variants_nmea import _line_times, _shift_to_midnight, checksum, fields, kind_of, map_nmea

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
