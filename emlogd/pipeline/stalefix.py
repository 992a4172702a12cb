"""A GNSS receiver repeating its last fix with new times: the vessel said to move and stay put.

A receiver that lost its fix (its antenna cable cut, no sky) but keeps sending, with
status ``A`` (some do, for a while), or a multiplexer or a logger that replays the last
sentence it had with the time of now, repeats the last position, speed over ground and
course while the vessel moves on. A vessel that moves leaves its position: fixes whose
position, speed and course all stay the first one's while their own speed over ground,
over the time their own clock says passed, makes :data:`STALE_DISTANCE_M` contradict
themselves, and are no reference from then until one of the three moves. A receiver's
position changes with every step of its last digit: a shorter run is the sentence's
resolution, and is kept. The fix's own time, not its receipt's: a logger that wrote one
sentence twice or three times (Psaros's log holds such runs of one fix time at 8.7 kn)
repeated a fix, it did not say the vessel stood still; a sentence without a time is not
judged.

No I/O, no clock.
"""

from __future__ import annotations

from dataclasses import dataclass

STALE_DISTANCE_M = 10.0
"""A repeated fix is stale once its speed over ground, times the time since the run of
equal fixes began (the fixes' own times), passes this, m: five times the 0.001′ (1.85 m) of the coarsest
position a receiver sends (most send 0.0001′, 0.19 m). At 2 m/s, 5 s; at 0.5 m/s, 20 s
(a frozen heading's :data:`~emlogd.pipeline.headingsources.FROZEN_S`)."""


Fix = tuple[float, float, float, float]
"""Latitude and longitude (°), speed over ground (m/s) and course (°), as sent."""


@dataclass
class _Run:
    fix: Fix
    t0: float
    stale: bool = False


class RepeatedFixes:
    """Per GNSS port, the run of fixes equal to its first (:meth:`stale`)."""

    def __init__(self) -> None:
        self.runs: dict[str, _Run] = {}

    def stale(self, t: float, port: str, fix: Fix | None) -> bool | None:
        """Whether the fix of ``port`` of time ``t`` (its own) repeats the first of its run for
        longer than its speed allows (:data:`STALE_DISTANCE_M`); None when it does so
        first (the run has just become stale: an event). ``fix`` None (a sentence
        without a position, speed, course or time: a VTG beside the RMC) is not judged
        and leaves the run as it is."""
        if fix is None:
            return False
        run = self.runs.get(port)
        if run is None or run.fix != fix:
            self.runs[port] = _Run(fix, t)
            return False
        if run.stale:
            return True
        if fix[2] * (t - run.t0) < STALE_DISTANCE_M:
            return False
        run.stale = True
        return None

    def adopt(self, old: RepeatedFixes, port: str) -> None:
        """Keep ``old``'s run of ``port`` (a reload that left the port as it was)."""
        if port in old.runs:
            self.runs[port] = old.runs[port]
