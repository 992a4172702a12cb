"""Records common to every protocol.

Protocol modules define their own frozen, slotted record dataclasses (``Vhw``,
``Pd0Ensemble``, ...). This module holds what all of them share:

- :class:`SpeedRecord`, the common speed record every protocol maps to, so the
  pipeline never cares which sensor produced a speed;
- :class:`Rejected`, yielded for a rejected frame when a decoder runs with
  ``errors="yield"``.

Decoders never read a clock: the receive time travels beside the records.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from drivers.errors import OutOfRangeError, RejectReason

SpeedKind = Literal["stw", "sog"]
"""``stw``: through water (EMlog, DVL water track); ``sog``: over ground (DVL bottom track)."""

SpeedRole = Literal["bottom", "water", "speed", "ground"]
"""What instrument a speed record measures with, set by the driver (never looked up from
:attr:`SpeedRecord.source`):

- ``bottom``: a DVL's bottom track (PD6 ``:BS``, PD0/PD4/PD5 bottom track, Rowe PRTI01);
- ``water``: a DVL's water-mass track (PD6 ``:WS``);
- ``speed``: a speed log's reading through the water (VHW, the VBW water pair);
- ``ground``: a speed log's ground pair (VBW), which the pipeline does not use.

The first three are also the names of the reference fields of the configuration."""

KNOT_MPS = 1852.0 / 3600.0
"""One international knot in m/s (exact)."""

KMH_MPS = 1000.0 / 3600.0
"""One km/h in m/s (exact)."""

# Physical ranges the decoders check every field against (docs/PROTOCOLS.md, "Field
# ranges"): a value outside is an ``out_of_range`` reject, never a record.

WATER_TEMP_RANGE_C = (-5.0, 60.0)
"""Plausible water (or instrument) temperature, °C."""

SALINITY_RANGE_PPT = (0.0, 50.0)
"""Plausible salinity, ppt."""

SOUND_SPEED_RANGE_MPS = (1300.0, 1700.0)
"""Plausible speed of sound in water, m/s."""

MAX_PITCH_DEG = 90.0
"""Largest pitch magnitude, degrees."""

MAX_ROLL_DEG = 180.0
"""Largest roll magnitude, degrees."""

MAX_DEPTH_M = 12_000.0
"""Deepest instrument or bottom depth, m (the deepest ocean is ~11 km)."""

PHYSICAL_RANGES: dict[str, tuple[float, float]] = {
    "pitch": (-MAX_PITCH_DEG, MAX_PITCH_DEG),
    "roll": (-MAX_ROLL_DEG, MAX_ROLL_DEG),
    "heading": (0.0, 360.0),
    "temperature": WATER_TEMP_RANGE_C,
    "salinity": SALINITY_RANGE_PPT,
    "sound_speed": SOUND_SPEED_RANGE_MPS,
    "depth": (0.0, MAX_DEPTH_M),
}
"""The closed range of each physical field :func:`check_ranges` checks, by field name
(degrees, °C, ppt, m/s, m)."""


def check_ranges(what: str, raw: bytes, **fields: float) -> None:
    """Each field (a :data:`PHYSICAL_RANGES` name) within its range; NaN is outside.

    Args:
        what: the block the fields came from, for the message (e.g. ``":TS"``).
        raw: the rejected bytes.
        **fields: the values by field name.

    Raises:
        OutOfRangeError: naming every field outside its range.
        KeyError: a field name with no range.
    """
    bad = [
        f"{name.replace('_', ' ')} {v}"
        for name, v in fields.items()
        if not PHYSICAL_RANGES[name][0] <= v <= PHYSICAL_RANGES[name][1]
    ]
    if bad:
        raise OutOfRangeError(f"{what} {', '.join(bad)} out of range", raw)


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedRecord:
    """One vessel speed measurement in the ship frame, SI units, vessel-motion sign.

    Built by keyword only (nine fields, four of them floats or None).

    Attributes:
        port: name of the port that produced it.
        kind: ``"stw"`` through water or ``"sog"`` over ground.
        role: what measured it (:data:`SpeedRole`).
        longitudinal_mps: forward speed, m/s, + = ahead. For VHW this is the
            speed through water as reported (the resultant on a two-axis log).
        transverse_mps: athwartships speed, m/s, + = to starboard; None if the
            sensor does not measure it (the default).
        valid: False when the sensor flagged the measurement as invalid
            (status V, -32768, no bottom lock). Invalid records are still
            passed on so that the pipeline can see a reference loss.
        heading_true_deg: true heading sent with the speed, degrees, or None. A DVL's
            heading is taken as true (the instrument applies its own variation setting).
            None by default.
        heading_mag_deg: magnetic heading sent with the speed (VHW), degrees, or None
            (the default).
        source: the sentence or block it came from, e.g. ``"VHW"``, ``"VBW"``,
            ``"PD6:BS"``, ``"PD0:BT"`` (for people and for matching a UUT's configured
            sentence; routing uses :attr:`role`).
    """

    port: str
    kind: SpeedKind
    role: SpeedRole
    longitudinal_mps: float | None
    transverse_mps: float | None = None
    valid: bool
    heading_true_deg: float | None = None
    heading_mag_deg: float | None = None
    source: str

    @property
    def speed_mps(self) -> float | None:
        """Horizontal speed magnitude in m/s (longitudinal alone if no transverse)."""
        if self.longitudinal_mps is None:
            return None
        if self.transverse_mps is None:
            return abs(self.longitudinal_mps)
        return math.hypot(self.longitudinal_mps, self.transverse_mps)


def ship_frame(a: float, b: float, heading_deg: float | None) -> tuple[float, float]:
    """A DVL's horizontal velocity (m/s) as (longitudinal, transverse) in the ship frame:
    ``(a, b)`` is (east, north) when a heading is given (earth coordinates, rotated by
    it), else (starboard, forward)."""
    if heading_deg is None:
        return b, a
    psi = math.radians(heading_deg)
    return a * math.sin(psi) + b * math.cos(psi), a * math.cos(psi) - b * math.sin(psi)


def bottom_track(
    port: str, ship: tuple[float, float] | None, heading_deg: float | None, source: str
) -> SpeedRecord:
    """A DVL's bottom track as a speed record (``sog``, role ``bottom``): ``ship`` is
    (longitudinal, transverse) in m/s, None when the instrument gives no valid track;
    the instrument's heading is taken as true."""
    return SpeedRecord(
        port=port,
        kind="sog",
        role="bottom",
        longitudinal_mps=None if ship is None else ship[0],
        transverse_mps=None if ship is None else ship[1],
        valid=ship is not None,
        heading_true_deg=heading_deg,
        source=source,
    )


@dataclass(frozen=True, slots=True)
class Rejected:
    """A rejected frame, yielded only when a decoder runs with ``errors="yield"``.

    Attributes:
        port: port name.
        reason: the reject counter it incremented.
        detail: a human-readable explanation.
        raw: the offending bytes (truncated to 256).
    """

    port: str
    reason: RejectReason
    detail: str
    raw: bytes
