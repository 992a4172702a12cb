"""The lag in use, checked against the data: a reference whose clock is off.

A configured lag is a claim about the time between the UUT's readings and its
reference's, and the data can contradict it: a reference whose records reach the
computer minutes late (buffered on its way), or stamped by a clock minutes off, pairs every reading with the reference of another
moment, and a calibration fitted on such pairs is wrong by whatever the speed did in
between. :class:`LagCheck` keeps the UUT's readings, its reference and heading of the
last :data:`LAG_CHECK_WINDOW_S` plus twice :data:`LAG_CHECK_RANGE_S`, and every
:data:`LAG_CHECK_EVERY_S` of readings scores the lag with :func:`calib.lagscan.scan_lags`
over ``±LAG_CHECK_RANGE_S`` (negative lags too: a reference stamped early; the lag
search proper looks at ``0..max_lag_s`` only), and the lag in use the same way. Each lag
is scored on the readings that overlap the reference at that lag (a DVL that loses the
bottom for a minute leaves, across ±3 minutes, no reading that overlaps it at every lag),
by an adjusted fit that fewer readings cannot flatter. The verdict
(:func:`verdict`):

- **cannot tell** (the last verdict stands) when fewer than
  :data:`LAG_CHECK_MIN_SAMPLES` readings were scored at the best lag or at the lag in
  use, or the best correlation is below :data:`calib.lag.MIN_LAG_CORRELATION` (the
  speed has not varied enough for a correlation to mean anything), or the best lag is
  at the range's bound or next to a lag scored on too few readings (where it lies,
  unknown), or it beats the lag in use by less than :data:`LAG_CHECK_MIN_GAIN` (a flat
  curve: a slow speed change fits many lags alike);
- **agrees** when the best lag is within :data:`LAG_CHECK_TOLERANCE_S` of the lag in
  use;
- **contradicts** the lag in use otherwise: the data say it is wrong beyond its
  uncertainty.

With ``lag: auto`` the estimated lag (or the fallback while none is accepted) is checked
too, but the data contradict it only when the best lag is minutes off
(:data:`LAG_CHECK_AUTO_MIN_OFFSET_S`) and the same in consecutive checks
(:data:`LAG_CHECK_AUTO_CONFIRM`): on real GNSS-referenced logs single windows peak
minutes away by chance, and a reference a second or two late is the lag search's
business, not the check's.

While contradicted, the UUT learns nothing, its applied calibration (and any candidate)
is withdrawn to raw, and the status says why (:attr:`LagCheck.why`); a later window
that agrees ends it, and the learner's parameters re-open (what they learnt from pairs
of different moments is not kept as knowledge). Nothing here reads a clock or does I/O.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from calib.errors import CalibrationError
from calib.lag import MIN_LAG_CORRELATION, LagEstimate
from calib.lagscan import scan_lags

LAG_CHECK_RANGE_S = 180.0
"""The lags the check scores, ±s: a reference three minutes off either way is found;
one farther off puts the best correlation at the bound."""

LAG_CHECK_WINDOW_S = 300.0
"""The readings each check scores, s (a speed change or a turn or two)."""

LAG_CHECK_EVERY_S = 300.0
"""A check is made every this many seconds of readings, s."""

LAG_CHECK_STEP_S = 1.0
"""The check's grid step, s: it tells lags apart by seconds, not tenths."""

LAG_CHECK_READING_S = 1.0
"""Readings are kept at most one per this many seconds, s (a 5 Hz log thinned to 1 Hz:
a check tells lags apart by seconds, and costs a fifth)."""

LAG_CHECK_REFERENCE_S = 0.5
"""Reference samples are kept at most one per this many seconds, s (a 10 Hz DVL thinned
to 2 Hz: the check smooths both series over twice the readings' 1-s spacing anyway)."""

LAG_CHECK_TOLERANCE_S = 5.0
"""A best lag this close to the lag in use, s, agrees with it: a configured lag is a
latency of seconds, and an imported log's refused estimates lie within −3..+4 s."""

LAG_CHECK_MIN_GAIN = 0.1
"""The best correlation must beat the one at the lag in use by this much: a flat
correlation curve (a slow speed change) places its peak anywhere."""

LAG_CHECK_MIN_SAMPLES = 150
"""Readings a lag must be scored on, at least (those whose reference at that lag is
covered, no outage near): on fewer, the fit of a current per block makes a correlation
of 0.99 at any lag."""

LAG_CHECK_AUTO_MIN_OFFSET_S = 30.0
"""With ``lag: auto`` a best lag contradicts the lag in use only this far from it, s (the
longest ``max_lag_s`` there is): a lag of seconds is the lag search's business, and on
real GNSS-referenced logs the check's best lag wanders 5–15 s from it on windows of
slow manoeuvres."""

LAG_CHECK_AUTO_CONFIRM = 2
"""With ``lag: auto`` this many checks in a row that can tell must contradict the lag
in use, their best lags within :data:`LAG_CHECK_TOLERANCE_S` of each other: a clock
minutes off repeats window after window, a false peak (r=0.83 at +136 s, r=0.61 at
−114 s on real logs) does not."""

LAG_CHECK_RATE_HZ = 20.0
"""Reference samples per second the buffers are sized for (a 10 Hz DVL twice over)."""


