"""NMEA 0183 encoders: sentences (without CR LF) with their checksum.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from datetime import UTC, datetime

from drivers.framing import with_checksum
from drivers.records import KMH_MPS, KNOT_MPS


def _fmt(x: float | None, decimals: int) -> str:
    if x is None:
        return ""
    if not math.isfinite(x):
        raise ValueError(f"cannot encode a non-finite value {x!r}")
    s = f"{x:.{decimals}f}"
    return "0." + "0" * decimals if s.startswith("-") and float(s) == 0.0 else s


def _talker(talker: str) -> str:
    if len(talker) != 2 or not talker.isalnum() or (not talker.isupper() and not talker.isdigit()):
        raise ValueError(f"talker must be two uppercase letters or digits, not {talker!r}")
    return talker


def encode_vhw(
    stw_mps: float,
    *,
    heading_true_deg: float | None = None,
    heading_mag_deg: float | None = None,
    talker: str = "VW",
    decimals: int = 2,
) -> str:
    """A VHW sentence (without CR LF): knots and km/h both filled and consistent.

    Raises:
        ValueError: a non-finite value or a bad talker.
    """
    if not math.isfinite(stw_mps):
        raise ValueError(f"cannot encode a non-finite speed {stw_mps!r}")
    kn = _fmt(stw_mps / KNOT_MPS, decimals)
    kmh = _fmt(stw_mps / KMH_MPS, decimals)
    ht = _fmt(None if heading_true_deg is None else heading_true_deg % 360.0, 1)
    hm = _fmt(None if heading_mag_deg is None else heading_mag_deg % 360.0, 1)
    body = f"{_talker(talker)}VHW,{ht},T,{hm},M,{kn},N,{kmh},K"
    return with_checksum(body)


def encode_vbw(
    water_long_mps: float,
    water_trans_mps: float,
    *,
    water_valid: bool = True,
    ground_long_mps: float | None = None,
    ground_trans_mps: float | None = None,
    ground_valid: bool = False,
    talker: str = "VM",
    decimals: int = 2,
) -> str:
    """A 6-field VBW sentence (without CR LF), speeds in knots.

    Raises:
        ValueError: a non-finite value or a bad talker.
    """
    wl = _fmt(water_long_mps / KNOT_MPS, decimals)
    wt = _fmt(water_trans_mps / KNOT_MPS, decimals)
    gl = _fmt(None if ground_long_mps is None else ground_long_mps / KNOT_MPS, decimals)
    gt = _fmt(None if ground_trans_mps is None else ground_trans_mps / KNOT_MPS, decimals)
    body = (
        f"{_talker(talker)}VBW,{wl},{wt},{'A' if water_valid else 'V'},"
        f"{gl},{gt},{'A' if ground_valid else 'V'}"
    )
    return with_checksum(body)


def _deg(x: float | None, decimals: int = 1) -> str:
    """A direction in [0, 360) with ``decimals``, empty for None or non-finite."""
    if x is None or not math.isfinite(x):
        return ""
    v = round(x % 360.0, decimals)
    return _fmt(0.0 if v >= 360.0 else v, decimals)


def _dm(a: float, digits: int) -> str:
    """Degrees ≥ 0 as (d)ddmm.mmmm, the minutes rounded first (59.99999 → next degree)."""
    ten_thousandths = round(a * 600_000.0)
    d, rest = divmod(ten_thousandths, 600_000)
    return f"{d:0{digits}d}{rest / 10_000.0:07.4f}"


def _lat(x: float | None) -> tuple[str, str]:
    if x is None or not math.isfinite(x):
        return "", ""
    return _dm(min(abs(x), 90.0), 2), "N" if x >= 0 else "S"


def _lon(x: float | None) -> tuple[str, str]:
    if x is None or not math.isfinite(x):
        return "", ""
    return _dm(min(abs(x), 180.0), 3), "E" if x >= 0 else "W"


def _hms(t: datetime | None) -> str:
    if t is None:
        return ""
    t = t.astimezone(UTC)
    return f"{t.hour:02d}{t.minute:02d}{t.second:02d}.{t.microsecond // 10000:02d}"


def encode_rmc(
    t: datetime | None,
    sog_mps: float | None,
    cog_true_deg: float | None,
    *,
    lat_deg: float | None = None,
    lon_deg: float | None = None,
    variation_deg: float | None = None,
    active: bool = True,
    mode: str = "A",
    talker: str = "GP",
) -> str:
    """An RMC sentence (NMEA 2.3, with the mode indicator; without CR LF).

    Speed is clamped to 0–999.9 kn, a non-finite value leaves its field empty.

    Raises:
        ValueError: a bad talker or mode.
    """
    if len(mode) != 1 or not mode.isalpha():
        raise ValueError(f"mode must be one letter, not {mode!r}")
    la, ns = _lat(lat_deg)
    lo, ew = _lon(lon_deg)
    kn = (
        ""
        if sog_mps is None or not math.isfinite(sog_mps)
        else _fmt(min(max(sog_mps / KNOT_MPS, 0.0), 999.9), 2)
    )
    day = "" if t is None else t.astimezone(UTC).strftime("%d%m%y")
    if variation_deg is None or not math.isfinite(variation_deg):
        var, vd = "", ""
    else:
        var, vd = _fmt(min(abs(variation_deg), 180.0), 1), "E" if variation_deg >= 0 else "W"
    body = (
        f"{_talker(talker)}RMC,{_hms(t)},{'A' if active else 'V'},{la},{ns},{lo},{ew},"
        f"{kn},{_deg(cog_true_deg)},{day},{var},{vd},{mode}"
    )
    return with_checksum(body)


def encode_vtg(
    sog_mps: float | None,
    cog_true_deg: float | None,
    *,
    cog_mag_deg: float | None = None,
    mode: str = "A",
    talker: str = "GP",
) -> str:
    """A VTG sentence with the mode indicator (without CR LF)."""
    kn = (
        ""
        if sog_mps is None or not math.isfinite(sog_mps)
        else _fmt(min(max(sog_mps / KNOT_MPS, 0.0), 999.9), 2)
    )
    kmh = (
        ""
        if sog_mps is None or not math.isfinite(sog_mps)
        else _fmt(min(max(sog_mps / KMH_MPS, 0.0), 1851.9), 2)
    )
    body = (
        f"{_talker(talker)}VTG,{_deg(cog_true_deg)},T,{_deg(cog_mag_deg)},M,{kn},N,{kmh},K,{mode}"
    )
    return with_checksum(body)


def encode_gga(
    t: datetime | None,
    lat_deg: float | None,
    lon_deg: float | None,
    quality: int = 1,
    *,
    satellites: int = 10,
    hdop: float = 0.9,
    talker: str = "GP",
) -> str:
    """A GGA sentence (without CR LF); altitude and geoid fields empty."""
    la, ns = _lat(lat_deg)
    lo, ew = _lon(lon_deg)
    body = (
        f"{_talker(talker)}GGA,{_hms(t)},{la},{ns},{lo},{ew},{min(max(int(quality), 0), 9)},"
        f"{min(max(int(satellites), 0), 99):02d},{_fmt(min(max(hdop, 0.0), 99.9), 1)},,M,,M,,"
    )
    return with_checksum(body)


def encode_zda(t: datetime, talker: str = "GP") -> str:
    """A ZDA sentence (UTC, local zone 0; without CR LF)."""
    u = t.astimezone(UTC)
    body = f"{_talker(talker)}ZDA,{_hms(u)},{u.day:02d},{u.month:02d},{u.year:04d},00,00"
    return with_checksum(body)


def encode_hdt(heading_deg: float, talker: str = "HE") -> str:
    """An HDT sentence (true heading; without CR LF)."""
    return with_checksum(f"{_talker(talker)}HDT,{_deg(heading_deg)},T")


def encode_hdm(heading_deg: float, talker: str = "HC") -> str:
    """An HDM sentence (magnetic heading; without CR LF)."""
    return with_checksum(f"{_talker(talker)}HDM,{_deg(heading_deg)},M")


def encode_hdg(
    sensor_deg: float,
    deviation_deg: float | None = None,
    variation_deg: float | None = None,
    talker: str = "HC",
) -> str:
    """An HDG sentence: magnetic sensor heading, deviation and variation (+ east; without CR LF)."""

    def signed(x: float | None) -> tuple[str, str]:
        if x is None or not math.isfinite(x):
            return "", ""
        return _fmt(min(abs(x), 180.0), 1), "E" if x >= 0 else "W"

    d, dd = signed(deviation_deg)
    v, vd = signed(variation_deg)
    return with_checksum(f"{_talker(talker)}HDG,{_deg(sensor_deg)},{d},{dd},{v},{vd}")
