"""The perturbation suite's rewrites of delimited logs (docs/real_variants.py): an
Expedition export's or a logger's table re-cut (columns renamed, dropped, reordered or
added; ``;`` with decimal commas, quoted cells, a byte-order mark; rows thinned;
Expedition's sparse log; the logger's other firmware; a row of units under the header
(knots and degrees, or SI units with the cells in them),
units in the names, NMEA field names, local OLE times) and the tidal current the
``tide`` variants add (:func:`tide`), which the NMEA rewrites use too."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from datetime import UTC, datetime, timedelta

TIDE_KN = 1.5
"""The ``tide`` variants' current along its major axis, kn (a strong tidal bay)."""

TIDE_PERIOD_S = 44_712.0
"""The ``tide`` variants' period: the semi-diurnal M2 tide's 12.42 h, s."""


def tide(
    t: float, scale: float = 1.0, phase: float = 0.0, turn_deg: float = 0.0
) -> tuple[float, float]:
    """The tidal current the ``tide`` variants add, (north, east) in knots at epoch
    seconds ``t``: a semi-diurnal ellipse of ``scale`` × :data:`TIDE_KN` along north and
    a third of it across, turning over :data:`TIDE_PERIOD_S`; ``phase`` (a fraction of
    the period) later in its cycle and its major axis turned ``turn_deg`` clockwise from
    north (the ``tide-pNN``/``-r90`` variants: the same log met at another hour of the
    tide, or in a stream across it)."""
    w = 2.0 * math.pi * (t + phase * TIDE_PERIOD_S) / TIDE_PERIOD_S
    n, e = scale * TIDE_KN * math.cos(w), scale * TIDE_KN / 3.0 * math.sin(w)
    if not turn_deg:
        return n, e
    r = math.radians(turn_deg)
    return n * math.cos(r) - e * math.sin(r), n * math.sin(r) + e * math.cos(r)


def add_current(
    sog_kn: float,
    cog_deg: float,
    t: float,
    scale: float = 1.0,
    phase: float = 0.0,
    turn_deg: float = 0.0,
) -> tuple[float, float]:
    """A ground velocity (knots, degrees) with :func:`tide`'s current added."""
    cn, ce = tide(t, scale, phase, turn_deg)
    a = math.radians(cog_deg)
    vn, ve = sog_kn * math.cos(a) + cn, sog_kn * math.sin(a) + ce
    return math.hypot(vn, ve), math.degrees(math.atan2(ve, vn)) % 360.0


def _table(text: str, delim: str) -> tuple[list[str], list[str], list[list[str]]]:
    """(banner lines, header, rows) of a delimited text whose header is the first line
    with the delimiter at least three times."""
    lines = text.lstrip("\ufeff").splitlines()
    h = next(i for i, ln in enumerate(lines) if ln.count(delim) >= 3)
    header = lines[h].split(delim)
    rows = [ln.split(delim) for ln in lines[h + 1 :] if ln.strip()]
    return lines[:h], header, rows


def _write(banner: list[str], header: list[str], rows: list[list[str]], delim: str) -> str:
    return "\n".join([*banner, delim.join(header), *(delim.join(r) for r in rows)]) + "\n"


Columns = Callable[[list[str], list[list[str]]], tuple[list[str], list[list[str]]]]
"""A rewrite of a table: (header, rows) → (header, rows)."""


def columns(fn: Columns) -> Callable[[str], str]:
    """A CSV variant from a function of (header, rows)."""

    def apply(text: str) -> str:
        banner, header, rows = _table(text, ",")
        header, rows = fn(header, rows)
        return _write(banner, header, rows, ",")

    return apply


def rename(names: dict[str, str]) -> Callable[[str], str]:
    return columns(lambda h, rows: ([names.get(c, c) for c in h], rows))


