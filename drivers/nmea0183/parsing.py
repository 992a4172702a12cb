"""NMEA 0183 fields and sentences: the field rules and one parser per sentence.

Each parser takes the talker, the fields after the address and the raw frame, and
returns a record or raises a :class:`~drivers.errors.FrameError` naming the reject
reason (see the package's docstring for the rules).

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from datetime import UTC, date, datetime, timedelta

from drivers.errors import FieldError, OutOfRangeError, UnknownSentenceError
from drivers.nmea0183.records import (
    Gga,
    Gll,
    Heading,
    Mtw,
    Prti,
    Rmc,
    Vbw,
    Vdr,
    Vhw,
    Vlw,
    Vtg,
    Zda,
)
from drivers.records import KMH_MPS, KNOT_MPS, MAX_DEPTH_M, WATER_TEMP_RANGE_C

MAX_SPEED_MPS = 40.0
"""Largest plausible speed of a survey vehicle (~78 kn); beyond is out_of_range."""

MAX_OFFSET_DEG = 180.0
"""Largest magnitude of a deviation or variation (HDG, RMC); beyond is out_of_range."""

MAX_HDOP = 99.9
"""Largest horizontal dilution of precision a GGA field can hold (``99.9``)."""

MAX_SATELLITES = 99
"""Largest satellite count a GGA field can hold (two digits)."""

MAX_FIX_QUALITY = 9
"""Largest GGA fix-quality indicator (0 no fix .. 8 simulator, 9 WAAS on some receivers)."""

ZDA_YEARS = (1980, 2199)
"""Years a ZDA date may name (GNSS time starts in 1980); outside is out_of_range."""

UNITS_ROUNDING = 1.5
"""VHW knots/km/h: how many units of the coarser field's last decimal the pair may
differ by (each is rounded to its own decimals) before it is refused."""

UNITS_RELATIVE = 0.01
"""VHW knots/km/h: relative difference allowed on top of :data:`UNITS_ROUNDING`."""

PRTI_INVALID = -99999
"""Rowe's invalid-velocity marker in $PRTI sentences (mm/s)."""


# ------------------------------------------------------------------ field helpers


def _num(field: str, name: str, raw: bytes) -> float | None:
    """An optional decimal field: None when empty, else a finite float."""
    if not field:
        return None
    try:
        x = float(field)
    except ValueError:
        raise FieldError(f"{name}: {field!r} is not a number", raw) from None
    if not math.isfinite(x) or field.strip() != field or "_" in field:
        raise FieldError(f"{name}: {field!r} is not a number", raw)
    return x


def _flag(field: str, allowed: str, name: str, raw: bytes) -> str:
    if field and field not in allowed:
        raise FieldError(f"{name}: flag {field!r}, expected {allowed} or empty", raw)
    return field


def _heading(x: float | None, name: str, raw: bytes) -> float | None:
    """A direction: within 0..360 as sent, returned in [0, 360) (360 reads as 0)."""
    if x is None:
        return None
    if not 0.0 <= x <= 360.0:
        raise OutOfRangeError(f"{name} {x} outside 0..360", raw)
    return 0.0 if x == 360.0 else x


def _offset(x: float | None, name: str, raw: bytes) -> float | None:
    """A deviation or variation: within ±:data:`MAX_OFFSET_DEG`."""
    if x is not None and not -MAX_OFFSET_DEG <= x <= MAX_OFFSET_DEG:
        raise OutOfRangeError(f"{name} {x} beyond ±{MAX_OFFSET_DEG:g}", raw)
    return x


def _temperature(x: float | None, name: str, raw: bytes) -> float | None:
    lo, hi = WATER_TEMP_RANGE_C
    if x is not None and not lo <= x <= hi:
        raise OutOfRangeError(f"{name} {x} °C outside {lo:g}..{hi:g}", raw)
    return x


def _speed(x: float | None, name: str, raw: bytes) -> float | None:
    if x is not None and abs(x) > MAX_SPEED_MPS:
        raise OutOfRangeError(f"{name} {x:.2f} m/s beyond ±{MAX_SPEED_MPS:g}", raw)
    return x


def _kn(x: float | None) -> float | None:
    return None if x is None else x * KNOT_MPS


def _status(field: str, name: str, raw: bytes) -> bool:
    if field not in ("A", "V", ""):
        raise FieldError(f"{name}: status {field!r}, expected A or V", raw)
    return field == "A"


# ------------------------------------------------------------------ sentence parsers


