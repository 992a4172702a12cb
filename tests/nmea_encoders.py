"""Encoders of the NMEA sentences emlogd reads but never writes (VTG, GGA, ZDA, HDT, HDM,
HDG): the tests' and the fuzzers' inputs, written with the field formatters of
:mod:`drivers.nmea0183.encoders`."""

from __future__ import annotations

import math
from datetime import UTC, datetime

from drivers.framing import with_checksum
from drivers.nmea0183.encoders import (
    check_talker,
    fmt_direction,
    fmt_lat,
    fmt_lon,
    fmt_number,
    fmt_time,
)
from drivers.records import KMH_MPS, KNOT_MPS


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
        else fmt_number(min(max(sog_mps / KNOT_MPS, 0.0), 999.9), 2)
    )
    kmh = (
        ""
        if sog_mps is None or not math.isfinite(sog_mps)
        else fmt_number(min(max(sog_mps / KMH_MPS, 0.0), 1851.9), 2)
    )
    body = f"{check_talker(talker)}VTG,{fmt_direction(cog_true_deg)},T,{fmt_direction(cog_mag_deg)},M,{kn},N,{kmh},K,{mode}"
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
    la, ns = fmt_lat(lat_deg)
    lo, ew = fmt_lon(lon_deg)
    body = (
        f"{check_talker(talker)}GGA,{fmt_time(t)},{la},{ns},{lo},{ew},{min(max(int(quality), 0), 9)},"
        f"{min(max(int(satellites), 0), 99):02d},{fmt_number(min(max(hdop, 0.0), 99.9), 1)},,M,,M,,"
    )
    return with_checksum(body)


def encode_zda(t: datetime, talker: str = "GP") -> str:
    """A ZDA sentence (UTC, local zone 0; without CR LF)."""
    u = t.astimezone(UTC)
    body = f"{check_talker(talker)}ZDA,{fmt_time(u)},{u.day:02d},{u.month:02d},{u.year:04d},00,00"
    return with_checksum(body)


def encode_hdt(heading_deg: float, talker: str = "HE") -> str:
    """An HDT sentence (true heading; without CR LF)."""
    return with_checksum(f"{check_talker(talker)}HDT,{fmt_direction(heading_deg)},T")


def encode_hdm(heading_deg: float, talker: str = "HC") -> str:
    """An HDM sentence (magnetic heading; without CR LF)."""
    return with_checksum(f"{check_talker(talker)}HDM,{fmt_direction(heading_deg)},M")


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
        return fmt_number(min(abs(x), 180.0), 1), "E" if x >= 0 else "W"

    d, dd = signed(deviation_deg)
    v, vd = signed(variation_deg)
    return with_checksum(f"{check_talker(talker)}HDG,{fmt_direction(sensor_deg)},{d},{dd},{v},{vd}")