def drop(names: set[str]) -> Callable[[str], str]:
    def fn(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
        keep = [i for i, c in enumerate(h) if c not in names]
        return [h[i] for i in keep], [[r[i] if i < len(r) else "" for i in keep] for r in rows]

    return columns(fn)


def reverse(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    n = len(h)
    return h[::-1], [(r + [""] * (n - len(r)))[:n][::-1] for r in rows]


def extra(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    extra = ["Vmg", "TargBsp", "Polar%", "Mark Lat", "Notes"]
    return h + extra, [[*r, "1.0", "6.5", "93", "39.4", "tack"] for r in rows]


VARIATION_DEG = 8.0
"""The ``hdg-magnetic`` variant's variation, east positive (a Baltic one: large enough
that a magnetic heading taken as true would show in the heading check)."""


def magnetic_heading(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """``Hdg`` (true) rewritten as ``HdgMag`` (the compass's magnetic heading, true minus
    :data:`VARIATION_DEG`) beside a ``MagVar`` column."""
    hi = h.index("Hdg")
    for r in rows:
        with contextlib.suppress(ValueError, IndexError):
            r[hi] = f"{(float(r[hi]) - VARIATION_DEG) % 360.0:.1f}"
    head = [*h[:hi], "HdgMag", *h[hi + 1 :], "MagVar"]
    return head, [[*r, f"{VARIATION_DEG:.1f}"] for r in rows]


VALENCIA_MODEL_VARIATION_DEG = -1.26
"""The IGRF model's variation at the Valencia log's first position and time (39.400° N,
0.299° W, 2005-06-13; ``emlogd.pipeline.variation.model_variation``), degrees east."""


def magnetic_heading_alone(
    h: list[str], rows: list[list[str]]
) -> tuple[list[str], list[list[str]]]:
    """``Hdg`` rewritten as ``HdgMag``, the magnetic heading a compass there gives (true
    minus :data:`VALENCIA_MODEL_VARIATION_DEG`), and no variation column: the variation
    is the model's at the ``Lat``/``Lon`` positions."""
    hi = h.index("Hdg")
    for r in rows:
        with contextlib.suppress(ValueError, IndexError):
            r[hi] = f"{(float(r[hi]) - VALENCIA_MODEL_VARIATION_DEG) % 360.0:.1f}"
    return [*h[:hi], "HdgMag", *h[hi + 1 :]], rows


def subset(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """Only ``Cog``, ``Sog``, ``Hdg``, ``Bsp`` and ``Utc``, in that order (an export of
    the columns someone picked)."""
    keep = [h.index(c) for c in ("Cog", "Sog", "Hdg", "Bsp", "Utc")]
    return [h[i] for i in keep], [[r[i] if i < len(r) else "" for i in keep] for r in rows]


def duplicate_rows(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """Every row written twice (the same time twice: a re-export that joined two
    copies)."""
    return h, [list(x) for r in rows for x in (r, r)]


def sparse_gnss(period_s: float) -> Callable[[str], str]:
    """Expedition rows whose Sog/Cog (and Lat/Lon) cells are written only every
    ``period_s`` (a slower GNSS): the other rows leave them empty."""

    def fn(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
        idx = [h.index(c) for c in ("Sog", "Cog", "Lat", "Lon") if c in h]
        t_kept = -math.inf
        for r in rows:
            try:
                t = float(r[h.index("Utc")]) * 86400.0
            except (ValueError, IndexError):
                continue
            if t >= t_kept + period_s - 0.05:
                t_kept = t
                continue
            for i in idx:
                if i < len(r):
                    r[i] = ""
        return h, rows

    return columns(fn)


def tidal_cells(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """Sog and Cog cells with :func:`tide`'s current added (rows whose cells are empty
    keep them empty)."""
    ti, si, ci = h.index("Utc"), h.index("Sog"), h.index("Cog")
    for r in rows:
        try:
            t = (float(r[ti]) - 25569.0) * 86400.0
            sog, cog = float(r[si]), float(r[ci])
        except (ValueError, IndexError):
            continue
        v, c = add_current(sog, cog, t)
        r[si], r[ci] = f"{v:.2f}", f"{c:.1f}"
    return h, rows


def semicolon(text: str) -> str:
    """``;`` delimiter and decimal commas (a European spreadsheet's export)."""
    banner, header, rows = _table(text, ",")
    rows = [[c.replace(".", ",") for c in r] for r in rows]
    return _write(banner, header, rows, ";")


def quoted(text: str) -> str:
    banner, header, rows = _table(text, ",")
    q = [[f'"{c}"' for c in r] for r in [header, *rows]]
    return _write(banner, q[0], q[1:], ",")


def bom_crlf(text: str) -> str:
    return "\ufeff" + "\r\n".join(text.splitlines()) + "\r\n"


EXPEDITION_CHANNELS = {
    "Utc": 0,
    "Bsp": 1,
    "Awa": 2,
    "Aws": 3,
    "Twa": 4,
    "Tws": 5,
    "Twd": 6,
    "Leeway": 10,
    "iSet": 11,
    "iDrift": 12,
    "Hdg": 13,
    "Depth": 17,
    "Heel": 18,
    "Lat": 48,
    "Lon": 49,
    "Cog": 50,
    "Sog": 51,
}
"""Expedition's channel numbers of the columns the sparse variant writes."""

SPARSE_NAMES = {"Bsp": "BSP", "Hdg": "HDG", "Cog": "COG", "Sog": "SOG", "iSet": "Set"}
SPARSE_NAMES |= {"iDrift": "Drift", "Awa": "AWA", "Aws": "AWS", "Twa": "TWA", "Tws": "TWS"}
SPARSE_NAMES |= {"Twd": "TWD"}


def expedition_log(text: str) -> str:
    """Expedition's own sparse log: a ``!Boat`` line of names, a ``!boat`` line of
    channel numbers, a version line, then rows ``boat,utc,channel,value,...`` holding
    only the written cells."""
    _, header, rows = _table(text, ",")
    have = [c for c in header if c in EXPEDITION_CHANNELS]
    names = ",".join(SPARSE_NAMES.get(c, c) for c in have)
    numbers = ",".join(str(EXPEDITION_CHANNELS[c]) for c in have)
    out = [f"!Boat,{names}", f"!boat,{numbers}", "!v10.5.3"]
    ti = header.index("Utc")
    for r in rows:
        pairs = [
            f"{EXPEDITION_CHANNELS[c]},{r[i]}"
            for i, c in enumerate(header)
            if c in EXPEDITION_CHANNELS and c != "Utc" and i < len(r) and r[i] != ""
        ]
        out.append(",".join(["0", r[ti], *pairs]))
    return "\r\n".join(out) + "\r\n"


# ------------------------------------------------------------------ TSV helpers


def no_banner(text: str) -> str:
    lines = text.splitlines(keepends=True)
    h = next(i for i, ln in enumerate(lines) if ln.count("\t") >= 3)
    return "".join(lines[h:])


LOGGER_NAMES = {
    "Boatspeed": "BS",
    "Heading": "HDG",
    "Ext_SOG": "SOG",
    "Ext_COG": "COG",
    "Latitudine": "Lat",
    "Longitudine": "Lon",
    "SET": "Set",
    "DRIFT": "Drift",
}
"""The logger's other firmware's column names."""

SETTINGS_LINES = 48
"""The other firmware's banner: this many lines of settings before the header."""


def logger_firmware(text: str) -> str:
    """The logger's other firmware: its own column names, a banner of settings (section
    rulers, ``NAME:<TAB>value`` lines, tables with tabs and commas) before the header,
    and ``-`` for the current in the first hundred rows."""
    lines = text.splitlines()
    h = next(i for i, ln in enumerate(lines) if ln.count("\t") >= 3)
    header = [LOGGER_NAMES.get(c, c) for c in lines[h].split("\t")]
    banner = ["-------- DAMPING --------"]
    banner += [f"CH{k}:\t0.{600 + k}" for k in range(SETTINGS_LINES // 2)]
    banner += ["-------- CALIBRATION --------"]
    banner += [
        f"POINT {k}: {k}.0\t GAIN: 1.{k:03d}\tCURVE:\t0.0,0.0,0.0"
        for k in range(SETTINGS_LINES // 2)
    ]
    banner += ["-------- LOG --------"]
    sd = [header.index("Set"), header.index("Drift")]
    rows = []
    for n, ln in enumerate(lines[h + 1 :]):
        cells = ln.split("\t")
        if n < 100:
            for i in sd:
                if i < len(cells):
                    cells[i] = "-"
        rows.append("\t".join(cells))
    return "\r\n".join([*lines[:h], *banner, "\t".join(header), *rows]) + "\r\n"


def thin_rows(period_s: float) -> Callable[[str], str]:
    """A TSV's rows kept only ``period_s`` apart (by their Time column)."""

    def apply(text: str) -> str:
        lines = text.splitlines(keepends=True)
        h = next(i for i, ln in enumerate(lines) if ln.count("\t") >= 3)
        ti = lines[h].split("\t").index("Time")
        kept, t_kept = lines[: h + 1], -math.inf
        for ln in lines[h + 1 :]:
            cells = ln.split("\t")
            try:
                hh, mm, ss = (int(x) for x in cells[ti].split(":"))
            except (ValueError, IndexError):
                continue
            t = hh * 3600 + mm * 60 + ss
            t = t if t >= t_kept else t + 86400
            if t >= t_kept + period_s:
                kept.append(ln)
                t_kept = t
        return "".join(kept)

    return apply


OLE_EPOCH = datetime(1899, 12, 30, tzinfo=UTC)
"""Day 0 of the OLE dates in Expedition's ``Utc``."""


def utc_text(pattern: str) -> Columns:
    """``Utc`` written as text with a ``strftime`` pattern instead of an OLE date."""

    def fn(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
        i = h.index("Utc")
        for r in rows:
            try:
                r[i] = (OLE_EPOCH + timedelta(days=float(r[i]))).strftime(pattern)
            except (ValueError, IndexError):
                continue
        return h, rows

    return fn


def date_time_columns(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """``Utc`` replaced by ``Date`` (dd/mm/yyyy) and ``Time`` (hh:mm:ss.ff) columns first."""
    return _split_utc(h, rows, ("Date", "Time"), "%d/%m/%Y")


def utc_date_time(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """``Utc`` replaced by ``UtcDate`` (ISO) and ``UtcTime`` (hh:mm:ss.ff) columns first
    (another navigation program's export)."""
    return _split_utc(h, rows, ("UtcDate", "UtcTime"), "%Y-%m-%d")


def _split_utc(
    h: list[str], rows: list[list[str]], names: tuple[str, str], day: str
) -> tuple[list[str], list[list[str]]]:
    """``Utc`` replaced by a date column (``day``, a strftime pattern) and a time of day
    column (hh:mm:ss.ff), named ``names``, first."""
    i = h.index("Utc")
    out = []
    for r in rows:
        try:
            t = OLE_EPOCH + timedelta(days=float(r[i]))
        except (ValueError, IndexError):
            continue
        clock = f"{t:%H:%M:%S}.{t.microsecond // 10_000:02d}"
        out.append([t.strftime(day), clock, *r[:i], *r[i + 1 :]])
    return [*names, *h[:i], *h[i + 1 :]], out


def tsv_dates(pattern: str) -> Callable[[str], str]:
    """The logger's ``Date`` (dd/mm/yy) written with another ``strftime`` pattern."""

    def apply(text: str) -> str:
        out = []
        for ln in text.splitlines(keepends=True):
            cells = ln.split("\t")
            with contextlib.suppress(ValueError):
                cells[0] = datetime.strptime(cells[0], "%d/%m/%y").strftime(pattern)
            out.append("\t".join(cells))
        return "".join(out)

    return apply


def tsv_fraction(text: str) -> str:
    """The logger's ``Time`` with tenths of a second (``12:39:06.0``)."""
    out = []
    for ln in text.splitlines(keepends=True):
        cells = ln.split("\t")
        if len(cells) > 1 and cells[1].count(":") == 2:
            cells[1] += ".0"
        out.append("\t".join(cells))
    return "".join(out)


UNITS = {"Utc": "days", "Bsp": "kt", "Hdg": "degT", "Sog": "kt", "Cog": "degT", "Lat": "deg"}
"""The units row's cells, by column (the rest empty)."""


def units_row(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """A row of units under the header (a spreadsheet's or a logger's second header)."""
    return h, [[UNITS.get(c, "") for c in h], *rows]


KNOT_MPS = 1852.0 / 3600.0
RAD = math.pi / 180.0
SI_UNITS = {
    "Bsp": ("m/s", KNOT_MPS),
    "Sog": ("m/s", KNOT_MPS),
    "Hdg": ("rad", RAD),
    "Cog": ("rad", RAD),
}
"""The SI units row's columns: (unit, the factor from the export's knots or degrees)."""


def units_row_si(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """A row of SI units under the header (``m/s``, ``rad``: a logger of Signal K's
    units) and the speed and angle cells written in them."""
    at = {h.index(c): f for c, (_, f) in SI_UNITS.items() if c in h}
    out = []
    for r in rows:
        g = list(r)
        for i, f in at.items():
            if i < len(g) and g[i]:
                g[i] = f"{float(g[i]) * f:.6f}"
        out.append(g)
    units = [SI_UNITS[c][0] if c in SI_UNITS else UNITS.get(c, "") for c in h]
    return h, [units, *out]


LOCAL_OFFSET_H = 2.0
"""The local-time variant's clock minus UTC, h (Valencia in June: CEST)."""


def ole_local(h: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    """``Utc`` as OLE days of local time, :data:`LOCAL_OFFSET_H` ahead (its exact value:
    the ``--utc-offset`` given takes it back)."""
    i = h.index("Utc")
    out = []
    for r in rows:
        g = list(r)
        if i < len(g) and g[i]:
            g[i] = repr(float(g[i]) + LOCAL_OFFSET_H / 24.0)
        out.append(g)
    return h, out


NMEA_NAMES = {
    "Utc": "UTC",
    "Bsp": "SOW",
    "Hdg": "HDT",
    "Sog": "SOG",
    "Cog": "COG",
    "Twd": "TWD",
    "iSet": "SET",
    "iDrift": "DRIFT",
    "Lat": "LAT",
    "Lon": "LON",
}
"""Another logger's names: the NMEA fields' (``SOW`` speed over water, ``HDT``)."""

NAME_UNITS = {"Bsp": "Bsp (kt)", "Hdg": "Hdg (°T)", "Sog": "Sog (kt)", "Cog": "Cog (°T)"}
"""Units in the names, as a spreadsheet writes them (``°T``: true)."""
