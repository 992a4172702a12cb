"""``emlogd import --format nmea``: an RMC without a course over ground (its field empty,
as receivers leave it at low speed, or always) given the course from the positions of
the fixes around it, when the speed and their spacing allow it (:class:`CourseFill`).

The course is the bearing between the valid RMC ``k`` fixes before it and the one ``k``
fixes after it, for the least ``k`` that puts them at least
:data:`COURSE_MIN_DISTANCE_M` and :data:`COURSE_MIN_RESOLUTIONS` position resolutions
apart (the minutes' last decimal: ``4613.353`` is 0.001', 1.85 m), each within
:data:`COURSE_MAX_DT_S` of it: a centred difference, the boat's mean course over the
span, whose midpoint is the RMC's time for fixes at a steady rate (a bearing from the
positions before alone is the mean over a span ending at the fix, and lags the boat by
half of it). Where the log has no fix within that on one side (its first and last
fixes, a gap) the bearing is taken over the positions on the other side alone. The
distance over the time between must agree with the RMC's speed over ground
(:data:`COURSE_SPEED_TOLERANCE`). Else the course stays empty (the fix gives no ground
velocity): a bearing over a few metres of quantised positions would be off by tens of
degrees. The RMC is rewritten with the course to 0.1° and its checksum; the lines
after an RMC waiting for the fixes after it are held back until it is written, so the
order of the log is kept.
"""

from __future__ import annotations

import math
from collections import deque

from drivers.errors import FrameError
from drivers.framing import split_nmea, with_checksum
from drivers.records import KNOT_MPS
from emlogd.offline.importbase import ImportReport

COURSE_MAX_DT_S = 5.0
"""The fixes a course is taken from are at most this long before and after it, s."""

HOLD_MAX_LINES = 1000
"""Most lines held back behind an RMC waiting for the fixes after it: past them (the
GNSS silent while the rest of the log goes on) it is given what the fixes before it
allow, so the memory an import takes does not grow with a gap in the fixes."""

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


def _dt(t0: float, t1: float) -> float:
    """``t1 − t0`` for times of day, s, across midnight (within ±12 h)."""
    return (t1 - t0 + 43_200.0) % 86_400.0 - 43_200.0


Fix = tuple[float, float, float, int]
"""A valid RMC's (time of day s, lat °, lon °, minutes' decimals)."""


class CourseFill:
    """RMC sentences without a course given one from the positions around them (module
    docstring); counted in ``notes``: ``course_from_positions``, and
    ``course_empty`` for those left without. :meth:`lines` returns the lines ready to be
    written, in order; :meth:`flush` the rest at the end of the log."""

    def __init__(self, report: ImportReport) -> None:
        self.report = report
        self.fixes: list[Fix] = []
        """The valid RMC fixes from the oldest one a waiting RMC may still need."""
        self.held: deque[tuple[str, list[str] | None, int]] = deque()
        """Lines held back: (line, the fields of an RMC waiting for a course, the index
        of its fix in :attr:`fixes`)."""

    def lines(self, text: str) -> list[str]:
        """The lines ready to be written once ``text`` is read."""
        fields = self._rmc(text)
        if fields is not None:
            f, fix = fields
            self.fixes.append(fix)
            if not f[8].strip():
                self.held.append((text, f, len(self.fixes) - 1))
                return self._release(final=False)
        if not self.held:
            self._forget()
            return [text]
        self.held.append((text, None, -1))
        return self._release(final=False)

    def flush(self) -> list[str]:
        """The lines still held, each waiting RMC given what the fixes allow."""
        return self._release(final=True)

    def _rmc(self, text: str) -> tuple[list[str], Fix] | None:
        """A valid RMC's fields and fix, else None."""
        if text[3:6] != "RMC":
            return None
        try:
            body = split_nmea(text.encode("ascii"), required=True).decode("ascii")
        except (FrameError, UnicodeError):
            return None
        f = body.split(",")
        if len(f) < 10 or f[2] != "A":
            return None
        t = _time_of_day(f[1])
        lat, lon = _angle(f[3], f[4], 2), _angle(f[5], f[6], 3)
        if t is None or lat is None or lon is None:
            return None
        return f, (t, lat[0], lon[0], min(lat[1], lon[1]))

    def _release(self, final: bool) -> list[str]:
        out: list[str] = []
        while self.held:
            text, f, i = self.held[0]
            if f is not None:
                t = self.fixes[i][0]
                ahead = _dt(t, self.fixes[-1][0])
                if (
                    not final
                    and len(self.held) <= HOLD_MAX_LINES
                    and (-COURSE_MAX_DT_S <= ahead <= COURSE_MAX_DT_S)
                ):
                    break  # a later fix within reach may still come (not past a time reset)
                text = self._filled(text, f, i)
            out.append(text)
            self.held.popleft()
        self._forget()
        return out

    def _forget(self) -> None:
        """Drop the fixes no waiting or later RMC can reach."""
        if not self.fixes:
            return
        ref = self.fixes[self.held[0][2]][0] if self.held else self.fixes[-1][0]
        first = 0
        while first < len(self.fixes) - 1 and _dt(self.fixes[first][0], ref) > COURSE_MAX_DT_S:
            first += 1
        if first:
            del self.fixes[:first]
            self.held = deque((x, f, i - first if f is not None else i) for x, f, i in self.held)

    def _filled(self, text: str, f: list[str], i: int) -> str:
        course = self._course(i, f[7])
        if course is None:
            self.report.notes["course_empty"] += 1
            return text
        self.report.notes["course_from_positions"] += 1
        f[8] = f"{course:.1f}"
        return with_checksum(",".join(f), text[0])

    def _within(self, i: int, j: int) -> bool:
        """Fix ``j`` exists and is within :data:`COURSE_MAX_DT_S` of fix ``i``."""
        return 0 <= j < len(self.fixes) and abs(_dt(self.fixes[i][0], self.fixes[j][0])) <= (
            COURSE_MAX_DT_S
        )

    def _course(self, i: int, sog_cell: str) -> float | None:
        """The bearing over the fixes around fix ``i``, or None (module docstring)."""
        try:
            sog = float(sog_cell) * KNOT_MPS
        except ValueError:
            return None
        both = self._within(i, i - 1) and self._within(i, i + 1)
        for k in range(1, len(self.fixes)):
            a, b = (i - k, i + k) if both else (i - k, i) if self._within(i, i - 1) else (i, i + k)
            if not (self._within(i, a) and self._within(i, b)):
                return None
            verdict = self._bearing(self.fixes[a], self.fixes[b], sog)
            if verdict is not False:
                return verdict
        return None

    @staticmethod
    def _bearing(p: Fix, q: Fix, sog: float) -> float | bool | None:
        """The bearing from ``p`` to ``q``; False when they are too close for one; None
        when their distance over the time disagrees with ``sog``."""
        dt = abs(_dt(p[0], q[0]))
        if dt == 0.0:
            return False
        coslat = math.cos(math.radians(q[1]))
        north = math.radians(q[1] - p[1]) * EARTH_RADIUS_M
        east = math.radians(q[2] - p[2]) * EARTH_RADIUS_M * coslat
        dist = math.hypot(north, east)
        res = MINUTE_M * 10.0 ** (-min(p[3], q[3]))
        if dist < max(COURSE_MIN_DISTANCE_M, COURSE_MIN_RESOLUTIONS * res):
            return False
        slack, frac = COURSE_SPEED_TOLERANCE
        if abs(dist / dt - sog) > slack + frac * sog:
            return None
        return math.degrees(math.atan2(east, north)) % 360.0
