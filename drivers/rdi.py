"""What Teledyne RDI's formats share: the bad-value marker of their 16-bit velocities,
the coordinate frames of the binary formats (PD0, PD4/PD5), and the mapping of a binary
bottom track to a speed record and back (what the encoders write). The decoders read
these as ``rdi.INVALID``, ``rdi.bottom_track`` ...

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import math
from typing import Literal, get_args

from drivers import records
from drivers.records import SpeedRecord

INVALID = -32768
"""Teledyne RDI's bad-value marker in a 16-bit velocity or error velocity (mm/s): PD0,
PD4/PD5 and PD6 alike."""

MAX_MMS = 32767
"""The largest magnitude of a valid RDI 16-bit velocity, mm/s."""

CoordFrame = Literal["beam", "instrument", "ship", "earth"]
"""The frame of an RDI binary velocity (PD0, PD4/PD5), in the order of its two-bit code."""

COORD_FRAMES: tuple[CoordFrame, ...] = get_args(CoordFrame)
"""The frames indexed by their two-bit code."""


def velocities(
    values: tuple[int, ...],
) -> tuple[int | None, int | None, int | None, int | None]:
    """Four RDI 16-bit velocities (mm/s) as read, :data:`INVALID` as None: what the
    PD0 and PD4/PD5 decoders keep."""
    a, b, c, d = (None if x == INVALID else x for x in values)
    return (a, b, c, d)


def mms(v: float | None) -> int:
    """A velocity in m/s as RDI's 16-bit mm/s (clamped to ±:data:`MAX_MMS`), :data:`INVALID`
    for None: what the PD0 and PD4/PD5 encoders write.

    Raises:
        ValueError: a non-finite value.
    """
    if v is None:
        return INVALID
    if not math.isfinite(v):
        raise ValueError(f"cannot encode a non-finite velocity {v!r}")
    return max(min(round(v * 1000.0), MAX_MMS), -MAX_MMS)


def bottom_track(
    port: str,
    frame: CoordFrame,
    lock: bool,
    vessel_mms: tuple[int | None, int | None],
    heading_deg: float | None,
    source: str,
) -> SpeedRecord:
    """An RDI binary bottom track (PD0, PD4/PD5) as a speed record
    (:func:`drivers.records.bottom_track`).

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
            ship = records.ship_frame(a / 1000.0, b / 1000.0, None)
        elif heading_deg is not None:
            ship = records.ship_frame(a / 1000.0, b / 1000.0, heading_deg)
    return records.bottom_track(port, ship, heading_deg, source)


def vessel_mms(
    ship_mps: tuple[float, float], frame: CoordFrame, heading_deg: float
) -> tuple[int, int]:
    """The vessel's (forward, starboard) motion in m/s as the RDI mm/s the PD0 and PD4/PD5
    encoders write (:func:`mms`): (starboard, forward), or in earth coordinates
    (east, north) rotated by the heading; the inverse of :func:`bottom_track`.

    Raises:
        ValueError: a non-finite value.
    """
    fwd, stb = ship_mps
    if frame != "earth":
        return mms(stb), mms(fwd)
    psi = math.radians(heading_deg)
    return (
        mms(fwd * math.sin(psi) + stb * math.cos(psi)),
        mms(fwd * math.cos(psi) - stb * math.sin(psi)),
    )
