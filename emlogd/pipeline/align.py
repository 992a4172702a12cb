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
  several samples with **the same time** (fix times repeated or coarse, receive times
  quantised) stand for that time by the newest of them, the one received last: it
  answers a query at that time and brackets the queries on either side;
- with ``cadence=True`` the gap comes from the series' own rate, not a constant (a
  reference may come at 10 Hz or at 0.2 Hz): each sample carries
  :func:`cadence_gap` of the median of the :data:`CADENCE_INTERVALS` intervals between
  distinct sample times up to and including it, and a query uses the gap of the later
  bracketing sample — so the answer does not depend on when the query is made, and
  a series faster than ``max_gap_s / GAP_INTERVALS`` keeps ``max_gap_s`` (a 10 Hz DVL:
  1 s; 1 Hz GNSS: 2.5 s; 0.5 Hz: 5 s; 0.2 Hz: 12.5 s; slower: :data:`MAX_GAP_CAP_S`);
- headings are angles: interpolated along the shorter arc, so 359° and 1° give 0°,
  never 180°.

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right, insort
from collections import deque
from operator import itemgetter

import numpy as np
import numpy.typing as npt

from calib.models import FloatArray

DEFAULT_MAX_GAP_S = 1.0
"""Largest distance from a query to each bracketing sample, s (a 10 Hz DVL with a
dropped ensemble or two still interpolates; a real outage does not)."""


GAP_INTERVALS = 2.5
"""With ``cadence=True``, each bracketing sample may lie this many median intervals from
the query: a dropped sample or two (or receive times quantised to whole fixes) are
bridged, an outage longer than twice this many intervals never is."""

MAX_GAP_CAP_S = 15.0
"""The cadence-sized gap never exceeds this, s: over longer gaps a vessel's speed is no
longer near-linear in time (a tack, a speed change), and the pairing would teach the
filter the manoeuvre instead of the sensor. A reference slower than one sample in
6 s gets this gap, so one slower than one in 15 s never aligns."""

CADENCE_INTERVALS = 32
"""The cadence is the median of this many most recent intervals between distinct
sample times (a robust rate that follows a change of the reference's rate within
half a minute at 1 Hz)."""


def cadence_gap(median_interval_s: float, floor_s: float) -> float:
    """The alignment gap for a series sampled every ``median_interval_s``, s.

    ``GAP_INTERVALS`` intervals, at least ``floor_s`` and at most
    ``max(MAX_GAP_CAP_S, floor_s)`` (written out: it runs at every sample of a ring).
    """
    g = GAP_INTERVALS * median_interval_s
    lo = g if g > floor_s else floor_s  # max(floor_s, g)
    cap = floor_s if floor_s > MAX_GAP_CAP_S else MAX_GAP_CAP_S  # max(MAX_GAP_CAP_S, floor_s)
    return cap if cap < lo else lo  # min(lo, cap)


def cadence_gaps(t_s: npt.ArrayLike, floor_s: float) -> FloatArray:
    """The gap each sample of a series carries under ``cadence=True``, s, shape (n,).

    The vectorised form of what :meth:`SampleRing.add` computes sample by sample.
    """
    t = np.asarray(t_s, dtype=np.float64)
    out = np.full(t.shape, float(floor_s))
    if t.size < 2:
        return out
    d = np.diff(t)
    pos = d[d > 0.0]
    count = np.concatenate(([0], np.cumsum(d > 0.0)))  # distinct intervals up to sample j
    med = np.empty(pos.size + 1)
    med[0] = np.nan
    for k in range(1, min(pos.size, CADENCE_INTERVALS) + 1):
        med[k] = float(np.median(pos[:k]))
    if pos.size > CADENCE_INTERVALS:
        win = np.lib.stride_tricks.sliding_window_view(pos, CADENCE_INTERVALS)
        med[CADENCE_INTERVALS + 1 :] = np.median(win[1:], axis=1)
    has = count > 0
    g = np.minimum(
        np.maximum(floor_s, GAP_INTERVALS * med[count[has]]), max(MAX_GAP_CAP_S, floor_s)
    )
    out[has] = g
    return out


