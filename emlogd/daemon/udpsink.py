"""The UDP output: sentences as datagrams to one destination (broadcast allowed).

The destination is an IP address, resolved once without the resolver; one that does not
resolve is retried from :meth:`UdpSink.housekeep` (its sentences meanwhile counted as
errors). A send the kernel refuses (``ENETUNREACH`` with no route to the destination,
``EPERM`` from a firewall rule, ``EAGAIN`` with the socket's buffer full) costs that
datagram alone: counted in ``errors``, the other outputs written as before, and the
output's ``state`` says ``failing`` with the reason and how many sends in a row failed,
until a send succeeds (``open`` again). Entering and leaving that state is an event
(``output_failing``, ``output_recovered``), at most one of each per :data:`FAIL_EVENT_S`.
"""

from __future__ import annotations

import errno
import math
import socket
import time
from collections.abc import Callable

from emlogd.daemon.sinks import SinkCounters, _Retry, parse_hostport

FAIL_EVENT_S = 10.0
"""Least time between two ``output_failing`` (or two ``output_recovered``) events of
one UDP output, s: a route that comes and goes costs a line per interval, not one per
sentence."""


def send_error(exc: OSError) -> str:
    """A failed send's reason: its errno's name and text (``ENETUNREACH: Network is
    unreachable``)."""
    name = errno.errorcode.get(exc.errno or 0, "error")
    return f"{name}: {exc.strerror or exc}"


class UdpSink:
    """Sentences as UDP datagrams to ``dest`` (``host:port``, an IP address).

    Args:
        dest: the destination.
        on_event: called with (event, detail) for what the log should say.
        monotonic: the clock of the retries and of :data:`FAIL_EVENT_S`.
    """

    def __init__(
        self,
        dest: str,
        *,
        on_event: Callable[[str, str], None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = f"udp:{dest}"
        self.counters = SinkCounters()
        self.host, self.port = parse_hostport(dest, default_host="127.0.0.1")
        self.on_event = on_event
        self.monotonic = monotonic
        self.addr: tuple[str, int] | None = None
        self.state = "unresolved"
        self.retry = _Retry(monotonic)
        self.failing: str | None = None
        """Why the last send failed, while sends fail (None: the last one succeeded)."""
        self.failed_in_row = 0
        """Sends failed since the last that succeeded."""
        self._said: dict[str, float] = {}
        """When each of ``output_failing`` and ``output_recovered`` was last told."""
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self.sock.setblocking(False)
        self.housekeep()

    def housekeep(self) -> None:
        """Resolve the destination when a retry is due (it did not resolve yet)."""
        if self.addr is not None or not self.retry.due():
            return
        try:
            info = socket.getaddrinfo(  # an address, never the resolver (config: ipv4_port)
                self.host, self.port, socket.AF_INET, socket.SOCK_DGRAM, 0, socket.AI_NUMERICHOST
            )
            addr = info[0][4]
            self.addr = (str(addr[0]), int(addr[1]))
        except (OSError, IndexError) as exc:
            delay = self.retry.failed()
            self.state = f"unresolved: {exc}"
            self._tell("output_unresolved", f"{self.name}: {exc}; retry in {delay:g} s")
            return
        self.state = "open"

    def write(self, line: bytes) -> None:
        """Send one sentence; a failure is counted and shown in :attr:`state`."""
        if self.addr is None:
            self.counters.errors += 1
            return
        try:
            self.sock.sendto(line, self.addr)
        except OSError as exc:
            self._failed(send_error(exc))
            return
        self.counters.sentences += 1
        self.counters.bytes += len(line)
        if self.failing is not None:
            self._tell_once(
                "output_recovered",
                f"{self.name}: sending again after "
                f"{self.failed_in_row} failed sends ({self.failing})",
            )
            self.failing, self.failed_in_row, self.state = None, 0, "open"

    def _failed(self, why: str) -> None:
        self.counters.errors += 1
        self.failed_in_row += 1
        if self.failing is None:
            self._tell_once("output_failing", f"{self.name}: {why}; the other outputs go on")
        self.failing = why
        self.state = f"failing: {why} ({self.failed_in_row} sends in a row)"

    def _tell_once(self, kind: str, detail: str) -> None:
        """``kind`` told unless it was within :data:`FAIL_EVENT_S`."""
        now = self.monotonic()
        if now - self._said.get(kind, -math.inf) >= FAIL_EVENT_S:
            self._said[kind] = now
            self._tell(kind, detail)

    def _tell(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, detail)

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()
