"""The perturbation suite's JSON-lines rewrites of an NMEA log (docs/real_variants.py):
the same log as a Signal K server's delta log, as canboat's analyzer JSON of the
NMEA 2000 bus and as its plain text (the PGNs' bytes), written from their documented
layouts.

Each sentence is timed as ``emlogd import`` times an NMEA log (spread evenly between
its RMC fixes; those before the first fix and after the last dropped) and becomes the
message its NMEA 2000 or Signal K counterpart would be: VHW → the speed through the
water (PGN 128259; ``navigation.speedThroughWater`` in m/s), HDG → the magnetic heading
with its variation (PGN 127250, reference magnetic; ``navigation.headingMagnetic`` and
``navigation.magneticVariation`` in radians), RMC → the course and speed over ground
and the position (PGNs 129026 and 129025; ``navigation.courseOverGroundTrue``,
``navigation.speedOverGround``, ``navigation.position``). The Signal K log also holds
an AIS target's deltas (another context) every :data:`AIS_EVERY` fixes.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Any

from variants_nmea import _rmc_time, fields

KNOT_MPS = 1852.0 / 3600.0

SELF_CONTEXT = "vessels.urn:mrn:imo:mmsi:269000001"
AIS_CONTEXT = "vessels.urn:mrn:imo:mmsi:227000002"

AIS_EVERY = 10
"""An AIS target's delta after every this many fixes (Signal K)."""


def _timed(text: str) -> Iterator[tuple[float, list[str]]]:
    """(time, fields) of each sentence, spread evenly between the RMC fixes."""
    block: list[list[str]] = []
    t_last: float | None = None
    for line in text.splitlines():
        f = fields(line.strip())
        if f is None:
            continue
        fix = _rmc_time(f) if f[0].endswith("RMC") else None
        if fix is None:
            block.append(f)
            continue
        t = fix.timestamp()
        if t_last is not None and t > t_last:
            step = (t - t_last) / (len(block) + 1)
            yield from ((t_last + (i + 1) * step, g) for i, g in enumerate(block))
        block = []
        t_last = t
        yield t, f


