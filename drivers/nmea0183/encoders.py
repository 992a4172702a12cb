"""NMEA 0183 encoders: sentences (without CR LF) with their checksum.

The sentences emlogd writes (VHW, VBW: corrected speeds; RMC: imports and simulated
trials), and the field formatters they are written with.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from datetime import UTC, datetime

from drivers.framing import with_checksum
from drivers.records import KMH_MPS, KNOT_MPS


def fmt_number(x: float | None, decimals: int) -> str:
    """A number with ``decimals``, empty for None, never ``-0.00``.

    Raises:
        ValueError: a non-finite value.
    """
    if x is None:
        return ""
    if not math.isfinite(x):
        raise ValueError(f"cannot encode a non-finite value {x!r}")
    s = "%.*f" % (decimals, x)  # noqa: UP031 - a third faster than the f-string's nested spec
    return "0." + "0" * decimals if s[0] == "-" and float(s) == 0.0 else s


def check_talker(talker: str) -> str:
    """The talker ID, two uppercase letters or digits.

    Raises:
        ValueError: anything else.
    """
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
    kn = fmt_number(stw_mps / KNOT_MPS, decimals)
    kmh = fmt_number(stw_mps / KMH_MPS, decimals)
    ht = fmt_number(None if heading_true_deg is None else heading_true_deg % 360.0, 1)
    hm = fmt_number(None if heading_mag_deg is None else heading_mag_deg % 360.0, 1)
    body = f"{check_talker(talker)}VHW,{ht},T,{hm},M,{kn},N,{kmh},K"
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
    wl = fmt_number(water_long_mps / KNOT_MPS, decimals)
    wt = fmt_number(water_trans_mps / KNOT_MPS, decimals)
    gl = fmt_number(None if ground_long_mps is None else ground_long_mps / KNOT_MPS, decimals)
    gt = fmt_number(None if ground_trans_mps is None else ground_trans_mps / KNOT_MPS, decimals)
    body = (
        f"{check_talker(talker)}VBW,{wl},{wt},{'A' if water_valid else 'V'},"
        f"{gl},{gt},{'A' if ground_valid else 'V'}"
    )
    return with_checksum(body)


def fmt_direction(x: float | None, decimals: int = 1) -> str:
    """A direction in [0, 360) with ``decimals``, empty for None or non-finite."""
    if x is None or not math.isfinite(x):
        return ""
    v = round(x % 360.0, decimals)
    return fmt_number(0.0 if v >= 360.0 else v, decimals)


def _dm(a: float, digits: int) -> str:
    """Degrees ≥ 0 as (d)ddmm.mmmm, the minutes rounded first (59.99999 → next degree)."""
    ten_thousandths = round(a * 600_000.0)
    d, rest = divmod(ten_thousandths, 600_000)
    return f"{d:0{digits}d}{rest / 10_000.0:07.4f}"


def fmt_lat(x: float | None) -> tuple[str, str]:
    """A latitude as (``ddmm.mmmm``, ``N``/``S``), empty fields for None or non-finite."""
    if x is None or not math.isfinite(x):
        return "", ""
    return _dm(min(abs(x), 90.0), 2), "N" if x >= 0 else "S"


def fmt_lon(x: float | None) -> tuple[str, str]:
    """A longitude as (``dddmm.mmmm``, ``E``/``W``), empty fields for None or non-finite."""
    if x is None or not math.isfinite(x):
        return "", ""
    return _dm(min(abs(x), 180.0), 3), "E" if x >= 0 else "W"


def fmt_time(t: datetime | None) -> str:
    """A time of day UTC as ``hhmmss.ss``, empty for None."""
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
    la, ns = fmt_lat(lat_deg)
    lo, ew = fmt_lon(lon_deg)
    kn = (
        ""
        if sog_mps is None or not math.isfinite(sog_mps)
        else fmt_number(min(max(sog_mps / KNOT_MPS, 0.0), 999.9), 2)
    )
    day = "" if t is None else t.astimezone(UTC).strftime("%d%m%y")
    if variation_deg is None or not math.isfinite(variation_deg):
        var, vd = "", ""
    else:
        var, vd = fmt_number(min(abs(variation_deg), 180.0), 1), "E" if variation_deg >= 0 else "W"
    body = (
        f"{check_talker(talker)}RMC,{fmt_time(t)},{'A' if active else 'V'},{la},{ns},{lo},{ew},"
        f"{kn},{fmt_direction(cog_true_deg)},{day},{var},{vd},{mode}"
    )
    return with_checksum(body)