def parse_vhw(talker: str, f: list[str], raw: bytes) -> Vhw:
    """Fields after the address of a VHW sentence."""
    if len(f) != 8:
        raise FieldError(f"VHW has {len(f)} fields, expected 8", raw)
    ht = _heading(_num(f[0], "heading true", raw), "heading true", raw)
    _flag(f[1], "T", "VHW field 2", raw)
    hm = _heading(_num(f[2], "heading magnetic", raw), "heading magnetic", raw)
    _flag(f[3], "M", "VHW field 4", raw)
    kn = _num(f[4], "speed knots", raw)
    _flag(f[5], "N", "VHW field 6", raw)
    kmh = _num(f[6], "speed km/h", raw)
    _flag(f[7], "K", "VHW field 8", raw)
    mps = kn * KNOT_MPS if kn is not None else (kmh * KMH_MPS if kmh is not None else None)
    _speed(mps, "STW", raw)
    if kn is not None and kmh is not None:
        _speed(kmh * KMH_MPS, "STW km/h", raw)
        if _units_disagree(kn, kmh, f[4], f[6]):
            raise OutOfRangeError(f"VHW speed {kn} kn and {kmh} km/h disagree", raw)
    return Vhw(
        talker=talker,
        heading_true_deg=ht,
        heading_mag_deg=hm,
        stw_knots=kn,
        stw_kmh=kmh,
        stw_mps=mps,
    )


def _units_disagree(kn: float, kmh: float, kn_field: str, kmh_field: str) -> bool:
    """Knots and km/h further apart than their rounding allows."""
    # each field is rounded to its own decimals: allow a unit and a half of the coarser one
    decimals = min(_decimals(kn_field), _decimals(kmh_field))
    tol_kmh = UNITS_ROUNDING * 10.0**-decimals * 1.852 + UNITS_RELATIVE * abs(kmh)
    return abs(kn * 1.852 - kmh) > tol_kmh


def _decimals(field: str) -> int:
    _, _, frac = field.partition(".")
    return len(frac)


def parse_vbw(talker: str, f: list[str], raw: bytes) -> Vbw:
    """Fields after the address of a VBW sentence (6 or 10 fields)."""
    if len(f) not in (6, 10):
        raise FieldError(f"VBW has {len(f)} fields, expected 6 or 10", raw)
    wl = _speed(_kn(_num(f[0], "water longitudinal", raw)), "water longitudinal", raw)
    wt = _speed(_kn(_num(f[1], "water transverse", raw)), "water transverse", raw)
    wv = _status(f[2], "water status", raw)
    gl = _speed(_kn(_num(f[3], "ground longitudinal", raw)), "ground longitudinal", raw)
    gt = _speed(_kn(_num(f[4], "ground transverse", raw)), "ground transverse", raw)
    gv = _status(f[5], "ground status", raw)
    sw = sg = None
    swv = sgv = False
    if len(f) == 10:
        sw = _speed(_kn(_num(f[6], "stern water", raw)), "stern water", raw)
        swv = _status(f[7], "stern water status", raw) and sw is not None
        sg = _speed(_kn(_num(f[8], "stern ground", raw)), "stern ground", raw)
        sgv = _status(f[9], "stern ground status", raw) and sg is not None
    return Vbw(
        talker=talker,
        water_long_mps=wl,
        water_trans_mps=wt,
        water_valid=wv and wl is not None,
        ground_long_mps=gl,
        ground_trans_mps=gt,
        ground_valid=gv and gl is not None,
        stern_water_mps=sw,
        stern_water_valid=swv,
        stern_ground_mps=sg,
        stern_ground_valid=sgv,
    )


def parse_vlw(talker: str, f: list[str], raw: bytes) -> Vlw:
    """VLW: total and trip distance through the water, N (4 fields); NMEA 3 adds the
    ground pair (8 fields)."""
    if len(f) not in (4, 8):
        raise FieldError(f"VLW has {len(f)} fields, expected 4 or 8", raw)
    for i in range(1, len(f), 2):
        _flag(f[i], "N", f"VLW field {i + 1}", raw)
    total = _num(f[0], "VLW total", raw)
    trip = _num(f[2], "VLW trip", raw)
    ground_total = _num(f[4], "VLW ground total", raw) if len(f) == 8 else None
    ground_trip = _num(f[6], "VLW ground trip", raw) if len(f) == 8 else None
    for x, name in (
        (total, "total"),
        (trip, "trip"),
        (ground_total, "ground total"),
        (ground_trip, "ground trip"),
    ):
        if x is not None and x < 0:
            raise OutOfRangeError(f"VLW {name} distance {x} < 0", raw)
    return Vlw(
        talker=talker,
        total_nm=total,
        trip_nm=trip,
        ground_total_nm=ground_total,
        ground_trip_nm=ground_trip,
    )


