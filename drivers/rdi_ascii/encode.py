"""The PD6 encoder (the simulator's and the tests' DVL output).

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from datetime import datetime

from drivers.rdi import mms


def _mm(v: float | None) -> str:
    return f"{mms(v):+06d}"


def _vel_line(kind: str, values: tuple[float, ...] | None, n: int) -> str:
    if values is None:
        return f":{kind}," + ",".join([_mm(None)] * n) + ",V"
    return f":{kind}," + ",".join(_mm(v) for v in values) + ",A"


def encode_pd6(
    *,
    timestamp: datetime,
    heading_deg: float,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    bottom_ship_mps: tuple[float, float, float] | None = None,
    range_m: float | None = None,
    water_ship_mps: tuple[float, float, float] | None = None,
    salinity_ppt: float = 35.0,
    temperature_c: float = 15.0,
    depth_m: float = 0.0,
    sound_speed_mps: float = 1500.0,
    bottom_dmg_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    time_since_good_s: float = 0.0,
) -> list[str]:
    """The PD6 lines of one ensemble (without CR LF), TRDI widths.

    Sends ``:SA :TS :BI :BS :BE :BD``, plus the water-mass lines when
    ``water_ship_mps`` is given. Ship-frame vectors are (T, L, N): + starboard,
    + forward, + away from the bottom (vessel motion). The instrument frame is taken
    aligned with the ship (X = T, Y = L); the earth frame is the ship frame rotated
    by the heading (pitch and roll ignored). ``None`` sends −32768 with status V.

    Raises:
        ValueError: non-finite values.
    """
    psi = math.radians(heading_deg)

    def earth(v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is None:
            return None
        t, lo, n = v
        return (lo * math.sin(psi) + t * math.cos(psi), lo * math.cos(psi) - t * math.sin(psi), n)

    lines = [
        f":SA,{pitch_deg:+06.2f},{roll_deg:+06.2f},{heading_deg % 360.0:06.2f}",
        f":TS,{timestamp:%y%m%d%H%M%S}{timestamp.microsecond // 10000:02d},{salinity_ppt:04.1f},"
        f"{temperature_c:+05.1f},{depth_m:06.1f},{sound_speed_mps:06.1f},000",
    ]
    if water_ship_mps is not None:
        lines += [
            _vel_line("WI", (*water_ship_mps, 0.0), 4),
            _vel_line("WS", water_ship_mps, 3),
            _vel_line("WE", earth(water_ship_mps), 3),
            ":WD,+0000.00,+0000.00,+0000.00,0000.00,000.00",
        ]
    e, n, u = bottom_dmg_m
    rng = 0.0 if range_m is None else range_m
    lines += [
        _vel_line("BI", None if bottom_ship_mps is None else (*bottom_ship_mps, 0.0), 4),
        _vel_line("BS", bottom_ship_mps, 3),
        _vel_line("BE", earth(bottom_ship_mps), 3),
        f":BD,{e:+011.2f},{n:+011.2f},{u:+011.2f},{rng:07.2f},{time_since_good_s:06.2f}",
    ]
    return lines