def _num(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _signed(value: str, hemi: str, negative: str) -> float | None:
    x = _num(value)
    return None if x is None else (-x if hemi == negative else x)


def _position(f: list[str]) -> tuple[float, float] | None:
    """RMC's latitude and longitude in degrees."""
    try:
        lat = int(f[3][:2]) + float(f[3][2:]) / 60.0
        lon = int(f[5][:3]) + float(f[5][3:]) / 60.0
    except (ValueError, IndexError):
        return None
    return (-lat if f[4] == "S" else lat), (-lon if f[6] == "W" else lon)


def _values(f: list[str]) -> dict[str, Any]:
    """A sentence's Signal K values (SI units), by path."""
    kind, out = f[0][2:], {}
    if kind == "VHW" and (kn := _num(f[5])) is not None:
        out["navigation.speedThroughWater"] = kn * KNOT_MPS
    elif kind == "HDG" and (hdg := _num(f[1])) is not None:
        out["navigation.headingMagnetic"] = math.radians(hdg)
        if (var := _signed(f[4], f[5], "W")) is not None:
            out["navigation.magneticVariation"] = math.radians(var)
    elif kind == "RMC" and f[2] == "A":
        if (pos := _position(f)) is not None:
            out["navigation.position"] = {"latitude": pos[0], "longitude": pos[1]}
        if (sog := _num(f[7])) is not None and (cog := _num(f[8])) is not None:
            out["navigation.speedOverGround"] = sog * KNOT_MPS
            out["navigation.courseOverGroundTrue"] = math.radians(cog)
    return out


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _delta(context: str, t: float, values: dict[str, Any], label: str) -> str:
    update = {
        "source": {"label": label, "type": "NMEA0183"},
        "timestamp": _iso(t),
        "values": [{"path": p, "value": v} for p, v in values.items()],
    }
    return json.dumps({"context": context, "updates": [update]})


def signalk(text: str) -> str:
    """The log as a Signal K delta log, with an AIS target's deltas among its own."""
    out: list[str] = []
    fixes = 0
    for t, f in _timed(text):
        values = _values(f)
        if values:
            out.append(_delta(SELF_CONTEXT, t, values, "ttyUSB0"))
        if f[0].endswith("RMC"):
            fixes += 1
            if fixes % AIS_EVERY == 0:
                ais = {"navigation.speedOverGround": 6.0, "navigation.courseOverGroundTrue": 1.0}
                out.append(_delta(AIS_CONTEXT, t, ais, "ais"))
    return "".join(line + "\n" for line in out)


def _n2k(t: float, pgn: int, src: int, fields_: dict[str, Any]) -> str:
    stamp = datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d-%H:%M:%S.%f")[:-3]
    return json.dumps(
        {"timestamp": stamp, "prio": 2, "src": src, "dst": 255, "pgn": pgn, "fields": fields_}
    )


def canboat(text: str) -> str:
    """The log as canboat analyzer JSON (speeds in m/s, angles in degrees)."""
    out: list[str] = []
    for t, f in _timed(text):
        v = _values(f)
        if "navigation.speedThroughWater" in v:
            stw = round(v["navigation.speedThroughWater"], 2)
            out.append(_n2k(t, 128259, 35, {"SID": 0, "Speed Water Referenced": stw}))
        if "navigation.headingMagnetic" in v:
            hdg = {"SID": 0, "Heading": round(math.degrees(v["navigation.headingMagnetic"]), 1)}
            if "navigation.magneticVariation" in v:
                hdg["Variation"] = round(math.degrees(v["navigation.magneticVariation"]), 1)
            out.append(_n2k(t, 127250, 204, {**hdg, "Reference": "Magnetic"}))
        if "navigation.speedOverGround" in v:
            cog = round(math.degrees(v["navigation.courseOverGroundTrue"]), 1)
            sog = round(v["navigation.speedOverGround"], 2)
            rapid = {"SID": 0, "COG Reference": "True", "COG": cog, "SOG": sog}
            out.append(_n2k(t, 129026, 2, rapid))
        if "navigation.position" in v:
            pos = v["navigation.position"]
            out.append(
                _n2k(t, 129025, 2, {"Latitude": pos["latitude"], "Longitude": pos["longitude"]})
            )
    return "".join(line + "\n" for line in out)


def _plain(t: float, pgn: int, src: int, data: bytes) -> str:
    stamp = datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"
    return f"{stamp},2,{pgn},{src},255,{len(data)}," + ",".join(f"{b:02x}" for b in data)


def _u16(x: float, scale: float) -> int:
    return min(max(round(x / scale), 0), 0xFFFC)


def n2k_plain(text: str) -> str:
    """The log as NMEA 2000 in canboat's plain text: PGNs 128259, 127250 (magnetic,
    with its variation), 129026 and 129025 in their byte layouts."""
    out: list[str] = []
    for t, f in _timed(text):
        v = _values(f)
        if "navigation.speedThroughWater" in v:
            stw = _u16(v["navigation.speedThroughWater"], 0.01)
            out.append(_plain(t, 128259, 35, struct.pack("<BHHBBB", 0, stw, 0xFFFF, 0, 0xFF, 0xFF)))
        if "navigation.headingMagnetic" in v:
            hdg = _u16(v["navigation.headingMagnetic"] % (2 * math.pi), 1e-4)
            var_rad = v.get("navigation.magneticVariation")
            var = 0x7FFF if var_rad is None else round(var_rad * 1e4)
            data = struct.pack("<BHhhB", 0, hdg, 0x7FFF, var, 0xFD)
            out.append(_plain(t, 127250, 204, data))
        if "navigation.speedOverGround" in v:
            cog = _u16(v["navigation.courseOverGroundTrue"], 1e-4)
            sog = _u16(v["navigation.speedOverGround"], 0.01)
            out.append(_plain(t, 129026, 2, struct.pack("<BBHHH", 0, 0xFC, cog, sog, 0xFFFF)))
        if "navigation.position" in v:
            pos = v["navigation.position"]
            data = struct.pack("<ii", round(pos["latitude"] * 1e7), round(pos["longitude"] * 1e7))
            out.append(_plain(t, 129025, 2, data))
    return "".join(line + "\n" for line in out)