def parse_mtw(talker: str, f: list[str], raw: bytes) -> Mtw:
    """MTW: temperature, C (2 fields)."""
    if len(f) != 2:
        raise FieldError(f"MTW has {len(f)} fields, expected 2", raw)
    _flag(f[1], "C", "MTW unit", raw)
    temp = _num(f[0], "MTW temperature", raw)
    return Mtw(talker=talker, temperature_c=_temperature(temp, "water temperature", raw))


def _signed(value: float | None, direction: str, name: str, raw: bytes) -> float | None:
    _flag(direction, "EW", name, raw)
    if value is None:
        return None
    return -value if direction == "W" else value


HEADING_FIELDS = {"HDT": 2, "HDM": 2, "HDG": 5, "THS": 2}
"""The heading sentences and how many fields follow their address."""

THS_VALID_MODES = frozenset("AEM")
"""THS modes whose heading is the ship's: autonomous, estimated (dead reckoning),
manual input. ``S`` (simulator) and ``V`` (not valid) give no heading."""


def parse_heading(kind: str, talker: str, f: list[str], raw: bytes) -> Heading:
    """HDT (heading, T), HDM (heading, M), HDG (sensor heading, deviation, E/W,
    variation, E/W) or THS (true heading, mode: a GNSS compass's or an INS's HDT of
    NMEA 0183 v3.01 on; the heading is None in a mode outside :data:`THS_VALID_MODES`)."""
    expected = HEADING_FIELDS[kind]
    if len(f) != expected:
        raise FieldError(f"{kind} has {len(f)} fields, expected {expected}", raw)
    heading = _heading(_num(f[0], f"{kind} heading", raw), kind, raw)
    if kind == "THS":
        _flag(f[1], "AEMSV", "THS mode", raw)
        valid = f[1] in THS_VALID_MODES
        return Heading(
            talker=talker, sentence=kind, heading_deg=heading if valid else None, true=True
        )
    if kind != "HDG":
        _flag(f[1], "T" if kind == "HDT" else "M", f"{kind} flag", raw)
        return Heading(talker=talker, sentence=kind, heading_deg=heading, true=kind == "HDT")
    dev = _signed(_num(f[1], "HDG deviation", raw), f[2], "HDG deviation direction", raw)
    var = _signed(_num(f[3], "HDG variation", raw), f[4], "HDG variation direction", raw)
    return Heading(
        talker=talker,
        sentence=kind,
        heading_deg=heading,
        true=False,
        deviation_deg=_offset(dev, "HDG deviation", raw),
        variation_deg=_offset(var, "HDG variation", raw),
    )


PASHR_FIELDS = 11
"""$PASHR's attitude form (an INS's or a GNSS compass's, Hemisphere, Applanix, SBG):
time, heading, ``T``, roll, pitch, heave, roll, pitch and heading accuracy, GNSS
quality, INS status."""

PASHR_ATT_FIELDS = 8
"""Ashtech's $PASHR,ATT: ``ATT``, time, heading, pitch, roll, brms, mrms, reset flag."""


def parse_pashr(f: list[str], raw: bytes) -> Heading:
    """$PASHR's true heading: the attitude form (:data:`PASHR_FIELDS`) or Ashtech's
    ``ATT`` (:data:`PASHR_ATT_FIELDS`); its other forms are not decoded.

    Raises:
        UnknownSentenceError: another $PASHR form (POS, ...).
        FieldError: a field count or a field that does not fit the form.
    """
    if f[:1] == ["ATT"]:
        if len(f) != PASHR_ATT_FIELDS:
            raise FieldError(f"PASHR,ATT has {len(f)} fields, expected {PASHR_ATT_FIELDS}", raw)
        heading = _heading(_num(f[2], "PASHR heading", raw), "PASHR", raw)
        return Heading(talker="P", sentence="PASHR", heading_deg=heading, true=True)
    if f[:1] and f[0][:1].isalpha():
        raise UnknownSentenceError(f"$PASHR,{f[0][:8]} not decoded", raw)
    if len(f) != PASHR_FIELDS:
        raise FieldError(f"PASHR has {len(f)} fields, expected {PASHR_FIELDS}", raw)
    _flag(f[2], "T", "PASHR heading flag", raw)
    heading = _heading(_num(f[1], "PASHR heading", raw), "PASHR", raw)
    return Heading(talker="P", sentence="PASHR", heading_deg=heading, true=True)


