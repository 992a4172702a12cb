"""A log's readings at the output: what a speed log's reading may do, and the check of
each reading against it (:class:`ReadingCheck`).

A reading that implies an acceleration no vessel makes since the log's last accepted
reading, or that arrives faster than the log's own rate (a babbling log), is neither
emitted nor learnt. The log's rate is learnt from its readings; a log that keeps a
faster rate steadily, its readings following each other plausibly, has changed its
rate and is heard at it (:data:`RATE_RELEARN_S`).

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from emlogd.pipeline.align import MedianWindow
from emlogd.pipeline.integrity import QUANTUM_MPS
from emlogd.pipeline.keys import key, number

READING_MARGIN_MPS = 0.3
"""A change of a log's reading always allowed between two readings, m/s: the reading's
noise (0.05 m/s) and the surge of a hull in waves, which a log at 1 Hz or faster sees."""

READING_REACQUIRE_S = 10.0
"""An implausible new level that stays continuous (each reading plausible from the one
before) this long is accepted, s: the log's earlier level was the wrong one, or the
vessel really is elsewhere after a fault. A spike shorter than this never goes out."""

ZERO_MPS = 2.0 * QUANTUM_MPS
"""A reading this close to zero is a zero (a log's dropout value): a log back from
zero is judged against its last accepted non-zero reading — the zero was the wrong
level, or the vessel was at rest and no acceleration is known."""

BURST_GAP_S = 0.5 / 20.0
"""Readings closer than this to the one before are one *burst*, s (half the interval of
the fastest log, :data:`DEFAULT_MAX_RATE_HZ`), as are those closer than
:data:`BURST_SHARE` of the median interval: a multiplexer or logger that batches, or a
USB-serial adapter's 16-ms latency timer, hands a log's readings on a few ms apart and
then nothing until the next batch. The log's rate is learnt as its bursts' interval
and the readings a burst holds (:attr:`ReadingCheck.burst`): learnt from the longer of
the two intervals of a log sending pairs, readings were let through at half the log's
rate and the log was babbling, nearly every reading dropped."""

BURST_SHARE = 0.25
"""An interval shorter than this share of the (upper) median interval between readings
joins its readings in one burst (:data:`BURST_GAP_S`): a log at twice the rate of the
lines it is sent with, its second reading right after the first, comes 0.1 s then
0.9 s apart; the receive-time jitter of a log sending one reading at a time is far
less than this."""

RATE_SLACK = 1.05
"""A log's readings are accepted at up to this many times its nominal rate (the jitter
of receive times and the drift between its clock and ours)."""

RATE_BURST = 2.0
"""Readings a log may send back to back above its rate (the token bucket's depth, plus
the learnt burst's readings beyond the first): one late reading, or burst, followed by
an early one is no babble."""

BABBLE_DROPS = 3
"""This many readings dropped for the rate within :data:`BABBLE_S` make a log *babbling*:
then every reading it sends is dropped (a reading let through at the rate is as much
garbage as the others), until none was dropped for :data:`BABBLE_S`. One dropped by a
late reading's jitter is no babble."""

BABBLE_S = 10.0
"""The window of :data:`BABBLE_DROPS`, and how long a babbling log must keep its rate, s."""

READ_SLACK = 2.0
"""A read may hold :data:`RATE_BURST` readings of a sentence plus this many times what the
time since the last read earned at the log's sentence rate (reads bunch up when the
daemon is busy); beyond, its newest is dropped for the rate (a log babbling 20
sentences a read). The sentence rate is learnt like the read rate, from the readings
per second of the reads not dropped (a multiplexer batching a 10-Hz log once a second
sends ten a read; a replay at 20 times real time reads a 10-Hz log at 200 Hz); until
:data:`RATE_MIN_INTERVALS` reads have taught it, a read's count is not judged
(``max_rate_hz`` fixes the rate and judges from the first read)."""

RATE_HISTORY = 32
"""The nominal interval is the median of this many intervals between consecutive
bursts (:data:`BURST_GAP_S`; a reading alone is a burst of one) with none dropped for
the rate between them, and the burst's size the median of as many bursts' readings,
each with none dropped (a babble, held to the rate, must not teach a shorter interval
nor a larger burst)."""

RATE_MIN_INTERVALS = 8
"""Intervals needed before the nominal rate is used (until then ``max_rate_hz`` alone)."""

RATE_RELEARN_S = 30.0
"""A log whose every reading has been dropped for the rate this long (no pause) while
they came faster than its nominal rate, each following the one before within the
acceleration rule (:data:`RATE_RELEARN_STEADY` of them), has changed its rate, s: its
nominal interval is learnt again from those readings, at most :data:`DEFAULT_MAX_RATE_HZ`.
Since a read dropped for the rate teaches no interval, a log set from 1 Hz to 5 Hz, or
back at 1 Hz after readings lost on the line had taught it a 4-s interval, was
babbling for good; a babble's values (0-14 kn at random) do not follow each other."""

RATE_RELEARN_STEADY = 0.9
"""The share of a :data:`RATE_RELEARN_S` spell's readings that must each follow the one
before within the acceleration rule for the log's rate to be learnt again."""


@dataclass(frozen=True, slots=True)
class ReadingLimits:
    """What a speed log's reading may do (``calibration`` keys, per log).

    Attributes:
        max_reading_accel_mps2: the largest acceleration of the vessel, m/s²: a reading
            that would need more since the log's last accepted reading (beyond
            :data:`READING_MARGIN_MPS`) is implausible.
        max_rate_hz: the most readings a log sends per second; null: its nominal rate,
            learnt from its accepted readings (the median interval), bounded by
            :data:`DEFAULT_MAX_RATE_HZ`.
    """

    max_reading_accel_mps2: float = key(
        1.0,
        check=number(0.0, 10_000.0, lo_open=True),
        unit="m/s²",
        doc="A log's reading that needs more acceleration than this since its last accepted "
        "one is neither emitted nor learnt (a spike, a dropout to 0). A replay at k times "
        "real time (`fake --speed k`) needs k² times this.",
    )
    max_rate_hz: float | None = key(
        None,
        check=number(0.0, 10_000.0, lo_open=True, optional=True),
        unit="Hz",
        doc="A log's readings beyond this rate are dropped, and all of them while it exceeds "
        "it (a babbling log); null: its nominal rate learnt from the median interval (+5 %), "
        "times the readings of the bursts it sends them in, at most 20 Hz.",
    )


DEFAULT_MAX_RATE_HZ = 20.0
"""Without ``max_rate_hz``: the rate no speed log's readings exceed (the nominal rate
is learnt below it; a log that babbles from its first sentence is held to this)."""


class _Spell:
    """A spell of readings dropped for the rate without a pause (:data:`RATE_RELEARN_S`):
    its start, its last reading (time, value), the intervals between its bursts
    (:data:`BURST_GAP_S`) and their readings, how many followed the one before within
    the acceleration rule, of how many."""

    __slots__ = ("gaps", "last", "n", "steady", "t0")

    def __init__(self, t: float, v: float) -> None:
        self.t0 = t
        self.last = (t, v)
        self.gaps: deque[tuple[float, bool]] = deque(maxlen=RATE_HISTORY)
        self.n = 0
        self.steady = 0


def bursts(gaps: deque[tuple[float, bool]]) -> tuple[float, int] | None:
    """The nominal interval between a log's bursts of readings and the readings a burst
    holds (:data:`BURST_GAP_S`, :data:`BURST_SHARE`), from the intervals between its
    readings in time order, each with whether readings were dropped before it (a burst
    is not known across them): the upper median of the intervals between bursts and the
    (lower) median of their readings; None until :data:`RATE_MIN_INTERVALS` bursts.
    A log sending one reading at a time: the upper median interval, 1."""
    order = sorted(g for g, _ in gaps)
    if not order:
        return None
    split = max(BURST_GAP_S, BURST_SHARE * order[len(order) // 2])
    intervals: list[float] = []
    sizes: list[int] = []
    since, n = 0.0, 1
    for g, hole in gaps:
        if hole:
            since, n = 0.0, 1
        if g < split:
            since += g
            n += 1
            continue
        intervals.append(since + g)
        sizes.append(n)
        since, n = 0.0, 1
    if len(intervals) < RATE_MIN_INTERVALS:
        return None
    intervals.sort()
    sizes.sort()
    m = len(sizes)
    size = sizes[m // 2] if m % 2 else sizes[m // 2 - 1]
    return intervals[len(intervals) // 2], max(size, 1)


class ReadingCheck:
    """The plausibility of one log's readings (one sentence type), in time order.

    :meth:`check` says why a reading must not go out (``"rate"``, ``"accel"``) or ``""``;
    :attr:`reacquired` is set when the last accepted reading re-acquired a new level
    (a discontinuity the fusion weighs against the log).
    """

    __slots__ = (
        "_depth",
        "_drops",
        "_first_refused",
        "_gap_order",
        "_gaps",
        "_hole",
        "_last",
        "_max_hz",
        "_moving",
        "_pending",
        "_per_sentence",
        "_rate_dropped",
        "_read_hz",
        "_spell",
        "_t_rate",
        "_tokens",
        "burst",
        "limits",
        "nominal_s",
        "reacquired",
    )

    def __init__(self, limits: ReadingLimits) -> None:
        self.limits = limits
        self._last: tuple[float, float] | None = None
        self._moving: tuple[float, float] | None = None
        self._first_refused: float | None = None
        self._pending: tuple[float, float, float] | None = None
        self._gaps: deque[tuple[float, bool]] = deque(maxlen=RATE_HISTORY)
        """The intervals between consecutive readings let through, each with whether
        readings were dropped for the rate before it (:func:`bursts`)."""
        self._hole = False
        self._gap_order = MedianWindow(RATE_HISTORY)
        """The same intervals, their order (:func:`bursts` runs only when one is short)."""
        self._per_sentence = MedianWindow(RATE_HISTORY)
        """The intervals between reads not dropped, over the readings each held."""
        self._t_rate: float | None = None
        self._tokens = RATE_BURST
        self._depth = RATE_BURST
        """The token bucket's depth: :data:`RATE_BURST` plus the burst's readings beyond
        its first."""
        self._rate_dropped = False
        self._drops: deque[float] = deque(maxlen=BABBLE_DROPS)
        """The times of the last reads dropped for the rate, within :data:`BABBLE_S`: the
        last :data:`BABBLE_DROPS` tell all the rule asks (a list of every drop within
        the window, its oldest removed at every reading, cost the whole list per reading
        of a log babbling one sentence a read)."""
        self.nominal_s: float | None = None
        """The log's nominal interval between bursts of readings (:data:`BURST_GAP_S`;
        between readings for a log sending them one at a time), s (None until learnt)."""
        self.burst = 1
        """The readings a burst of the log holds (the median; 1 until learnt)."""
        self.reacquired = False
        fixed = limits.max_rate_hz
        self._max_hz = DEFAULT_MAX_RATE_HZ if fixed is None else fixed
        """:meth:`max_rate_hz`, set again when :attr:`nominal_s` changes."""
        self._read_hz = fixed
        """The readings per second a read may bring (:data:`READ_SLACK`), Hz: ``max_rate_hz``,
        else learnt from the sentence rate's window once it holds
        :data:`RATE_MIN_INTERVALS`; None until then."""
        self._spell: _Spell | None = None
        """The readings dropped for the rate since the last one let through (a learnt
        rate only)."""

    def max_rate_hz(self) -> float:
        """The rate readings are accepted at now, Hz: ``max_rate_hz``, else the nominal rate
        (:data:`RATE_SLACK`) at most :data:`DEFAULT_MAX_RATE_HZ`."""
        return self._max_hz

    def check(self, t: float, v: float, n: int = 1) -> str:
        """Judge one reading at receive time ``t``: ``""`` when plausible, else why not.

        ``n``: the readings of this sentence the read that brought it held (it the
        newest; the others are backlog, not judged themselves). The rate is judged on
        reads; a read holding more than :data:`RATE_BURST` readings plus
        :data:`READ_SLACK` times what the time since the last read earned at the
        sentence rate is dropped for the rate too: a log babbling in bursts is no less
        babbling, and a USB-serial stall released at once, or a multiplexer's batch, is
        no babble.
        """
        self.reacquired = False
        why = self._judge_rate(t, n)
        if not why:
            self._spell = None
            return self._accel(t, v)
        if self.limits.max_rate_hz is None:
            self._relearn(t, v)
        return why

    def _relearn(self, t: float, v: float) -> None:
        """A reading dropped for the rate: the spell of them goes on; once it is
        :data:`RATE_RELEARN_S` long, faster than the nominal rate and its readings
        follow each other, the rate is learnt again from its intervals."""
        sp = self._spell
        if sp is None:
            self._spell = _Spell(t, v)
            return
        t_last, v_last = sp.last
        sp.last = (t, v)
        dt = t - t_last
        if dt <= 0.0:
            return
        sp.gaps.append((dt, False))
        sp.n += 1
        if abs(v - v_last) <= READING_MARGIN_MPS + self.limits.max_reading_accel_mps2 * dt:
            sp.steady += 1
        if t - sp.t0 < RATE_RELEARN_S or len(sp.gaps) < RATE_MIN_INTERVALS:
            return
        self._spell = None
        learnt = bursts(sp.gaps)
        if learnt is None:
            return
        nominal, size = learnt
        faster = self.nominal_s is None or nominal * RATE_SLACK * self.burst < self.nominal_s * size
        if not faster or sp.steady < RATE_RELEARN_STEADY * sp.n:
            return  # the log's own rate in bursts, or a babble: a spell starts afresh
        if nominal * DEFAULT_MAX_RATE_HZ < size:
            return
        self._gaps = sp.gaps
        self._gap_order.clear()
        for g, _ in sp.gaps:
            self._gap_order.append(g)
        self._hole = True
        self._learnt(nominal, size)
        self._tokens = self._depth
        self._drops.clear()
        self._per_sentence.clear()
        self._read_hz = None

    def arrived(self, t: float, n: int = 1) -> None:
        """A reading refused before its check (out of range) counts for the rate: the gaps
        left taught a 1-Hz log astern 4 s, then it was babbling for good under way."""
        self._judge_rate(t, n)

    def _judge_rate(self, t: float, n: int) -> str:
        """The rate's verdict on a read (:meth:`check`): ``"rate"`` or ``""``."""
        drops = self._drops
        prev = self._t_rate
        ok = self._rate(t)
        if prev is not None:
            dt = t - prev
            dt = 0.0 if dt < 0.0 else dt
            rate = self._read_hz
            if rate is not None and n > RATE_BURST + READ_SLACK * dt * rate:
                ok = False
            elif ok and dt > 0.0:
                per = self._per_sentence
                per.append(dt / max(n, 1))
                if self.limits.max_rate_hz is None and len(per) >= RATE_MIN_INTERVALS:
                    self._read_hz = 1.0 / max(per.median(), 1e-9)
        if not ok:
            drops.append(t)
        while drops and t - drops[0] > BABBLE_S:
            drops.popleft()
        if drops and (drops[-1] == t or len(drops) >= BABBLE_DROPS):
            return "rate"
        return ""

    def _rate(self, t: float) -> bool:
        prev = self._t_rate
        if prev is not None:
            dt = max(t - prev, 0.0)
            self._tokens = min(self._tokens + dt * self._max_hz, self._depth)
        self._t_rate = t
        if self._tokens < 1.0:
            self._rate_dropped = True
            return False
        self._tokens -= 1.0
        dropped, self._rate_dropped = self._rate_dropped, False
        if self.limits.max_rate_hz is not None:
            return True
        if dropped:
            self._hole = True
        elif prev is not None and t > prev:
            self._gaps.append((t - prev, self._hole))
            order = self._gap_order
            order.append(t - prev)
            self._hole = False
            if len(order) >= RATE_MIN_INTERVALS:
                upper = order.upper()
                if order.lowest() >= max(BURST_GAP_S, BURST_SHARE * upper):
                    self._learnt(upper, 1)  # no burst: every reading its own
                else:
                    learnt = bursts(self._gaps)
                    if learnt is not None:
                        self._learnt(*learnt)
        return True

    def _learnt(self, nominal: float, size: int) -> None:
        """The nominal interval between bursts and their readings learnt: the rate and
        the token bucket's depth follow."""
        self.nominal_s = nominal
        self.burst = size
        self._max_hz = min(RATE_SLACK * size / nominal, DEFAULT_MAX_RATE_HZ)
        self._depth = RATE_BURST + size - 1

    def _accel(self, t: float, v: float) -> str:
        last = self._last
        if last is None:
            self._last = (t, v)
            return ""
        # the time the vessel had to change since the last accepted reading: up to the
        # first implausible one (readings kept coming, so the speed is known to be
        # continuous from there; a new level must then be re-acquired)
        t_to = t if self._first_refused is None else self._first_refused
        a = self.limits.max_reading_accel_mps2
        if abs(v - last[1]) <= READING_MARGIN_MPS + a * max(t_to - last[0], 0.0):
            self._accept(t, v)
            return ""
        if abs(last[1]) <= ZERO_MPS:  # back from zero: against the last moving level
            ref = self._moving
            if ref is None or abs(v - ref[1]) <= READING_MARGIN_MPS + a * max(t - ref[0], 0.0):
                self._accept(t, v)
                return ""
        if self._first_refused is None:
            self._first_refused = t
        pend = self._pending
        if pend is not None and abs(v - pend[2]) <= READING_MARGIN_MPS + a * max(t - pend[1], 0.0):
            if t - pend[0] >= READING_REACQUIRE_S:
                self._accept(t, v)
                self.reacquired = True
                return ""
            self._pending = (pend[0], t, v)
        else:
            self._pending = (t, t, v)
        return "accel"

    def _accept(self, t: float, v: float) -> None:
        self._last = (t, v)
        if abs(v) > ZERO_MPS:
            self._moving = (t, v)
        self._first_refused = None
        self._pending = None