class MedianWindow:
    """The newest ``size`` values of a series and their order, for its median in O(size).

    Kept sorted as values come and go (a binary search and one list move each), so
    the median is read without sorting the window on every value.
    :meth:`median` equals :func:`statistics.median` of the window and :meth:`upper`
    ``sorted(window)[len // 2]``, exactly.

    Args:
        size: values kept (the oldest is forgotten when a new one comes).

    Raises:
        ValueError: a size below 1.
    """

    __slots__ = ("_order", "_window")

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError("size must be at least 1")
        self._window: deque[float] = deque(maxlen=size)
        self._order: list[float] = []

    def __len__(self) -> int:
        return len(self._window)

    def append(self, value: float) -> None:
        """Add a value (not NaN), forgetting the oldest when the window is full."""
        window = self._window
        order = self._order
        if len(window) == window.maxlen:
            del order[bisect_left(order, window[0])]
        window.append(value)
        insort(order, value)

    def clear(self) -> None:
        """Forget every value."""
        self._window.clear()
        self._order.clear()

    def median(self) -> float:
        """The median (the mean of the two middle values for an even count).

        Raises:
            IndexError: the window is empty.
        """
        order = self._order
        n = len(order)
        i = n // 2
        if not n:
            raise IndexError("median of an empty window")
        return order[i] if n % 2 else (order[i - 1] + order[i]) / 2

    def upper(self) -> float:
        """The upper median (the larger middle value for an even count).

        Raises:
            IndexError: the window is empty.
        """
        return self._order[len(self._order) // 2]

    def lowest(self) -> float:
        """The smallest value.

        Raises:
            IndexError: the window is empty.
        """
        return self._order[0]


_time = itemgetter(0)


def wrap_deg(angle: float) -> float:
    """An angle in degrees mapped to [0, 360)."""
    a = math.fmod(angle, 360.0)
    return a + 360.0 if a < 0.0 else (0.0 if a == 360.0 else a)


class SampleRing:
    """The newest samples of one series, queried at a past time (see the module docstring).

    Args:
        capacity: samples kept (the memory bound).
        max_gap_s: largest distance from a query to each bracketing sample, s (with
            ``cadence``, the least such gap).
        angular: the series is an angle in degrees (interpolated along the shorter arc).
        cadence: the gap follows the series' own rate (:func:`cadence_gap`).

    Raises:
        ValueError: a capacity below 2 or a non-positive gap.
    """

    __slots__ = ("_buf", "_dts", "angular", "cadence", "max_gap_s")

    def __init__(
        self,
        capacity: int,
        max_gap_s: float = DEFAULT_MAX_GAP_S,
        *,
        angular: bool = False,
        cadence: bool = False,
    ) -> None:
        if capacity < 2:
            raise ValueError("capacity must be at least 2")
        if not max_gap_s > 0.0:
            raise ValueError("max_gap_s must be positive")
        self._buf: deque[tuple[float, float, bool, float]] = deque(maxlen=capacity)
        self._dts = MedianWindow(CADENCE_INTERVALS)
        self.max_gap_s = max_gap_s
        self.angular = angular
        self.cadence = cadence

    def add(self, t: float, value: float | None, valid: bool = True) -> bool:
        """Append a sample; False (and nothing kept) when it is older than the newest.

        A sample with no value (None or not finite) is kept as invalid: it marks an
        outage that queries never bridge.
        """
        buf = self._buf
        gap = self.max_gap_s
        if buf:
            last = buf[-1]
            dt = t - last[0]
            if dt < 0.0:
                return False
            if self.cadence:
                if dt > 0.0:
                    self._dts.append(dt)
                gap = last[3] if dt == 0.0 else cadence_gap(self._dts.median(), gap)
        ok = valid and value is not None and math.isfinite(value)
        buf.append((t, value if ok and value is not None else math.nan, ok, gap))
        return True

    def clear(self) -> None:
        """Forget every sample (and the cadence)."""
        self._buf.clear()
        self._dts.clear()

    @property
    def gap_s(self) -> float:
        """The gap the newest sample carries, s (``max_gap_s`` without ``cadence``)."""
        return self._buf[-1][3] if self._buf else self.max_gap_s

    @property
    def newest_t(self) -> float | None:
        """Time of the newest sample, s (None when empty)."""
        return self._buf[-1][0] if self._buf else None

    def newest(self) -> tuple[float, float, bool] | None:
        """The newest sample ``(t, value, valid)``."""
        return self._buf[-1][:3] if self._buf else None

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
        after = buf[bisect_right(buf, buf[i][0], key=_time) - 1]  # the newest at its time
        if not (s[2] and after[2]):
            return None
        gap = after[3]
        if t - s[0] > gap or after[0] - t > gap:
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
    cadence: bool = False,
) -> FloatArray:
    """The alignment rule over whole arrays: :meth:`SampleRing.at` at every query time.

    Args:
        t_s: sample times, s, non-decreasing, shape (n,).
        values: sample values, shape (n,).
        valid: sample validity, shape (n,).
        t_query: query times, s, shape (k,).
        max_gap_s: largest distance from a query to each bracketing sample, s (with
            ``cadence``, the least such gap).
        angular: the values are angles in degrees (shorter arc, result in [0, 360)).
        cadence: the gap follows the series' own rate (:func:`cadence_gaps`).

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
    a_c = np.searchsorted(t, t[a_c], side="right") - 1  # the newest at its time
    gap = cadence_gaps(t, max_gap_s)[a_c] if cadence else np.full(q.shape, float(max_gap_s))
    inner = has_s & ~exact & (idx < n)
    inner &= ok[s_c] & ok[a_c]
    inner &= (q - t[s_c] <= gap) & (t[a_c] - q <= gap)
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