def _int(field: str, name: str, raw: bytes, base: int = 10) -> int:
    try:
        return int(field, base)
    except ValueError:
        raise FieldError(f"{name}: {field!r} is not an integer", raw) from None


def _mm(field: str, name: str, raw: bytes) -> float | None:
    """A PRTI velocity in mm/s → m/s; None for empty or -99999."""
    if not field:
        return None
    v = _int(field, name, raw)
    if v == PRTI_INVALID:
        return None
    return v / 1000.0


def _vec3(v: list[float | None]) -> tuple[float, float, float] | None:
    a, b, c = v
    return None if a is None or b is None or c is None else (a, b, c)


def parse_prti(sentence: str, f: list[str], raw: bytes) -> Prti:
    """Rowe $PRTI01/$PRTI02 (12 or 14 fields after the address)."""
    if len(f) not in (12, 14):
        raise FieldError(f"{sentence} has {len(f)} fields, expected 12 or 14", raw)
    start = _int(f[0], "start time", raw) / 100.0
    sample = _int(f[1], "sample", raw)
    temp = _int(f[2], "temperature", raw) / 100.0
    bt = [_mm(f[i], f"bottom velocity {i - 2}", raw) for i in (3, 4, 5)]
    depth = _int(f[6], "bottom depth", raw) / 1000.0 if f[6] else 0.0
    wm = [_mm(f[i], f"water velocity {i - 6}", raw) for i in (7, 8, 9)]
    wdepth = _int(f[10], "water depth", raw) / 1000.0 if f[10] else None
    status = _int(f[11], "status", raw, 16) if f[11] else 0
    if start < 0.0 or sample < 0 or status < 0:
        raise OutOfRangeError(f"{sentence} start time, sample or status negative", raw)
    _temperature(temp, f"{sentence} temperature", raw)
    for d, name in ((depth, "bottom depth"), (wdepth, "water depth")):
        if d is not None and not 0.0 <= d <= MAX_DEPTH_M:
            raise OutOfRangeError(f"{sentence} {name} {d} m outside 0..{MAX_DEPTH_M:g}", raw)
    bottom = _vec3(bt)
    water = _vec3(wm)
    for vec, name in ((bottom, "bottom"), (water, "water")):
        if vec is not None:
            for v in vec:
                _speed(v, f"{sentence} {name} velocity", raw)
    sub = f[12] if len(f) == 14 else None
    cepo = _int(f[13], "CEPO index", raw) if len(f) == 14 and f[13] else None
    return Prti(
        sentence=sentence,
        start_time_s=start,
        sample=sample,
        temperature_c=temp,
        bottom_mps=bottom,
        bottom_depth_m=depth,
        water_mps=water,
        water_depth_m=wdepth,
        status=status,
        subsystem=sub,
        cepo_index=cepo,
    )


def _time_of_day(field: str, raw: bytes) -> float | None:
    """``hhmmss.ss`` → seconds since midnight, or None when empty."""
    if not field:
        return None
    if len(field) < 6 or not field[:6].isdigit():
        raise FieldError(f"time {field!r} is not hhmmss.ss", raw)
    h, m = int(field[0:2]), int(field[2:4])
    sec = _num(field[4:], "seconds", raw) or 0.0
    if h > 23 or m > 59 or not 0.0 <= sec < 61.0:
        raise OutOfRangeError(f"time {field!r} out of range", raw)
    return h * 3600.0 + m * 60.0 + sec


def _date(field: str, raw: bytes) -> date | None:
    """``ddmmyy`` → a date (years 80–99 are 1980–1999), or None when empty."""
    if not field:
        return None
    if len(field) != 6 or not field.isdigit():
        raise FieldError(f"date {field!r} is not ddmmyy", raw)
    yy = int(field[4:6])
    try:
        return date(1900 + yy if yy >= 80 else 2000 + yy, int(field[2:4]), int(field[0:2]))
    except ValueError:
        raise OutOfRangeError(f"date {field!r} out of range", raw) from None


def _at(day: date | None, tod: float | None) -> datetime | None:
    if day is None or tod is None:
        return None
    return datetime(day.year, day.month, day.day, tzinfo=UTC) + timedelta(seconds=tod)


