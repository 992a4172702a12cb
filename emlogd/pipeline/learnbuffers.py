"""The learner's bounded buffers: the block means it learns from, and the series the
one-off lag estimate is made on.

:class:`BlockMeans` averages consecutive blocks of learnt-from samples (the streaming
form of :func:`calib.lsq.block_average`); :class:`LagFinder` holds the UUT's, its
reference's and its heading's recent samples until :func:`calib.lag.estimate_lag`
gives a lag :func:`calib.lag.accept` takes. Nothing here reads a clock or does I/O.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from calib.errors import CalibrationError
from calib.lag import LAG_FALLBACK_S, MIN_LAG_CORRELATION, LagEstimate, accept, estimate_lag
from calib.lsq import BLOCK_MAX_GAP_S, MIN_HEADING_COHERENCE
from calib.models import FloatArray, HeadingCS
from emlogd.pipeline.lagcheck import LAG_CHECK_AUTO_CONFIRM, LAG_CHECK_TOLERANCE_S

LAG_WINDOW_GROWTH = 4.0
"""A refused lag estimate lets the window grow up to this many times ``lag_window_s``."""

LAG_MAX_RATE_HZ = 20.0
"""Reference samples per second the lag window is sized for (a 10 Hz DVL twice over)."""


class BlockMeans:
    """Consecutive blocks of learnt-from samples, averaged (:data:`emlogd.pipeline.learner.AVERAGE_S`); the
    streaming form of :func:`calib.lsq.block_average`, with its rules.

    A block closes after ``window_s`` (samples that cannot be learnt from are left out);
    it is dropped when the set of unknowns learning changes, a gap between its samples
    exceeds 5 s, the heading comes or goes, or the heading turned too much
    inside it (its mean heading vector shorter than :data:`MIN_HEADING_COHERENCE`).
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self.clear()

    def clear(self) -> None:
        """Drop the block being collected."""
        self.n = 0
        self.t0 = self.t_last = 0.0
        self.raw = self.ref = self.c = self.s = 0.0
        self.learn: frozenset[str] = frozenset()
        self.with_heading = False

    def add(
        self,
        t: float,
        raw: float,
        ref: float,
        cs: HeadingCS,
        learn: frozenset[str],
    ) -> tuple[float, float, HeadingCS, frozenset[str]] | None:
        """Add a sample; the block's (raw, ref, (cos, sin), unknowns) when it closes."""
        if self.n and (
            learn != self.learn
            or t - self.t_last > BLOCK_MAX_GAP_S
            or (cs is not None) != self.with_heading
        ):
            self.clear()
        if not self.n:
            self.t0, self.learn, self.with_heading = t, learn, cs is not None
        self.n += 1
        self.t_last = t
        self.raw += raw
        self.ref += ref
        if cs is not None:
            self.c += cs[0]
            self.s += cs[1]
        if t - self.t0 < self.window_s:
            return None
        n, learn_set = self.n, self.learn
        mean_cs: HeadingCS = None
        if self.with_heading:
            c, s = self.c / n, self.s / n
            norm = math.hypot(c, s)
            if norm < MIN_HEADING_COHERENCE:
                self.clear()
                return None
            mean_cs = (c / norm, s / norm)
        out = (self.raw / n, self.ref / n, mean_cs, learn_set)
        self.clear()
        return out


