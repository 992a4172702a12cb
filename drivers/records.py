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
from typing import Literal, get_args

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

RDI_INVALID = -32768
"""Teledyne RDI's bad-value marker in a 16-bit velocity or error velocity (mm/s): PD0,
PD4/PD5 and PD6 alike."""

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


CoordFrame = Literal["beam", "instrument", "ship", "earth"]
"""The frame of an RDI binary velocity (PD0, PD4/PD5), in the order of its two-bit code."""

COORD_FRAMES: tuple[CoordFrame, ...] = get_args(CoordFrame)
"""The frames indexed by their two-bit code."""


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


def rdi_velocities(
    values: tuple[int, ...],
) -> tuple[int | None, int | None, int | None, int | None]:
    """Four RDI 16-bit velocities (mm/s) as read, :data:`RDI_INVALID` as None: what the
    PD0 and PD4/PD5 decoders keep."""
    a, b, c, d = (None if x == RDI_INVALID else x for x in values)
    return (a, b, c, d)


def rdi_mms(v: float | None) -> int:
    """A velocity in m/s as RDI's 16-bit mm/s (clamped to ±32767), :data:`RDI_INVALID`
    for None: what the PD0 and PD4/PD5 encoders write.

    Raises:
        ValueError: a non-finite value.
    """
    if v is None:
        return RDI_INVALID
    if not math.isfinite(v):
        raise ValueError(f"cannot encode a non-finite velocity {v!r}")
    return max(min(round(v * 1000.0), 32767), -32767)


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


def rdi_bottom_track(
    port: str,
    frame: CoordFrame,
    lock: bool,
    vessel_mms: tuple[int | None, int | None],
    heading_deg: float | None,
    source: str,
) -> SpeedRecord:
    """An RDI binary bottom track (PD0, PD4/PD5) as a speed record (:func:`bottom_track`).

    Args:
        port: the port's name.
        frame: the velocity's coordinate frame.
        lock: the instrument has a bottom lock.
        vessel_mms: the vessel's motion, mm/s (None: bad): (starboard, forward), or
            (east, north) in earth coordinates, rotated into the ship frame by the heading.
        heading_deg: the instrument's heading (taken as true), or None.
        source: the record's source, e.g. ``"PD0:BT"``.

    Returns:
        The record, invalid in beam coordinates, without a lock, with a bad component,
        or in earth coordinates without a heading.
    """
    a, b = vessel_mms
    earth = frame == "earth"
    ship = None
    if lock and frame != "beam" and a is not None and b is not None:
        if not earth:
            ship = ship_frame(a / 1000.0, b / 1000.0, None)
        elif heading_deg is not None:
            ship = ship_frame(a / 1000.0, b / 1000.0, heading_deg)
    return bottom_track(port, ship, heading_deg, source)


def rdi_vessel_mms(
    ship_mps: tuple[float, float], frame: CoordFrame, heading_deg: float
) -> tuple[int, int]:
    """The vessel's (forward, starboard) motion in m/s as the RDI mm/s the PD0 and PD4/PD5
    encoders write (:func:`rdi_mms`): (starboard, forward), or in earth coordinates
    (east, north) rotated by the heading; the inverse of :func:`rdi_bottom_track`.

    Raises:
        ValueError: a non-finite value.
    """
    fwd, stb = ship_mps
    if frame != "earth":
        return rdi_mms(stb), rdi_mms(fwd)
    psi = math.radians(heading_deg)
    return (
        rdi_mms(fwd * math.sin(psi) + stb * math.cos(psi)),
        rdi_mms(fwd * math.cos(psi) - stb * math.sin(psi)),
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