def _latlon(value: str, hemi: str, degrees_digits: int, name: str, raw: bytes) -> float | None:
    """``(d)ddmm.mmmm`` + hemisphere → signed degrees, or None when empty."""
    if not value:
        return None
    head = value.partition(".")[0]
    if len(head) != degrees_digits + 2 or not head.isdigit():
        raise FieldError(f"{name} {value!r} is not (d)ddmm.mmmm", raw)
    deg = int(head[:degrees_digits])
    minutes = _num(value[degrees_digits:], name, raw) or 0.0
    if minutes >= 60.0 or deg > (90 if degrees_digits == 2 else 180):
        raise OutOfRangeError(f"{name} {value!r} out of range", raw)
    x = deg + minutes / 60.0
    _flag(hemi, "NS" if degrees_digits == 2 else "EW", f"{name} hemisphere", raw)
    return -x if hemi in ("S", "W") else x


def _mode(f: list[str], i: int, raw: bytes) -> str | None:
    if len(f) <= i or not f[i]:
        return None
    if len(f[i]) != 1 or not f[i].isalpha():
        raise FieldError(f"mode indicator {f[i]!r}", raw)
    return f[i]


def parse_rmc(talker: str, f: list[str], raw: bytes) -> Rmc:
    """RMC: 11 fields (NMEA 2.0), 12 with the mode (2.3), 13 with the navigational status (4.1)."""
    if len(f) not in (11, 12, 13):
        raise FieldError(f"RMC has {len(f)} fields, expected 11 to 13", raw)
    tod = _time_of_day(f[0], raw)
    active = _status(f[1], "RMC status", raw)
    lat = _latlon(f[2], f[3], 2, "latitude", raw)
    lon = _latlon(f[4], f[5], 3, "longitude", raw)
    sog = _speed(_kn(_num(f[6], "RMC speed", raw)), "RMC speed", raw)
    if sog is not None and sog < 0.0:
        raise OutOfRangeError(f"RMC speed {sog:.2f} m/s is negative", raw)
    cog = _heading(_num(f[7], "RMC course", raw), "RMC course", raw)
    day = _date(f[8], raw)
    var = _offset(
        _signed(_num(f[9], "RMC variation", raw), f[10], "RMC variation direction", raw),
        "RMC variation",
        raw,
    )
    return Rmc(
        talker=talker,
        time_utc=_at(day, tod),
        time_of_day_s=tod,
        status_active=active,
        lat_deg=lat,
        lon_deg=lon,
        sog_mps=sog,
        cog_true_deg=cog,
        variation_deg=var,
        mode=_mode(f, 11, raw),
    )


def parse_vtg(talker: str, f: list[str], raw: bytes) -> Vtg:
    """VTG: 8 fields, 9 with the mode indicator (NMEA 2.3); or the 4 of its form before
    NMEA 2.0 (course true, course magnetic, knots, km/h: no unit letters), as older
    receivers send it."""
    if len(f) == 4:
        f = [f[0], "T", f[1], "M", f[2], "N", f[3], "K"]
    if len(f) not in (8, 9):
        raise FieldError(f"VTG has {len(f)} fields, expected 8 or 9 (or 4)", raw)
    cog_t = _heading(_num(f[0], "VTG course true", raw), "VTG course true", raw)
    _flag(f[1], "T", "VTG field 2", raw)
    cog_m = _heading(_num(f[2], "VTG course magnetic", raw), "VTG course magnetic", raw)
    _flag(f[3], "M", "VTG field 4", raw)
    kn = _num(f[4], "VTG speed knots", raw)
    _flag(f[5], "N", "VTG field 6", raw)
    kmh = _num(f[6], "VTG speed km/h", raw)
    _flag(f[7], "K", "VTG field 8", raw)
    sog = _kn(kn) if kn is not None else (None if kmh is None else kmh * KMH_MPS)
    sog = _speed(sog, "VTG speed", raw)
    if sog is not None and sog < 0.0:
        raise OutOfRangeError(f"VTG speed {sog:.2f} m/s is negative", raw)
    return Vtg(
        talker=talker, cog_true_deg=cog_t, cog_mag_deg=cog_m, sog_mps=sog, mode=_mode(f, 8, raw)
    )


