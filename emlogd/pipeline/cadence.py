"""The scored readings' cadence, and what the change detector's baseline needs at it.

The supervisor's change detector (:mod:`emlogd.pipeline.supervisor`) judges on a window
forgetting in time; how many readings that window can hold depends on how often they
come. :class:`Cadence` follows the intervals and says how much weight the baseline
needs before it is judged on: a count at 0.5 Hz and faster, the weight of a span of
readings at a slower cadence.
"""

from __future__ import annotations

import math

from emlogd.pipeline.evidence import CUSUM_MAX_GAP_S

CUSUM_MIN_FILL_S = 30.0
"""Readings slower than one every 2.5 s: the change detector's baseline is judged on once
it holds the weight this long of readings at their cadence gives its window
(:meth:`Cadence.min_weight`), when that is less than the supervisor's sample count. A
window of a 60-s half-life holds at most 18 readings taken every 5 s and forgets over a
CUSUM run (whose samples are kept out of it): after a run of a minute it holds fewer than
ten, and a detector waiting for ten would be off for much of a log at 0.2 Hz while a
calibration stays applied unwatched."""

CADENCE_GAIN = 0.1
"""The weight of each new interval in :class:`Cadence`'s running mean."""


class Cadence:
    """The scored readings' cadence: a running mean of the intervals between them, s
    (an interval over :data:`CUSUM_MAX_GAP_S` is a silence, not a cadence)."""

    def __init__(self) -> None:
        self.dt_s = math.nan
        self.t = -math.inf
        """The last scored reading's time, s (-inf: none yet)."""

    def add(self, t: float) -> None:
        """A scored reading at ``t``."""
        dt = t - self.t
        if 0.0 < dt <= CUSUM_MAX_GAP_S:
            self.dt_s = dt if math.isnan(self.dt_s) else self.dt_s + CADENCE_GAIN * (dt - self.dt_s)
        self.t = t

    def min_weight(self, t: float, min_samples: float, half_life_s: float) -> float:
        """With a scored reading at ``t`` (:meth:`add`): ``min_samples``, or the weight a
        window forgetting with ``half_life_s`` fills to over :data:`CUSUM_MIN_FILL_S` of
        readings at the cadence when that is less."""
        self.add(t)
        dt = self.dt_s
        if not dt > 0.0:
            return min_samples
        fill = (1.0 - 0.5 ** (CUSUM_MIN_FILL_S / half_life_s)) / (1.0 - 0.5 ** (dt / half_life_s))
        return min(min_samples, float(fill))
