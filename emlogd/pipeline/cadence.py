"""The scored readings' cadence, and what the change detector's baseline needs at it.

The supervisor's change detector (:mod:`emlogd.pipeline.detector`) judges on a window
forgetting in time; how many readings that window can hold depends on how often they
come. :class:`Cadence` follows the intervals and says how much weight the baseline
needs before it is judged on: a count at 0.5 Hz and faster, the weight of a span of
readings at a slower cadence. The re-check's window (:data:`RECHECK_MIN_FILL_S`) and a
candidate's validation (:data:`VALIDATION_MIN_FILL_S`) follow the same rule.
"""

from __future__ import annotations

import math
import statistics
from collections import deque

from emlogd.pipeline.evidence import CUSUM_MAX_GAP_S

CUSUM_MIN_FILL_S = 30.0
"""Readings slower than one every 2.5 s: the change detector's baseline is judged on once
it holds the weight this long of readings at their cadence gives its window
(:meth:`Cadence.detector_weight`), when that is less than the detector's sample count. A
window of a 60-s half-life holds at most 18 readings taken every 5 s and forgets over a
CUSUM run (whose samples are kept out of it): after a run of a minute it holds fewer than
ten, and a detector waiting for ten would be off for much of a log at 0.2 Hz while a
calibration stays applied unwatched."""

VALIDATION_MIN_SAMPLES = 20.0
"""A candidate needs at least this many scored samples in its validation window (fewer at
a slow cadence, :data:`VALIDATION_MIN_FILL_S`)."""

RECHECK_MIN_SAMPLES = 60.0
"""The supervisor's re-check judges the applied calibration once its window holds this
many (less at a slow cadence, :data:`RECHECK_MIN_FILL_S`)."""

RECHECK_MIN_FILL_S = 150.0
"""Readings slower than one every 2 s: the re-check judges the applied calibration once
its window holds the weight this long of readings at their cadence gives it, when that is
less than the supervisor's sample count (:meth:`Cadence.weight`). Sixty readings every 5 s
in a window of a 300-s half-life take about 8.5 minutes to gather; a calibration
re-applied on a validation that straddled a step of the sensor stood that long."""

VALIDATION_MIN_FILL_S = 40.0
"""Readings slower than one every 2 s: a candidate's validation needs the readings this
long holds at their cadence, when that is fewer than the supervisor's sample count
(:meth:`Cadence.count`). Twenty readings every 5 s take 100 s: a re-validation that long
straddles what changed within it."""

CADENCE_INTERVALS = 9
"""The cadence is the median of this many most recent intervals (:attr:`Cadence.median_s`):
a reference lost for half a minute in a log read every second (which would move a
running mean past 2 s) is not a slow cadence."""


class Cadence:
    """The scored readings' cadence: the median of the intervals between them, s
    (:data:`CADENCE_INTERVALS`; an interval over :data:`CUSUM_MAX_GAP_S` is a silence,
    not a cadence)."""

    def __init__(self) -> None:
        self._median = math.nan
        self._stale = False
        self._recent: deque[float] = deque(maxlen=CADENCE_INTERVALS)
        self.t = -math.inf
        """The last scored reading's time, s (-inf: none yet)."""

    def add(self, t: float) -> None:
        """A scored reading at ``t``."""
        dt = t - self.t
        if 0.0 < dt <= CUSUM_MAX_GAP_S:
            self._recent.append(dt)
            self._stale = True
        self.t = t

    @property
    def median_s(self) -> float:
        """The median of the last :data:`CADENCE_INTERVALS` intervals, s (nan: none yet)."""
        if self._stale:
            self._median = statistics.median(self._recent)
            self._stale = False
        return self._median

    def detector_weight(self, min_samples: float, half_life_s: float) -> float:
        """The weight the change detector's baseline (forgetting with ``half_life_s``)
        needs: ``min_samples``, or less at a slow cadence (:data:`CUSUM_MIN_FILL_S`)."""
        return self.weight(min_samples, CUSUM_MIN_FILL_S, half_life_s, self.median_s)

    @staticmethod
    def weight(min_samples: float, span_s: float, half_life_s: float, dt: float) -> float:
        """``min_samples``, or the weight a window forgetting with ``half_life_s`` fills
        to over ``span_s`` of readings ``dt`` apart when that is less."""
        if not dt > 0.0:
            return min_samples
        fill = (1.0 - 0.5 ** (span_s / half_life_s)) / (1.0 - 0.5 ** (dt / half_life_s))
        return min(min_samples, float(fill))

    def recheck_weight(self, half_life_s: float) -> float:
        """The weight the re-check's window (forgetting with ``half_life_s``) needs:
        :data:`RECHECK_MIN_SAMPLES`, or less at a slow cadence (:data:`RECHECK_MIN_FILL_S`)."""
        return self.weight(RECHECK_MIN_SAMPLES, RECHECK_MIN_FILL_S, half_life_s, self.median_s)

    def validation_count(self) -> float:
        """The scored samples a candidate's validation needs: :data:`VALIDATION_MIN_SAMPLES`,
        or fewer at a slow cadence (:data:`VALIDATION_MIN_FILL_S`)."""
        return self.count(VALIDATION_MIN_SAMPLES, VALIDATION_MIN_FILL_S)

    def count(self, min_samples: float, span_s: float) -> float:
        """``min_samples``, or the readings ``span_s`` holds at the median cadence when
        fewer."""
        dt = self.median_s
        if not dt > 0.0:
            return min_samples
        return min(min_samples, span_s / dt)
