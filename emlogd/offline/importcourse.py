"""``emlogd import --format nmea``: an RMC without a course over ground (its field empty,
as receivers leave it at low speed, or always) given the course from the positions of
the fixes before it, when the speed and their spacing allow it (:class:`CourseFill`).

The course is the bearing from the latest earlier RMC at least :data:`COURSE_MIN_DISTANCE_M`
and :data:`COURSE_MIN_RESOLUTIONS` position resolutions away (the minutes' last decimal:
``4613.353`` is 0.001', 1.85 m), no more than :data:`COURSE_MAX_DT_S` before; the
distance over the time between must agree with the RMC's speed over ground
(:data:`COURSE_SPEED_TOLERANCE`). Else the course stays empty (the fix gives no ground
velocity): a bearing over a few metres of quantised positions would be off by tens of
degrees. The RMC is rewritten with the course to 0.1° and its checksum.
"""

from __future__ import annotations

import math
from collections import deque

from drivers.errors import FrameError
from drivers.framing import split_nmea, with_checksum
from drivers.records import KNOT_MPS
from emlogd.offline.importbase import ImportReport

COURSE_MAX_DT_S = 5.0
"""The earlier fix a course is taken from is at most this long before, s (the course is
then the mean over at most this long: it lags by half of it)."""

COURSE_MIN_DISTANCE_M = 2.0
"""The positions a course is taken from are at least this far apart, m (a GNSS's
position noise from one fix to the next is a few decimetres)."""

COURSE_MIN_RESOLUTIONS = 8
"""... and at least this many times the positions' resolution apart (rounded positions
give a bearing off by about 0.4 resolutions over the distance, rms: under 3°)."""

COURSE_SPEED_TOLERANCE = (0.5, 0.25)
"""The distance over the time may differ from the RMC's speed by at most this much
(m/s) plus this fraction of it: else a position jumped, or the boat turned."""

EARTH_RADIUS_M = 6_371_000.0
MINUTE_M = 1852.0


def _angle(cell: str, hemi: str, degree_digits: int) -> tuple[float, int] | None:
    """``ddmm.mmm`` and its hemisphere → (signed degrees, the minutes' decimals)."""
    if len(cell) < degree_digits + 2 or hemi not in ("N", "S", "E", "W"):
        return None
    try:
        deg = int(cell[:degree_digits])
        minutes = float(cell[degree_digits:])
    except ValueError:
        return None
    x = deg + minutes / 60.0
    return (-x if hemi in ("S", "W") else x), len(cell.partition(".")[2])


def _time_of_day(cell: str) -> float | None:
    try:
        return int(cell[0:2]) * 3600.0 + int(cell[2:4]) * 60.0 + float(cell[4:])
    except ValueError:
        return None


class CourseFill:
    """RMC sentences without a course given one from the positions before them (module
    docstring); counted in ``notes``: ``course_from_positions``, and
    ``course_empty`` for those left without."""

    def __init__(self, report: ImportReport) -> None:
        self.report = report
        self.fixes: deque[tuple[float, float, float, int]] = deque(maxlen=64)
        """Recent valid RMC fixes: (time of day s, lat °, lon °, minutes' decimals)."""

    def line(self, text: str) -> str:
        """The sentence, an RMC without a course rewritten with one when it can be."""
        if text[3:6] != "RMC":
            return text
        try:
            body = split_nmea(text.encode("ascii"), required=True).decode("ascii")
        except (FrameError, UnicodeError):
            return text
        f = body.split(",")
        if len(f) < 10 or f[2] != "A":
            return text
        t = _time_of_day(f[1])
        lat, lon = _angle(f[3], f[4], 2), _angle(f[5], f[6], 3)
        if t is None or lat is None or lon is None:
            return text
        fix = (t, lat[0], lon[0], min(lat[1], lon[1]))
        course = None if f[8].strip() else self._course(fix, f[7])
        self.fixes.append(fix)
        if f[8].strip():
            return text
        if course is None:
            self.report.notes["course_empty"] += 1
            return text
        self.report.notes["course_from_positions"] += 1
        f[8] = f"{course:.1f}"
        return with_checksum(",".join(f), text[0])

    def _course(self, fix: tuple[float, float, float, int], sog_cell: str) -> float | None:
        """The bearing to ``fix`` from the latest earlier fix far enough away, or None."""
        try:
            sog = float(sog_cell) * KNOT_MPS
        except ValueError:
            return None
        t, lat, lon, decimals = fix
        res = MINUTE_M * 10.0 ** (-decimals)
        need = max(COURSE_MIN_DISTANCE_M, COURSE_MIN_RESOLUTIONS * res)
        coslat = math.cos(math.radians(lat))
        for t0, lat0, lon0, _ in reversed(self.fixes):
            dt = (t - t0) % 86_400.0
            if dt > COURSE_MAX_DT_S:
                return None
            if dt == 0.0:
                continue
            north = math.radians(lat - lat0) * EARTH_RADIUS_M
            east = math.radians(lon - lon0) * EARTH_RADIUS_M * coslat
            dist = math.hypot(north, east)
            if dist < need:
                continue
            slack, frac = COURSE_SPEED_TOLERANCE
            if abs(dist / dt - sog) > slack + frac * sog:
                return None
            return math.degrees(math.atan2(east, north)) % 360.0
        return None
