"""What the daemon's listening sockets (control, TCP output) share: a cap on clients,
and a pause when ``accept`` fails for lack of resources.

When the process is out of descriptors (``EMFILE``) or the kernel out of memory,
``accept`` keeps failing while the connection waits in the backlog, and a
level-triggered selector would report the listening socket readable forever: a busy
loop. :class:`AcceptPause` takes the socket out of the selector for a growing delay
(:data:`PAUSE_S`), puts it back from :meth:`AcceptPause.resume_due` (called from the
daemon's housekeeping), and reports the failures at most once per :data:`REPORT_S`.
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

    def accepted(self) -> None:
        """A connection was accepted: the next failure pauses briefly again."""
        self.run = 0

    def resume_due(self) -> bool:
        """True once, when the pause is over (the caller listens again)."""
        if self.until is None or self.monotonic() < self.until:
            return False
        self.until = None
        return True
