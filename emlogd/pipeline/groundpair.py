"""The ground pair of a UUT's corrected VBW: its reference's speed over ground on the hull.

IMO A.824(19) §2.6 asks a log that indicates speeds other than fore and aft for both
the forward and the athwart speeds with their validity. The corrected ``$--VBW`` carries
the speed through the water the UUT measured (corrected) and, in its ground pair, the
vessel's speed over ground along and across the hull as its reference gave it last:

- a DVL's **bottom track** (PD6 ``:BS``, PD0/PD4/PD5, in the ship frame or rotated into
  it from the earth frame by the instrument's heading) from the UUT's reference port,
  whatever field the UUT calibrates against;
- a **GNSS** speed and course projected on the hull with the UUT's heading at the fix's
  time (``SOG·cos(COG − ψ)``, ``SOG·sin(COG − ψ)``), for a UUT whose reference is GNSS,
  when the projection along the hull is valid (:meth:`~emlogd.pipeline.routing.UutRoute.project`).

A record flagged invalid (no bottom lock, a bad component, beam coordinates, a GNSS fix
without status A or a fix, below ``min_sog_mps``, a heading the course check flagged),
or one whose along or across speed jumps faster than the UUT's ``max_accel_mps2`` allows
(each axis through a glitch filter like the reference's,
:class:`~emlogd.pipeline.integrity.JumpFilter`), withdraws the pair at once; a pair older than the reference's staleness bound
(``ref_stale_s``, judged by :func:`~emlogd.pipeline.staleness.silent`) is not sent. The
sentence then carries the ground pair empty with status ``V``.

Until a UUT's first VBW asks for the pair, only the reference's latest sample is kept,
as it came (a log sending VHW alone pays one tuple per reference sample); the first
VBW's look-up passes it through the checks above, so that VBW carries the pair when the
reference's latest sample is valid and fresh, and ``V`` only when no reference sample
has arrived, the latest is invalid, or it is older than the staleness bound.
"""

from __future__ import annotations

import math

from drivers.records import SpeedRecord
from emlogd.pipeline.integrity import JumpFilter
from emlogd.pipeline.staleness import silent


class GroundPair:
    """The latest valid speed over ground along and across the hull of one UUT's reference.

    Args:
        stale_s: the reference's staleness bound, s (the UUT's ``ref_stale_s``).
        max_accel_mps2: the largest acceleration on either axis, m/s² (the UUT's
            ``max_accel_mps2``).
        margin_mps: a change always allowed on either axis, m/s (the reference's
            glitch filter's).
    """

    __slots__ = ("jumps", "latest", "stale_s", "unchecked", "wanted")

    def __init__(self, stale_s: float, max_accel_mps2: float, margin_mps: float) -> None:
        self.stale_s = stale_s
        self.jumps = (
            JumpFilter(max_accel_mps2, margin_mps),
            JumpFilter(max_accel_mps2, margin_mps),
        )
        """The glitch filters of the along and the across speed."""
        self.wanted = False
        """Whether a VBW asked for the pair (:meth:`at`): until then only
        :attr:`unchecked` is kept."""
        self.unchecked: tuple[float, float | None, float | None, bool] | None = None
        """Before the first VBW: the reference's latest sample as it came (receive time
        s, along, across, valid), checked by the first look-up."""
        self.latest: tuple[float, float, float] | None = None
        """The latest valid pair: (receive time s, along m/s + ahead, across m/s + to
        starboard); None after an invalid record."""

    def add(self, t: float, along: float | None, across: float | None, valid: bool) -> None:
        """A reference sample at ``t``: kept when valid, finite and no glitch on either
        axis, else the pair is withdrawn; before a VBW asked for the pair, kept unchecked
        (:attr:`unchecked`)."""
        if not self.wanted:
            self.unchecked = (t, along, across, valid)
            return
        if (
            valid
            and along is not None
            and across is not None
            and math.isfinite(along)
            and math.isfinite(across)
            and self.jumps[0].accept(t, along) & self.jumps[1].accept(t, across)  # both see it
        ):
            self.latest = (t, along, across)
        else:
            self.latest = None

    def bottom(self, t: float, sp: SpeedRecord) -> None:
        """A speed record of the reference's port: only a bottom track is a ground pair."""
        if sp.role == "bottom":
            self.add(t, sp.longitudinal_mps, sp.transverse_mps, sp.valid)

    def at(self, t: float) -> tuple[float, float] | None:
        """The pair (along, across) m/s to send with a reading at ``t``: None without a
        valid one, or when it is older than the staleness bound."""
        if not self.wanted:
            self.wanted = True
            if self.unchecked is not None:
                self.add(*self.unchecked)
                self.unchecked = None
        g = self.latest
        if g is None or silent(g[0], t, self.stale_s):
            return None
        return g[1], g[2]
