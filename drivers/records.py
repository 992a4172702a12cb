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

from drivers.errors import RejectReason

SpeedKind = Literal["stw", "sog"]
"""``stw``: through water (EMlog, DVL water track); ``sog``: over ground (DVL bottom track)."""

KNOT_MPS = 1852.0 / 3600.0
"""One international knot in m/s (exact)."""

KMH_MPS = 1000.0 / 3600.0
"""One km/h in m/s (exact)."""


@dataclass(frozen=True, slots=True)
class SpeedRecord:
    """One vessel speed measurement in the ship frame, SI units, vessel-motion sign.

    Attributes:
        port: name of the port that produced it.
        kind: ``"stw"`` through water or ``"sog"`` over ground.
        longitudinal_mps: forward speed, m/s, + = ahead. For VHW this is the
            speed through water as reported (the resultant on a two-axis log).
        transverse_mps: athwartships speed, m/s, + = to starboard; None if the
            sensor does not measure it.
        valid: False when the sensor flagged the measurement as invalid
            (status V, -32768, no bottom lock). Invalid records are still
            passed on so that the pipeline can see a reference loss.
        heading_deg: heading in degrees (true if known, else magnetic), None if unknown.
        source: the sentence or block it came from, e.g. ``"VHW"``, ``"VBW"``,
            ``"PD6:BS"``, ``"PD0:BT"``.
    """

    port: str
    kind: SpeedKind
    longitudinal_mps: float | None
    transverse_mps: float | None
    valid: bool
    heading_deg: float | None
    source: str

    @property
    def speed_mps(self) -> float | None:
        """Horizontal speed magnitude in m/s (longitudinal alone if no transverse)."""
        if self.longitudinal_mps is None:
            return None
        if self.transverse_mps is None:
            return abs(self.longitudinal_mps)
        return math.hypot(self.longitudinal_mps, self.transverse_mps)


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