class LagFinder:
    """Bounded series of the UUT, its reference and heading for the one-off lag estimate.

    The first estimate is made over ``window_s``; a refused one keeps the data and
    waits for a window half as long again, up to :data:`LAG_WINDOW_GROWTH` times the
    first (a broad correlation peak sharpens with more data); beyond that the older
    half is dropped and the window slides. Only an estimate :func:`calib.lag.accept`
    takes (never negative, within ``max_lag_s``, σ within
    :data:`calib.lag.MAX_LAG_STD_S`) is used, and it is final; until then the UUT
    learns on :data:`calib.lag.LAG_FALLBACK_S`.

    Searches in a row (:data:`~emlogd.pipeline.lagcheck.LAG_CHECK_AUTO_CONFIRM`) whose
    clear peak (:data:`calib.lag.MIN_LAG_CORRELATION`) is at the same bound say the log
    is later than ``max_lag_s`` (the upper bound) or its reference later than the log by
    more than ``max_lag_s`` (the lower: a reference buffered on its way, a clock offset
    between ports; no latency of the log is negative) (the correlation still rises
    there, window after window):
    the fallback pairs each reading with the reference of another moment (:attr:`beyond`
    says so, and the UUT learns and applies nothing) until an estimate is accepted or a
    search's clear peak lies within the lag check's tolerance of the fallback
    (:data:`~emlogd.pipeline.lagcheck.LAG_CHECK_TOLERANCE_S`). A log whose readings
    are too sparse for the lag check (most of them dropped for the rate) is so told.
    """

    def __init__(self, window_s: float, max_lag_s: float, with_heading: bool) -> None:
        self.window_s = window_s
        self.target_s = window_s
        self.max_lag_s = max_lag_s
        self.with_heading = with_heading
        cap = int((LAG_WINDOW_GROWTH * window_s + 2 * max_lag_s) * LAG_MAX_RATE_HZ) + 64
        self.uut = _Series(cap)
        self.ref = _Series(cap)
        self.heading = _Series(cap)
        self.beyond = ""
        """Why the log lags its reference beyond the search (empty: not known to)."""
        self.at_bound = 0
        """Searches in a row whose clear peak was at the same bound."""
        self.bound_side = 0.0
        """The bound of the last search's clear peak: +1 upper, −1 lower, 0 neither."""

    def ready(self) -> bool:
        """The UUT series spans the current target window."""
        return self.uut.span() >= self.target_s

    def span(self) -> float:
        """Time the UUT series spans, s."""
        return self.uut.span()

    def estimate(self) -> tuple[float | None, float, str]:
        """``(lag, std, why)``: an accepted lag, or None and why (the window grows)."""
        try:
            est = estimate_lag(
                self.uut.times(),
                self.uut.values(),
                self.ref.times(),
                self.ref.values(),
                self.max_lag_s,
                step_s=0.1,
                heading=(self.heading.times(), self.heading.values())
                if self.with_heading
                else None,
            )
        except CalibrationError as exc:
            why = str(exc)
        else:
            why = accept(est, max_lag_s=self.max_lag_s)
            self._beyond(est)
            if not why:
                self.beyond = ""
                return est.lag_s, est.std_s, f"r={est.peak_corr:.2f}, σ {est.std_s:.3f} s"
        self._grow()
        return None, math.inf, why

    def _beyond(self, est: LagEstimate) -> None:
        """Whether ``est`` says the log lags beyond the search, or agrees with the
        fallback lag (:attr:`beyond`; else it stands)."""
        clear = est.peak_corr >= MIN_LAG_CORRELATION
        bound = clear and est.at_bound
        side = math.copysign(1.0, est.lag_s) if bound and est.lag_s != 0.0 else 0.0
        same = side != 0.0 and side == self.bound_side
        self.at_bound = self.at_bound + 1 if same else (1 if side else 0)
        self.bound_side = side
        if clear and not bound and abs(est.lag_s - LAG_FALLBACK_S) <= LAG_CHECK_TOLERANCE_S:
            self.beyond = ""
        elif self.at_bound >= LAG_CHECK_AUTO_CONFIRM and not self.beyond:
            who = "the log lags its reference" if side > 0 else "the reference lags the log"
            self.beyond = (
                f"{who} beyond max_lag_s: {self.at_bound} lag searches "
                f"in a row peak at their bound ({est.lag_s:+.1f} s, r={est.peak_corr:.2f})"
            )

    def _grow(self) -> None:
        if self.target_s < LAG_WINDOW_GROWTH * self.window_s:
            self.target_s = min(1.5 * self.target_s, LAG_WINDOW_GROWTH * self.window_s)
        else:
            for q in (self.uut, self.ref, self.heading):
                q.drop_older_half()


class _Series:
    """Two bounded deques of floats (times and values): lean fixed memory."""

    __slots__ = ("t", "v")

    def __init__(self, cap: int) -> None:
        self.t: deque[float] = deque(maxlen=cap)
        self.v: deque[float] = deque(maxlen=cap)

    def append(self, item: tuple[float, float]) -> None:
        self.t.append(item[0])
        self.v.append(item[1])

    def span(self) -> float:
        return self.t[-1] - self.t[0] if self.t else 0.0

    def times(self) -> FloatArray:
        return np.fromiter(self.t, dtype=np.float64, count=len(self.t))

    def values(self) -> FloatArray:
        return np.fromiter(self.v, dtype=np.float64, count=len(self.v))

    def drop_older_half(self) -> None:
        for _ in range(len(self.t) // 2):
            self.t.popleft()
            self.v.popleft()

    def __len__(self) -> int:
        return len(self.t)
