"""NMEA 2000 messages in canboat's plain text (``actisense-serial``'s output, a Signal K
server's data log of an NMEA 2000 connection), decoded into the analyzer-JSON message
:mod:`emlogd.offline.importjson` reads.

A line is ``timestamp,priority,PGN,source,destination,length,byte,byte,...`` with the
bytes in hex (``2016-04-09T16:41:39.628Z,2,127250,7,255,8,00,fc,69,ff,7f,ff,7f,fd``);
anything before the time stamp (a Signal K data log's ``1460212899628;A;``) is passed
over. The PGNs read are single-frame ones, decoded from their NMEA 2000 layouts
(little-endian fields; all ones is "no value"):

- 128259 Speed: SID, speed water referenced (uint16, 0.01 m/s), ...
- 127250 Vessel Heading: SID, heading (uint16, 0.0001 rad), deviation and variation
  (int16, 0.0001 rad), reference in the low two bits of byte 7 (0 true, 1 magnetic).
- 129026 COG & SOG, Rapid Update: SID, COG reference in the low two bits of byte 1,
  COG (uint16, 0.0001 rad), SOG (uint16, 0.01 m/s).
- 129025 Position, Rapid Update: latitude, longitude (int32, 1e-7 degree).
- 127258 Magnetic Variation: SID, source, age (uint16 days), variation (int16, 0.0001 rad).
"""

from __future__ import annotations

import math
import re
import struct
from typing import Any

PLAIN_LINE = re.compile(
    r"(?:.*?[;\s])?(?P<stamp>\d{4}-\d{2}-\d{2}[-T ]\d{2}:\d{2}:\d{2}(?:\.\d+)?Z?),"
    r"(?P<prio>\d),(?P<pgn>\d{5,6}),(?P<src>\d{1,3}),(?P<dst>\d{1,3}),(?P<len>\d{1,4}),"
    r"(?P<data>[0-9A-Fa-f]{2}(?:,[0-9A-Fa-f]{2})*)\s*$"
)
"""A canboat plain-text line (a prefix before its time stamp allowed)."""

DEG_PER_RAD = 180.0 / math.pi

REFERENCES = {0: "True", 1: "Magnetic", 2: "Error", 3: "Null"}
"""The direction reference's codes."""


def _u16(data: bytes, at: int, scale: float) -> float | None:
    (x,) = struct.unpack_from("<H", data, at)
    return None if x >= 0xFFFD else x * scale  # the top codes: no value, error, reserved


def _i16(data: bytes, at: int, scale: float) -> float | None:
    (x,) = struct.unpack_from("<h", data, at)
    return None if x >= 0x7FFD else x * scale


def _i32(data: bytes, at: int, scale: float) -> float | None:
    (x,) = struct.unpack_from("<i", data, at)
    return None if x >= 0x7FFFFFFD else x * scale


def _fields(pgn: int, data: bytes) -> dict[str, Any] | None:
    """The analyzer's fields of a PGN read (speeds m/s, angles degrees); None for
    another PGN or too few bytes. A field without a value is left out."""
    out: dict[str, Any]
    if pgn == 128259 and len(data) >= 3:
        out = {"Speed Water Referenced": _u16(data, 1, 0.01)}
    elif pgn == 127250 and len(data) >= 8:
        out = {
            "Heading": _deg(_u16(data, 1, 1e-4)),
            "Deviation": _deg(_i16(data, 3, 1e-4)),
            "Variation": _deg(_i16(data, 5, 1e-4)),
            "Reference": REFERENCES[data[7] & 0x03],
        }
    elif pgn == 129026 and len(data) >= 6:
        out = {
            "COG Reference": REFERENCES[data[1] & 0x03],
            "COG": _deg(_u16(data, 2, 1e-4)),
            "SOG": _u16(data, 4, 0.01),
        }
    elif pgn == 129025 and len(data) >= 8:
        out = {"Latitude": _i32(data, 0, 1e-7), "Longitude": _i32(data, 4, 1e-7)}
    elif pgn == 127258 and len(data) >= 6:
        out = {"Variation": _deg(_i16(data, 4, 1e-4))}
    else:
        return None
    return {k: v for k, v in out.items() if v is not None}


def _deg(rad: float | None) -> float | None:
    return None if rad is None else rad * DEG_PER_RAD


def plain_message(line: str) -> dict[str, Any] | None:
    """A plain-text line as an analyzer-JSON message (``timestamp``, ``pgn``,
    ``src``, ``fields``; the fields empty for a PGN not read), or None when the line is
    not one."""
    m = PLAIN_LINE.match(line.strip())
    if m is None:
        return None
    data = bytes.fromhex(m.group("data").replace(",", ""))
    pgn = int(m.group("pgn"))
    return {
        "timestamp": m.group("stamp"),
        "pgn": pgn,
        "src": int(m.group("src")),
        "fields": _fields(pgn, data) or {},
    }
