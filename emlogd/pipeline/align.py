"""Alignment: a sensor's samples kept in a fixed ring and read back at a past time.

One rule, used by the daemon, ``emlogd replay`` and the offline commands alike. It is
written twice, once per shape of data, and tested equal: :class:`SampleRing` for a
stream (the daemon's fixed-memory ring, queried near its newest end) and
:func:`interpolate` for whole recordings (the offline commands, vectorised):

- a series is queried at time ``t`` by linear interpolation between the two samples
  that bracket ``t``, only when **both are valid and each lies within** ``max_gap_s``
  of ``t`` — an outage is never bridged, and a query past the newest sample gets
  nothing (the caller waits for the next sample instead of extrapolating);
- a sample exactly at ``t`` answers alone;
- samples arrive in time order; an older one than the newest is stale and refused;
- headings are angles: interpolated along the shorter arc, so 359° and 1° give 0°,
  never 180°.

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from operator import itemgetter

import numpy as np
import numpy.typing as npt

from calib.models import FloatArray

DEFAULT_MAX_GAP_S = 1.0
"""Largest distance from a query to each bracketing sample, s (a 10 Hz DVL with a
dropped ensemble or two still interpolates; a real outage does not)."""


_time = itemgetter(0)


def wrap_deg(angle: float) -> float:
    """An angle in degrees mapped to [0, 360)."""
    a = math.fmod(angle, 360.0)
    return a + 360.0 if a < 0.0 else (0.0 if a == 360.0 else a)


class SampleRing:
    """The newest samples of one series, queried at a past time (see the module docstring).

    Args:
        capacity: samples kept (the memory bound).
        max_gap_s: largest distance from a query to each bracketing sample, s.
        angular: the series is an angle in degrees (interpolated along the shorter arc).

    Raises:
        ValueError: a capacity below 2 or a non-positive gap.
    """

    __slots__ = ("_buf", "angular", "max_gap_s")

    def __init__(
        self, capacity: int, max_gap_s: float = DEFAULT_MAX_GAP_S, *, angular: bool = False
    ) -> None:
        if capacity < 2:
            raise ValueError("capacity must be at least 2")
        if not max_gap_s > 0.0:
            raise ValueError("max_gap_s must be positive")
        self._buf: deque[tuple[float, float, bool]] = deque(maxlen=capacity)
        self.max_gap_s = max_gap_s
        self.angular = angular

    def add(self, t: float, value: float | None, valid: bool = True) -> bool:
        """Append a sample; False (and nothing kept) when it is older than the newest.

        A sample with no value (None or not finite) is kept as invalid: it marks an
        outage that queries never bridge.
        """
        buf = self._buf
        if buf and t < buf[-1][0]:
            return False
        ok = valid and value is not None and math.isfinite(value)
        buf.append((t, value if ok and value is not None else math.nan, ok))
        return True

    def clear(self) -> None:
        """Forget every sample."""
        self._buf.clear()

    @property
    def newest_t(self) -> float | None:
        """Time of the newest sample, s (None when empty)."""
        return self._buf[-1][0] if self._buf else None

    def newest(self) -> tuple[float, float, bool] | None:
        """The newest sample ``(t, value, valid)``."""
        return self._buf[-1] if self._buf else None

    def covers(self, t: float) -> bool:
        """A sample at or after ``t`` has arrived (a query at ``t`` is final)."""
        return bool(self._buf) and self._buf[-1][0] >= t

    def at(self, t: float) -> float | None:
        """The series at time ``t`` by the alignment rule, or None."""
        buf = self._buf
        i = bisect_right(buf, t, key=_time)  # buf[i - 1] is the newest sample at or before t
        if i == 0:
            return None
        s = buf[i - 1]
        if s[0] == t:
            return s[1] if s[2] else None
        if i == len(buf):
            return None
        after = buf[i]
        if not (s[2] and after[2]):
            return None
        if t - s[0] > self.max_gap_s or after[0] - t > self.max_gap_s:
            return None
        w = (t - s[0]) / (after[0] - s[0])
        if self.angular:
            d = (after[1] - s[1] + 180.0) % 360.0 - 180.0
            return wrap_deg(s[1] + w * d)
        return s[1] + w * (after[1] - s[1])

    def nearest(self, t: float, max_dist_s: float) -> float | None:
        """The value of the valid sample nearest ``t`` within ``max_dist_s``, or None."""
        best: tuple[float, float] | None = None
        for s in reversed(self._buf):
            d = abs(s[0] - t)
            if s[2] and d <= max_dist_s and (best is None or d < best[0]):
                best = (d, s[1])
            if s[0] < t - max_dist_s:
                break
        return None if best is None else best[1]

    def __len__(self) -> int:
        return len(self._buf)


def interpolate(
    t_s: npt.ArrayLike,
    values: npt.ArrayLike,
    valid: npt.ArrayLike,
    t_query: npt.ArrayLike,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
    *,
    angular: bool = False,
) -> FloatArray:
    """The alignment rule over whole arrays: :meth:`SampleRing.at` at every query time.

    Args:
        t_s: sample times, s, non-decreasing, shape (n,).
        values: sample values, shape (n,).
        valid: sample validity, shape (n,).
        t_query: query times, s, shape (k,).
        max_gap_s: largest distance from a query to each bracketing sample, s.
        angular: the values are angles in degrees (shorter arc, result in [0, 360)).

    Returns:
        The values at the query times, nan where the rule gives nothing, shape (k,).
    """
    t = np.asarray(t_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool) & np.isfinite(v)
    q = np.asarray(t_query, dtype=np.float64)
    out = np.full(q.shape, np.nan)
    n = t.size
    if n == 0:
        return out
    idx = np.searchsorted(t, q, side="right")
    s = idx - 1
    has_s = s >= 0
    s_c = np.clip(s, 0, n - 1)
    exact = has_s & (t[s_c] == q)
    out[exact & ok[s_c]] = v[s_c][exact & ok[s_c]]
    a_c = np.clip(idx, 0, n - 1)
    inner = has_s & ~exact & (idx < n)
    inner &= ok[s_c] & ok[a_c]
    inner &= (q - t[s_c] <= max_gap_s) & (t[a_c] - q <= max_gap_s)
    span = np.where(inner, t[a_c] - t[s_c], 1.0)
    w = np.where(inner, (q - t[s_c]) / span, 0.0)
    lo, hi = v[s_c], v[a_c]
    if angular:
        d = (hi - lo + 180.0) % 360.0 - 180.0
        val = np.mod(lo + w * d, 360.0)
    else:
        val = lo + w * (hi - lo)
    out[inner] = val[inner]
    return out