def parse_gga(talker: str, f: list[str], raw: bytes) -> Gga:
    """GGA: 14 fields."""
    if len(f) != 14:
        raise FieldError(f"GGA has {len(f)} fields, expected 14", raw)
    tod = _time_of_day(f[0], raw)
    lat = _latlon(f[1], f[2], 2, "latitude", raw)
    lon = _latlon(f[3], f[4], 3, "longitude", raw)
    quality = _int(f[5], "GGA fix quality", raw) if f[5] else 0
    sats = _int(f[6], "GGA satellites", raw) if f[6] else None
    hdop = _num(f[7], "GGA HDOP", raw)
    if not 0 <= quality <= MAX_FIX_QUALITY:
        raise OutOfRangeError(f"GGA fix quality {quality} outside 0..{MAX_FIX_QUALITY}", raw)
    if sats is not None and not 0 <= sats <= MAX_SATELLITES:
        raise OutOfRangeError(f"GGA satellites {sats} outside 0..{MAX_SATELLITES}", raw)
    if hdop is not None and not 0.0 <= hdop <= MAX_HDOP:
        raise OutOfRangeError(f"GGA HDOP {hdop} outside 0..{MAX_HDOP:g}", raw)
    return Gga(
        talker=talker,
        time_of_day_s=tod,
        lat_deg=lat,
        lon_deg=lon,
        quality=quality,
        satellites=sats,
        hdop=hdop,
    )


def parse_gll(talker: str, f: list[str], raw: bytes) -> Gll:
    """GLL: latitude, N/S, longitude, E/W (NMEA 1.5: 4 fields), the time of day and the
    status (2.0: 6), the mode (2.3: 7)."""
    if len(f) not in (4, 6, 7):
        raise FieldError(f"GLL has {len(f)} fields, expected 4, 6 or 7", raw)
    lat = _latlon(f[0], f[1], 2, "latitude", raw)
    lon = _latlon(f[2], f[3], 3, "longitude", raw)
    tod = _time_of_day(f[4], raw) if len(f) > 4 else None
    status = f[5] if len(f) > 5 else ""
    active = _status(status, "GLL status", raw) or status == ""
    return Gll(
        talker=talker,
        lat_deg=lat,
        lon_deg=lon,
        time_of_day_s=tod,
        status_active=active,
        mode=_mode(f, 6, raw),
    )


def parse_zda(talker: str, f: list[str], raw: bytes) -> Zda:
    """ZDA: time, day, month, year, local zone hours and minutes (6 fields)."""
    if len(f) != 6:
        raise FieldError(f"ZDA has {len(f)} fields, expected 6", raw)
    tod = _time_of_day(f[0], raw)
    if not (f[1] and f[2] and f[3]):
        return Zda(talker=talker, time_utc=None)
    year = _int(f[3], "ZDA year", raw)
    if not ZDA_YEARS[0] <= year <= ZDA_YEARS[1]:
        raise OutOfRangeError(f"ZDA year {year} outside {ZDA_YEARS[0]}..{ZDA_YEARS[1]}", raw)
    try:
        day = date(year, _int(f[2], "ZDA month", raw), _int(f[1], "ZDA day", raw))
    except (ValueError, OverflowError):
        raise OutOfRangeError("ZDA date out of range", raw) from None
    return Zda(talker=talker, time_utc=_at(day, tod))


def parse_vdr(talker: str, f: list[str], raw: bytes) -> Vdr:
    """VDR: set true, T, set magnetic, M, drift knots, N (6 fields)."""
    if len(f) != 6:
        raise FieldError(f"VDR has {len(f)} fields, expected 6", raw)
    st = _heading(_num(f[0], "VDR set true", raw), "VDR set true", raw)
    _flag(f[1], "T", "VDR field 2", raw)
    sm = _heading(_num(f[2], "VDR set magnetic", raw), "VDR set magnetic", raw)
    _flag(f[3], "M", "VDR field 4", raw)
    drift = _speed(_kn(_num(f[4], "VDR drift", raw)), "VDR drift", raw)
    _flag(f[5], "N", "VDR field 6", raw)
    if drift is not None and drift < 0.0:
        raise OutOfRangeError(f"VDR drift {drift:.2f} m/s is negative", raw)
    return Vdr(talker=talker, set_true_deg=st, set_mag_deg=sm, drift_mps=drift)


GNSS_PARSERS: dict[str, Callable[[str, list[str], bytes], Rmc | Vtg | Gga | Zda | Vdr]] = {
    "RMC": parse_rmc,
    "VTG": parse_vtg,
    "GGA": parse_gga,
    "ZDA": parse_zda,
    "VDR": parse_vdr,
}
"""Parsers of the GNSS sentences (and VDR) by sentence formatter."""