def verdict(est: LagEstimate, lag_s: float, claim: str = "configured") -> str | None:
    """The check's verdict on ``lag_s``: why the data contradict it, ``""`` when they
    agree, None when they cannot tell (see the module docstring).

    Args:
        est: the best lag over ``±LAG_CHECK_RANGE_S`` with ``corr_at`` at ``lag_s``
            (:func:`calib.lag.estimate_lag`).
        lag_s: the lag in use, s.
        claim: what the lag in use is, in the reason (``configured``, ``in use``).
    """
    if not (est.n_samples >= LAG_CHECK_MIN_SAMPLES and est.peak_corr >= MIN_LAG_CORRELATION):
        return None
    if abs(est.lag_s - lag_s) <= LAG_CHECK_TOLERANCE_S:
        return ""
    if est.at_bound or not est.peak_corr - est.corr_at >= LAG_CHECK_MIN_GAIN:
        return None
    return (
        f"the reference's time does not match the log's: best lag {est.lag_s:+.1f} s "
        f"(r={est.peak_corr:.2f}), {claim} {lag_s:g} s (r={est.corr_at:.2f})"
    )


class LagCheck:
    """The UUT's, its reference's and heading's recent series, and the verdict on the
    lag in use (see the module docstring).

    Args:
        with_heading: score in the water frame (the current modelled).
        auto: the lag in use is the lag search's (``lag: auto``): a contradiction must
            be minutes off and repeat (:data:`LAG_CHECK_AUTO_MIN_OFFSET_S`,
            :data:`LAG_CHECK_AUTO_CONFIRM`).
    """

    def __init__(self, with_heading: bool, auto: bool = False) -> None:
        self.with_heading = with_heading
        self.auto = auto
        self.offsets: list[float] = []
        """With ``auto``: the best lags of the last checks in a row that contradicted."""
        self.keep_s = LAG_CHECK_WINDOW_S + 2.0 * LAG_CHECK_RANGE_S
        cap = int(self.keep_s * LAG_CHECK_RATE_HZ) + 64
        self.uut: deque[tuple[float, float]] = deque(maxlen=cap)
        self.ref: deque[tuple[float, float]] = deque(maxlen=cap)
        self.heading: deque[tuple[float, float]] = deque(maxlen=cap)
        self.t_next: float | None = None
        self.why = ""
        """Why the data contradict the lag in use (the status reason), or empty."""
        self.checks = 0
        """Checks made (those that could not tell included)."""

    @property
    def contradicted(self) -> bool:
        """The last check that could tell contradicted the lag in use."""
        return bool(self.why)

    def reference(
        self, t: float, v_mps: float, heading_at: Callable[[float], float | None]
    ) -> None:
        """One valid reference sample along the hull (``heading_at``: the heading at a time)."""
        if self.ref and t - self.ref[-1][0] < LAG_CHECK_REFERENCE_S:
            return
        _push(self.ref, t, v_mps, self.keep_s)
        if self.with_heading:
            h = heading_at(t)
            if h is not None:
                _push(self.heading, t, h, self.keep_s)

    def reading(self, t: float, raw_mps: float, lag_s: float | None) -> bool:
        """One reading; True when a check changed the verdict (:attr:`why`)."""
        if not self.uut or t - self.uut[-1][0] >= LAG_CHECK_READING_S:
            _push(self.uut, t, raw_mps, self.keep_s)
        if self.t_next is None:
            self.t_next = t + self.keep_s
        if lag_s is None or t < self.t_next:
            return False
        self.t_next = t + LAG_CHECK_EVERY_S
        est = self._check(lag_s)
        why = None if est is None else verdict(est, lag_s, "in use" if self.auto else "configured")
        if self.auto and est is not None:
            why = self._confirmed(why, est.lag_s, lag_s)
        if why is None or why == self.why:
            return False
        self.why = why
        return True

    def _confirmed(self, why: str | None, best_s: float, lag_s: float) -> str | None:
        """With ``lag: auto``: a contradiction once it is minutes off and repeats (else
        None: cannot tell yet); an agreement as it is."""
        if not why:
            if why == "":
                self.offsets.clear()
            return why
        if abs(best_s - lag_s) < LAG_CHECK_AUTO_MIN_OFFSET_S:
            self.offsets.clear()
            return None
        if self.offsets and abs(best_s - self.offsets[-1]) > LAG_CHECK_TOLERANCE_S:
            self.offsets.clear()
        self.offsets.append(best_s)
        return why if len(self.offsets) >= LAG_CHECK_AUTO_CONFIRM else None

    def _check(self, lag_s: float) -> LagEstimate | None:
        """The best lag over the window with the score at ``lag_s``; None when too few
        readings overlap the reference."""
        self.checks += 1
        t_ref_end = self.ref[-1][0] if self.ref else -math.inf
        uut = [s for s in self.uut if s[0] <= t_ref_end - LAG_CHECK_RANGE_S]
        uut = [s for s in uut if s[0] >= uut[-1][0] - LAG_CHECK_WINDOW_S] if uut else uut
        if len(uut) < 3 or len(self.ref) < 3:
            return None
        tm, vm = np.array(uut).T
        tr, vr = np.array(self.ref).T
        heading = None
        if self.with_heading:
            if len(self.heading) < 3:
                return None
            th, psi = np.array(self.heading).T
            heading = (th, psi)
        try:
            est = scan_lags(
                tm,
                vm,
                tr,
                vr,
                LAG_CHECK_RANGE_S,
                step_s=LAG_CHECK_STEP_S,
                min_samples=LAG_CHECK_MIN_SAMPLES,
                heading=heading,
                at_s=lag_s,
            )
        except CalibrationError:
            return None
        return est


def _push(q: deque[tuple[float, float]], t: float, v: float, keep_s: float) -> None:
    """Append ``(t, v)`` (a finite value after the newest time) and forget what is older
    than ``keep_s``."""
    if not math.isfinite(v) or (q and t <= q[-1][0]):
        return
    q.append((t, v))
    while q and q[0][0] < t - keep_s:
        q.popleft()
