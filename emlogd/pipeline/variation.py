"""Magnetic variation from position and date, and the heading-against-course check.

**The model.** A magnetic heading (``$IIHDG`` without a variation field, ``$IIVHW``
magnetic only: most yacht logs) becomes true with the variation (declination, east
positive) of the International Geomagnetic Reference Field, IGRF-14, evaluated at the
GNSS position and the fix's date, on the ground (altitude 0). The coefficients and
the spherical-harmonic synthesis come from the ``pyIGRF14`` package (MIT licence;
pure Python with numpy only, which emlogd needs anyway; IGRF-14 covers 1900–2030, so
logs from the 2000s are computed with the definitive models of their own epoch,
which the World Magnetic Model packages, starting in 2010, do not). Outside
:data:`MODEL_YEARS` the model gives nothing, and a magnetic heading then needs a
variation from the log or the configuration.

The main field's variation changes by a few hundredths of a degree per kilometre and
per year, so a value is computed once per :data:`CELL_DEG` cell of position and
day (the cache holds at most :data:`CACHE_SIZE` cells).

**The check.** A heading that is wrong (a magnetic heading taken as true, a badly
mounted or uncalibrated compass) shows as an angle between the heading and the
course over ground that the water cannot explain. On straight legs (the heading
turning slower than :data:`STRAIGHT_DPS`) with the ground speed above
:data:`CHECK_MIN_SOG_MPS`, the cross-track ground speed is regressed on the
along-track one and the heading's cosine and sine,
``SOG·sin(COG − ψ) = tan d · SOG·cos(COG − ψ) + p·cos ψ + q·sin ψ``: the two last
terms take a constant current (whose cross-track part turns with the heading), and
``d`` is the heading's offset from the course through the water. Leeway alternates
sign with the tack and averages out over the legs; a yacht's leeway itself is a few
degrees and rarely over :data:`MAX_HEADING_OFFSET_DEG`, so an offset above it is a
heading error. The offset is decided only once the straight-leg headings cover at
least :data:`CHECK_MIN_SECTORS` sectors of 45° (on one leg current and offset are
one unknown) and :data:`CHECK_MIN_SAMPLES` samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np
import pyIGRF14

from calib.excitation import N_SECTORS, SECTOR_DEG

MODEL_YEARS = (1900.0, 2030.0)
"""The years IGRF-14 covers (decimal years); outside them no model variation."""

CELL_DEG = 0.1
"""A computed variation serves a cell of this size in latitude and longitude, deg."""

CACHE_SIZE = 256
"""Cells kept (a day's passage touches a few dozen)."""

MAX_HEADING_OFFSET_DEG = 10.0
"""Heading-to-course offset on straight legs above which the heading is wrong, deg."""

STRAIGHT_DPS = 3.0
"""A heading turning slower than this is on a straight leg, °/s."""

CHECK_MIN_SOG_MPS = 1.0
"""Below this ground speed the course is too noisy for the check, m/s."""

CHECK_MIN_SECTORS = 3
"""45° heading sectors the straight legs must cover before the offset is decided."""

CHECK_MIN_SAMPLES = 120
"""Straight-leg samples needed before the offset is decided."""

CHECK_MIN_SECTOR_SAMPLES = 10
"""Samples a sector needs to count as covered."""


def decimal_year(t: float) -> float:
    """Epoch seconds (UTC) → decimal year."""
    d = datetime.fromtimestamp(t, UTC)
    start = datetime(d.year, 1, 1, tzinfo=UTC).timestamp()
    end = datetime(d.year + 1, 1, 1, tzinfo=UTC).timestamp()
    return d.year + (t - start) / (end - start)


def model_variation(lat_deg: float, lon_deg: float, t: float) -> float | None:
    """IGRF-14 variation (east positive, deg) at a position and time (epoch s), or None
    outside the model's years or for an impossible position."""
    if not (math.isfinite(lat_deg) and math.isfinite(lon_deg) and math.isfinite(t)):
        return None
    if abs(lat_deg) > 90.0 or abs(lon_deg) > 180.0:
        return None
    try:
        year = decimal_year(t)
    except (OverflowError, OSError, ValueError):
        return None
    if not MODEL_YEARS[0] <= year <= MODEL_YEARS[1]:
        return None
    return _cached(round(lat_deg / CELL_DEG), round(lon_deg / CELL_DEG), round(year * 365.25))


_CACHE: dict[tuple[int, int, int], float] = {}


def _cached(i_lat: int, i_lon: int, day: int) -> float:
    k = (i_lat, i_lon, day)
    v = _CACHE.get(k)
    if v is None:
        if len(_CACHE) >= CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        lat = max(-90.0, min(90.0, i_lat * CELL_DEG))
        v = float(pyIGRF14.igrf_value(lat, i_lon * CELL_DEG, 0.0, day / 365.25)[0])
        _CACHE[k] = v
    return v


@dataclass
class CourseOffsetCheck:
    """The heading-against-course check (module docstring), fed sample by sample.

    Attributes:
        n: straight-leg samples taken.
        sectors: samples per heading sector (:data:`calib.excitation.SECTOR_DEG`, the
            sectors of the calibration's excitation rule).
    """

    n: int = 0
    sectors: list[int] = field(default_factory=lambda: [0] * N_SECTORS)
    _ata: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    _atb: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _last: tuple[float, float] | None = None

    def add(self, t: float, heading_deg: float, sog_mps: float, cog_deg: float) -> None:
        """One fix: time, true heading at that time, ground speed and course."""
        last, self._last = self._last, (t, heading_deg)
        if last is None or t <= last[0] or sog_mps < CHECK_MIN_SOG_MPS:
            return
        turn = abs((heading_deg - last[1] + 180.0) % 360.0 - 180.0) / (t - last[0])
        if turn > STRAIGHT_DPS:
            return
        rel = math.radians(cog_deg - heading_deg)
        psi = math.radians(heading_deg)
        row = np.array([sog_mps * math.cos(rel), math.cos(psi), math.sin(psi)])
        self._ata += np.outer(row, row)
        self._atb += row * (sog_mps * math.sin(rel))
        self.n += 1
        self.sectors[int((heading_deg % 360.0) // SECTOR_DEG) % N_SECTORS] += 1

    @property
    def covered(self) -> int:
        """45° sectors with at least :data:`CHECK_MIN_SECTOR_SAMPLES` samples."""
        return sum(1 for c in self.sectors if c >= CHECK_MIN_SECTOR_SAMPLES)

    def offset_deg(self) -> float | None:
        """The heading's offset from the course through the water (COG side positive),
        deg, once decided (module docstring); None before."""
        if self.n < CHECK_MIN_SAMPLES or self.covered < CHECK_MIN_SECTORS:
            return None
        try:
            x = np.linalg.solve(self._ata, self._atb)
        except np.linalg.LinAlgError:
            return None
        return math.degrees(math.atan(float(x[0])))

    def flagged(self) -> bool:
        """Whether the decided offset exceeds :data:`MAX_HEADING_OFFSET_DEG`."""
        d = self.offset_deg()
        return d is not None and abs(d) > MAX_HEADING_OFFSET_DEG

    def as_dict(self) -> dict[str, object]:
        """Plain types for the status and the JSON of the offline commands."""
        d = self.offset_deg()
        return {
            "offset_deg": None if d is None else round(d, 2),
            "samples": self.n,
            "sectors": self.covered,
            "max_offset_deg": MAX_HEADING_OFFSET_DEG,
            "flagged": self.flagged(),
        }
