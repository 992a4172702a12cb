"""Staleness: when an input counts as silent. One rule for ports, references, headings.

An input is *stale* when more than its timeout has passed since it was last heard
(:func:`silent`). The timeouts:

- a **port**: its ``stale_timeout_s`` (:class:`~emlogd.pipeline.settings.PortSettings`);
  :class:`Liveness` tracks every port and says when one goes stale or comes back. The
  pipeline owns one; its status reports it and the daemon logs its ``stale`` and
  ``alive`` events (the serial sources run no silence detection of their own);
- a **reference**: its port's ``stale_timeout_s`` again (the config hands it to the UUT
  as ``ref_stale_s``): the learner (:mod:`emlogd.pipeline.learner`) judges it with
  :func:`silent` and learns nothing from a reference silent that long;
- a **heading**: a port's heading at a time is interpolated between the samples
  around it when neither is further than :data:`HEADING_MAX_GAP_S` from that time,
  else taken from a sample within :data:`HEADING_NEAREST_S`, else there is none; a
  GNSS fix waits for the heading at its time at most :data:`GNSS_HEADING_WAIT_S`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

HEADING_MAX_GAP_S = 2.0
"""A heading is interpolated only between samples at most this far from the query time."""

HEADING_NEAREST_S = 0.6
"""Outside an interpolation, a heading sample this close in time is used as it is."""

GNSS_HEADING_WAIT_S = 2.0
"""A GNSS fix waits this long (record time) for the heading at its time to arrive."""


def silent(last: float | None, now: float, timeout_s: float) -> bool:
    """Whether an input last heard at ``last`` (None: never) is stale at ``now``: more
    than ``timeout_s`` has passed. An input never heard is not stale (nothing to miss)."""
    return last is not None and now - last > timeout_s


class Liveness:
    """When each port was last heard and whether it is stale now.

    Args:
        timeouts: each port's ``stale_timeout_s``, s.
    """

    def __init__(self, timeouts: Mapping[str, float]) -> None:
        self.timeouts = dict(timeouts)
        self.last: dict[str, float] = {}
        """The receive time of each port's latest data, s."""
        self.stale: dict[str, bool] = dict.fromkeys(self.timeouts, False)

    def heard(self, port: str, t: float) -> bool:
        """Data from ``port`` at ``t``; True when the port was stale (it is alive again)."""
        self.last[port] = t
        if self.stale[port]:
            self.stale[port] = False
            return True
        return False

    def check(self, now: float) -> list[tuple[str, float]]:
        """The ports that went stale by ``now``, each with how long it has been silent, s
        (each reported once until it is heard again)."""
        gone: list[tuple[str, float]] = []
        for port, timeout in self.timeouts.items():
            last = self.last.get(port)
            if not self.stale[port] and silent(last, now, timeout):
                assert last is not None
                self.stale[port] = True
                gone.append((port, now - last))
        return gone

    def adopt(self, old: Liveness, ports: Iterable[str]) -> None:
        """Take over ``ports``' state from ``old`` (a reload keeping those ports)."""
        for port in ports:
            self.stale[port] = old.stale.get(port, False)
            if port in old.last:
                self.last[port] = old.last[port]
