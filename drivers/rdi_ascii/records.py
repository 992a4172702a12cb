"""The records of a PD6/PD13 ensemble and the order of its lines.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias, get_args

ORDER = ("SA", "TS", "RA", "WI", "WS", "WE", "WD", "BI", "BS", "BE", "BD")
"""Line types of one ensemble, in transmission order."""

_RANK = {k: i for i, k in enumerate(ORDER)}

_LAST = len(ORDER) - 1
"""The rank of ``:BD``, the line that ends an ensemble."""

_NOT_SENT = object()
"""The value of a block's line that has not arrived (an invalid vector's is None)."""


@dataclass(frozen=True, slots=True)
class Velocity:
    """A velocity triple (plus the error velocity for the instrument frame), m/s.

    Attributes:
        a, b, c: the components (instrument X/Y/Z, ship T/L/N, earth E/N/U).
        error: error velocity (instrument frame only), m/s, or None.
    """

    a: float
    b: float
    c: float
    error: float | None = None


@dataclass(frozen=True, slots=True)
class DistanceMadeGood:
    """``:WD``/``:BD``: distance made good east/north/up (m), range (m), time since good (s)."""

    east_m: float
    north_m: float
    up_m: float
    range_m: float
    time_since_good_s: float


@dataclass(frozen=True, slots=True)
class Pd6Ensemble:
    """One PD6/PD13 ensemble (velocities None when invalid or not sent).

    Attributes:
        pitch_deg, roll_deg, heading_deg: attitude, degrees.
        timestamp: the DVL clock ``YYMMDDHHmmsshh`` as sent.
        salinity_ppt, temperature_c, depth_m, sound_speed_mps: :TS environment.
        bit: built-in-test result.
        pressure_kpa: :RA pressure (PD13), or None.
        beam_ranges_m: :RA range to bottom per beam, m (PD13), or None.
        water_instrument, water_ship, water_earth: water-mass velocities.
        water_dmg: :WD, or None.
        bottom_instrument, bottom_ship, bottom_earth: bottom-track velocities.
        bottom_dmg: :BD, or None.
    """

    pitch_deg: float
    roll_deg: float
    heading_deg: float
    timestamp: str
    salinity_ppt: float
    temperature_c: float
    depth_m: float
    sound_speed_mps: float
    bit: int
    pressure_kpa: float | None
    beam_ranges_m: tuple[float, float, float, float] | None
    water_instrument: Velocity | None
    water_ship: Velocity | None
    water_earth: Velocity | None
    water_dmg: DistanceMadeGood | None
    bottom_instrument: Velocity | None
    bottom_ship: Velocity | None
    bottom_earth: Velocity | None
    bottom_dmg: DistanceMadeGood | None

    @property
    def bottom_range_m(self) -> float | None:
        """Range to the bottom from :BD, m (None if not sent)."""
        return self.bottom_dmg.range_m if self.bottom_dmg is not None else None


@dataclass(frozen=True, slots=True)
class PdHealth:
    """A Pathfinder ``:HM`` system-health line, fields kept as text (not all documented)."""

    fields: tuple[str, ...]


Pd6Record: TypeAlias = Pd6Ensemble | PdHealth
"""Every record :class:`PdAsciiDecoder` yields (besides :class:`~drivers.records.Rejected`)."""

RECORDS: tuple[type[Pd6Record], ...] = get_args(Pd6Record)
"""The members of :data:`Pd6Record`, in its order."""

RECORD_PARTS = (Velocity, DistanceMadeGood)
"""The dataclasses nested in a :class:`Pd6Ensemble` (never yielded on their own)."""
