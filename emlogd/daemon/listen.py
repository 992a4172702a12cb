"""What the daemon's listening sockets (control, TCP output) share: a cap on clients,
a pause when ``accept`` fails for lack of resources, and a budget of connections.

When the process is out of descriptors (``EMFILE``) or the kernel out of memory,
``accept`` keeps failing while the connection waits in the backlog, and a
level-triggered selector would report the listening socket readable forever: a busy
loop. :class:`AcceptPause` takes the socket out of the selector for a growing delay
(:data:`PAUSE_S`), puts it back from :meth:`AcceptPause.resume_due` (called from the
daemon's housekeeping), and reports the failures at most once per :data:`REPORT_S`.

A client that connects again at once after each close (a flooder reset for what it
sent, a script in a loop) would cost the daemon an accept, a registration and a close
per connection, thousands a second. :class:`AcceptBudget` admits per source address at
most :data:`SOURCE_BURST` connections at once, refilled at :data:`SOURCE_RATE` per
second, and from all sources together :data:`ALL_BURST` refilled at :data:`ALL_RATE`;
a connection past either is reset at once, without a read or a registration, and
counted. A source's own excess never spends the budget of all (a flooder does not lock
out the other hosts), and the sources remembered are at most :data:`SOURCES_KEPT`.
"""

from __future__ import annotations

import errno
import math
import time
from collections.abc import Callable

PAUSE_S = (0.1, 0.5, 1.0, 2.0, 5.0)
"""Pauses after consecutive resource failures of ``accept``, the last one repeating."""

REPORT_S = 60.0
"""Least time between two reports of accept failures."""

RESOURCE_ERRNOS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
"""``accept`` errors that pause the listener (any other drops one connection only)."""


class AcceptPause:
    """The pause state of one listening socket.

    Args:
        report: called as ``report(detail)`` for a failure worth logging (rate-limited).
        monotonic: the clock of the pause.
    """

    def __init__(
        self, report: Callable[[str], None], monotonic: Callable[[], float] = time.monotonic
    ) -> None:
        self.report = report
        self.monotonic = monotonic
        self.until: float | None = None
        self.run = 0
        self.errors = 0
        self._reported = -math.inf
        self._unreported = 0

    @property
    def paused(self) -> bool:
        """Accepting is suspended."""
        return self.until is not None

    def failed(self, exc: OSError) -> bool:
        """Count a failed ``accept``; True when the listener must pause (resource error)."""
        self.errors += 1
        if exc.errno not in RESOURCE_ERRNOS:
            return False
        now = self.monotonic()
        delay = PAUSE_S[min(self.run, len(PAUSE_S) - 1)]
        self.run += 1
        self.until = now + delay
        if now - self._reported >= REPORT_S:
            more = f" ({self._unreported} more since the last report)" if self._unreported else ""
            self.report(f"{exc.strerror or exc}{more}; not accepting for {delay:g} s")
            self._reported = now
            self._unreported = 0
        else:
            self._unreported += 1
        return True

    def hold(self, delay: float) -> None:
        """Suspend accepting for ``delay`` s (no failure: the caller chose to)."""
        self.until = self.monotonic() + delay

    def accepted(self) -> None:
        """A connection was accepted: the next failure pauses briefly again."""
        self.run = 0

    def resume_due(self) -> bool:
        """True once, when the pause is over (the caller listens again)."""
        if self.until is None or self.monotonic() < self.until:
            return False
        self.until = None
        return True


SOURCE_BURST = 64
"""Most connections one source address may open at once (twice the default client
limit: a host starting its navigation programs together, a test opening 40)."""

SOURCE_RATE = 2.0
"""Connections a second one source's budget refills at: a client reconnecting every few
seconds is never refused, a loop is held to this rate."""

ALL_BURST = 128
"""Most connections all sources together may open at once."""

ALL_RATE = 20.0
"""Connections a second the budget of all sources refills at."""

SOURCES_KEPT = 1024
"""Most source addresses whose budget is remembered; past it, those whose budget is full
again are forgotten, then the longest unheard."""


class _Bucket:
    """A token bucket: ``burst`` at most, refilled at ``rate`` a second."""

    __slots__ = ("at", "burst", "rate", "tokens")

    def __init__(self, burst: float, rate: float, now: float) -> None:
        self.burst = burst
        self.rate = rate
        self.tokens = burst
        self.at = now

    def level(self, now: float) -> float:
        """The tokens at ``now`` (refilled since the last count)."""
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        return self.tokens


class AcceptBudget:
    """How many connections the listener admits, per source address and in all.

    Args:
        monotonic: the clock of the refills.
        source: (burst, rate) of one source address.
        overall: (burst, rate) of all sources together.
    """

    def __init__(
        self,
        monotonic: Callable[[], float] = time.monotonic,
        source: tuple[float, float] = (SOURCE_BURST, SOURCE_RATE),
        overall: tuple[float, float] = (ALL_BURST, ALL_RATE),
    ) -> None:
        self.monotonic = monotonic
        self.source = source
        self.sources: dict[str, _Bucket] = {}
        self.all = _Bucket(*overall, monotonic())

    def admit(self, address: str) -> bool:
        """Spend a connection of ``address`` (and of all); False: over a budget, refuse it."""
        now = self.monotonic()
        bucket = self.sources.pop(address, None) or _Bucket(*self.source, now)
        self.sources[address] = bucket  # the most recently heard last
        if len(self.sources) > SOURCES_KEPT:
            self._forget(now)
        if bucket.level(now) < 1.0 or self.all.level(now) < 1.0:
            return False
        bucket.tokens -= 1.0
        self.all.tokens -= 1.0
        return True

    def _forget(self, now: float) -> None:
        for address, bucket in list(self.sources.items()):
            if bucket.level(now) >= bucket.burst:
                del self.sources[address]
        while len(self.sources) > SOURCES_KEPT:
            del self.sources[next(iter(self.sources))]
