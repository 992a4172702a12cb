"""Output sinks for the corrected NMEA: pty, TCP server, UDP, stdout, file.

Every sink takes whole sentences (bytes ending in CR LF) and never blocks the
daemon loop: writes are non-blocking, send errors are counted and skipped. The UDP
output is :class:`emlogd.daemon.udpsink.UdpSink`.
Sinks that need the selector (the TCP server) expose their file descriptors.

No TCP client holds the output hostage (:class:`TcpServerSink`, limits in
:class:`TcpLimits`): a client whose pending output (the daemon's backlog plus the
kernel's send queue) exceeds a bound is closed (``client_too_slow``), and so is one
that has taken nothing for :attr:`TcpLimits.stall_s` while output was pending
(``client_stalled``); at the client limit a newcomer is let in and an existing
client goes (``client_evicted``): one that ended its sending, else the one that has
been stalled longest, else the most recently connected (a burst of connections takes
one slot over and over, never the long-standing readers'). Such a close is a reset:
what is queued for the client is discarded (a FIN would wait behind it, and so would
the kernel's memory). The
kernel acknowledges whatever fits in a client's receive buffer, read or not: a
client that never reads is noticed once that buffer is full.

Connections are admitted within a budget per source address and in all
(:class:`~emlogd.daemon.listen.AcceptBudget`): one past it is reset at once
(``client_throttled``) and the listener rests a moment (:data:`THROTTLE_PAUSE_S`), so a
client reconnecting in a loop costs a few accepts a pause, and only a few connections a
second get further.

The stream is output only: what a client sends is read and discarded, within a budget
(:data:`TCP_INPUT_BURST` bytes, refilled at :data:`TCP_INPUT_RATE` bytes/s); a
client that sends more is closed (``client_sent_data``), so a flooding client costs
the daemon one read, not a core.

A network output never stops the daemon: a TCP address that cannot be bound (in
use, not yet configured) or a UDP destination that does not resolve leaves the sink
``unbound``/``unresolved`` (its :attr:`state`) and is retried from
:meth:`housekeep` with a growing delay (:data:`RETRY_S`). Addresses are resolved
once, never per sentence. The TCP server pauses when ``accept`` runs out of
descriptors (:mod:`emlogd.daemon.listen`).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import math
import os
import select
import selectors
import socket
import struct
import termios
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

from drivers.errors import ConfigError
from emlogd.daemon.listen import AcceptBudget, AcceptPause
from emlogd.daemon.logsetup import EventLimiter

TCP_BACKLOG_BYTES = 64 * 1024
"""Default largest pending output per TCP client (the daemon's backlog plus the
kernel's send queue) before it is closed (``outputs.tcp_max_pending_bytes``)."""

MAX_TCP_CLIENTS = 32
"""Default most clients of a TCP output at a time (``outputs.tcp_max_clients``); a
newcomer beyond it evicts one."""

TCP_STALL_S = 10.0
"""Default time a TCP client may take nothing while output is pending before it is
closed (``outputs.tcp_stall_s``)."""

TCP_CHECK_S = 0.25
"""How often :meth:`TcpServerSink.housekeep` reads each client's send queue (one
``ioctl`` per client): the resolution of the stall time."""

TCP_INPUT_BURST = 4096
"""Most bytes a TCP client may send at once (read and discarded) before it is closed
(``client_sent_data``)."""

ACCEPTS_PER_ROUND = 16
"""Most connections accepted at one wake-up (twice the listen backlog): a round ends
even while a loop keeps connecting."""

THROTTLE_PAUSE_S = 0.1
"""How long the TCP output stops accepting after it reset a connection past the accept
budget (:class:`~emlogd.daemon.listen.AcceptBudget`): meanwhile connections wait in the
listen backlog (8) and the kernel drops the SYNs past it, so a reconnect loop costs a
round of at most :data:`ACCEPTS_PER_ROUND` accepts per pause instead of one per
connection; a newcomer from another host waits for the next round (or its SYN's
retransmission, 1 s, when the backlog was full)."""

TCP_INPUT_RATE = 1024.0
"""Bytes/s a TCP client's input budget refills at: a client that echoes a few sentences
now and then stays; one that sends faster is closed once its burst is spent."""

TCP_ENDED_QUIET_S = 5.0
"""How long a TCP client that ended its sending (read returned end of file) is kept
while nothing is sent to it: a half-closed reader is served as long as output flows, a
peer gone for good is noticed at the second write after its close (reset), or after
this long without output."""

RETRY_S = (1.0, 2.0, 5.0, 10.0, 30.0)
"""Delays between attempts to bind a TCP output or resolve a UDP destination."""


class _Retry:
    """When to try again: a growing delay, reset by a success."""

    def __init__(self, monotonic: Callable[[], float]) -> None:
        self.monotonic = monotonic
        self.attempts = 0
        self.next = -math.inf

    def due(self) -> bool:
        return self.monotonic() >= self.next

    def failed(self) -> float:
        delay = RETRY_S[min(self.attempts, len(RETRY_S) - 1)]
        self.attempts += 1
        self.next = self.monotonic() + delay
        return delay


@dataclass(frozen=True, slots=True)
class TcpLimits:
    """What a TCP output lets a client hold (the ``outputs.tcp_*`` keys, whose defaults
    are these)."""

    max_clients: int = MAX_TCP_CLIENTS
    max_pending_bytes: int = TCP_BACKLOG_BYTES
    stall_s: float = TCP_STALL_S


@dataclass(slots=True)
class SinkCounters:
    """Per-sink figures for the status event.

    ``dropped_clients`` counts the clients the sink closed, whatever the reason; the
    reasons apart: ``too_slow`` (pending output over the bound), ``stalled`` (nothing
    taken for the stall time), ``evicted`` (made room for a newcomer at the limit), ``sent_data`` (sent more than
    its input budget, :data:`TCP_INPUT_BURST`). ``throttled`` counts the connections
    reset at once, past the accept budget (never clients, not in ``dropped_clients``).
    """

    sentences: int = 0
    bytes: int = 0
    errors: int = 0
    dropped_clients: int = 0
    clients: int = 0
    too_slow: int = 0
    stalled: int = 0
    evicted: int = 0
    sent_data: int = 0
    throttled: int = 0

    def as_dict(self) -> dict[str, int]:
        """Plain types."""
        return {
            "sentences": self.sentences,
            "bytes": self.bytes,
            "errors": self.errors,
            "dropped_clients": self.dropped_clients,
            "clients": self.clients,
            "too_slow": self.too_slow,
            "stalled": self.stalled,
            "evicted": self.evicted,
            "sent_data": self.sent_data,
            "throttled": self.throttled,
        }


class Sink(Protocol):
    """What the daemon needs of an output."""

    name: str
    counters: SinkCounters
    state: str
    """``open``, or why not (``unbound: ...``, ``unresolved: ...``)."""

    def write(self, line: bytes) -> None:
        """Send one sentence (CR LF included); never blocks, never raises for I/O."""

    def housekeep(self) -> None:
        """Retry what failed (called from the daemon's housekeeping)."""

    def close(self) -> None:
        """Release the resources."""


def parse_hostport(
    text: str, *, default_host: str = "0.0.0.0", allow_zero: bool = False
) -> tuple[str, int]:
    """``"host:port"`` or ``":port"`` or ``"port"`` → (host, port).

    Port 0 (an ephemeral port, for tests) only with ``allow_zero``.

    Raises:
        ConfigError: not an address with a port in 1..65535.
    """
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = "", text
    host = host.strip("[]") or default_host
    if not port.isdigit() or not (0 if allow_zero else 1) <= int(port) < 65536:
        raise ConfigError(f"{text!r}: expected HOST:PORT with a port in 1..65535")
    return host, int(port)


@dataclass
class StreamSink:
    """Sentences to a binary stream (stdout or a file), flushed per sentence.

    The stream stays blocking (its descriptor is shared with whoever handed it over),
    so a sentence is written only when the descriptor polls writable: into a pipe or a
    terminal whose reader does not keep up, a sentence that does not fit is dropped and
    counted as an error instead of blocking the daemon (a stalled ``emlogd run |
    reader`` hung every output and the control socket). A sentence is far under
    ``PIPE_BUF``, and a writable pipe has room for one.
    """

    name: str
    stream: BinaryIO
    close_stream: bool = False
    counters: SinkCounters = field(default_factory=SinkCounters)
    state: str = "open"
    _ready: select.poll | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        try:
            fd = self.stream.fileno()
        except (OSError, ValueError):  # in memory: always ready
            return
        self._ready = select.poll()
        self._ready.register(fd, select.POLLOUT)

    def housekeep(self) -> None:
        pass

    def write(self, line: bytes) -> None:
        if self._ready is not None and not self._ready.poll(0):
            self.counters.errors += 1  # the reader does not keep up: dropped, not waited for
            return
        try:
            self.stream.write(line)
            self.stream.flush()
        except (OSError, ValueError):
            self.counters.errors += 1
            return
        self.counters.sentences += 1
        self.counters.bytes += len(line)

    def close(self) -> None:
        if self.close_stream:
            self.stream.close()


DROP_REASONS = {
    "client_too_slow": "too_slow",
    "client_stalled": "stalled",
    "client_evicted": "evicted",
    "client_sent_data": "sent_data",
}
"""Why the sink closes a client: the event logged, and its counter in :class:`SinkCounters`."""


_RESET = struct.pack("ii", 1, 0)
"""``SO_LINGER`` on, 0 s: ``close`` resets the connection and discards what is queued."""


def _send_queue(sock: socket.socket) -> int:
    """Bytes in the kernel's send queue of ``sock`` (sent but not acknowledged, or not
    sent yet: ``SIOCOUTQ``); 0 when it cannot be read."""
    try:
        raw = fcntl.ioctl(sock.fileno(), termios.TIOCOUTQ, b"\0\0\0\0")
    except OSError:
        return 0
    return int(struct.unpack("i", raw)[0])


def _reset(sock: socket.socket) -> None:
    """Close ``sock`` with a reset, discarding what is queued either way."""
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
    sock.close()


class _Client:
    __slots__ = (
        "addr",
        "allowance",
        "backlog",
        "connected",
        "delivered",
        "ended",
        "heard",
        "progress",
        "queued",
        "sock",
    )

    def __init__(self, sock: socket.socket, addr: object, now: float) -> None:
        self.sock = sock
        self.addr = addr
        self.backlog = bytearray()
        self.connected = now
        self.queued = 0
        """Bytes handed to the kernel so far."""
        self.delivered = 0
        """Bytes the client's end acknowledged so far (as of the last check)."""
        self.progress = now
        """When the client last took something, or had nothing pending."""
        self.allowance = float(TCP_INPUT_BURST)
        """Bytes the client may still send (refilled at :data:`TCP_INPUT_RATE`)."""
        self.heard = now
        """When the allowance was last counted."""
        self.ended: float | None = None
        """When the client ended its sending, or last had output sent after (None: it
        has not ended it)."""

    def check(self, now: float) -> int:
        """Read the send queue: note progress; return the pending bytes."""
        queue = _send_queue(self.sock)
        delivered = self.queued - queue
        pending = queue + len(self.backlog)
        if delivered > self.delivered or pending == 0:
            self.progress = now
        self.delivered = max(delivered, self.delivered)
        return pending


class TcpServerSink:
    """NMEA over TCP: several clients, none of which can lock the others out.

    Register :meth:`fileno` for reading in the daemon's selector and call
    :meth:`on_readable` when it fires (accepts clients, and discards what a client
    sends within its budget: a client that sends more is closed, ``client_sent_data``). Writes go straight to each client's socket; what the kernel
    does not take waits in a per-client backlog. :meth:`housekeep` closes a client
    whose pending output exceeds :attr:`TcpLimits.max_pending_bytes` or that has
    taken nothing for :attr:`TcpLimits.stall_s` while output was pending; at
    :attr:`TcpLimits.max_clients` a newcomer evicts a client (the module's
    docstring). An address that cannot be bound leaves the sink ``unbound`` and is
    retried from :meth:`housekeep`.
    """

    def __init__(
        self,
        listen: str,
        *,
        selector: selectors.BaseSelector | None = None,
        on_event: Callable[[str, str], None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        limits: TcpLimits = TcpLimits(),
    ) -> None:
        self.name = f"tcp:{listen}"
        self.counters = SinkCounters()
        self.host, self.port = parse_hostport(listen, allow_zero=True)
        self.clients: dict[int, _Client] = {}
        self.selector = selector
        self.on_event = on_event
        self.monotonic = monotonic
        self.limits = limits
        self.server: socket.socket | None = None
        self.state = "unbound"
        self.retry = _Retry(monotonic)
        self.pause = AcceptPause(lambda d: self._note("accept_error", d), monotonic)
        self.budget = AcceptBudget(monotonic)
        self._next_check = -math.inf
        self._bind()

    def _bind(self) -> None:
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            server.bind((self.host, self.port))
            server.listen(8)
        except OSError as exc:
            server.close()
            self.retry.failed()
            state = f"unbound: {exc.strerror or exc}"
            if state != self.state:  # one line per new reason, not per retry
                self._note("output_unbound", f"{self.name}: {state}; retrying in the background")
            self.state = state
            return
        server.setblocking(False)
        self.server = server
        if self.state != "unbound":
            self._note("output_bound", self.name)
        self.state = "open"
        if self.selector is not None:
            self.selector.register(server, selectors.EVENT_READ, self._accept)

    def housekeep(self) -> None:
        """Bind again if unbound (when due); listen again once an accept pause is over;
        close the clients that are too slow or stalled (every :data:`TCP_CHECK_S`)."""
        if self.server is None:
            if self.retry.due():
                self._bind()
            return
        if self.pause.resume_due() and self.selector is not None:
            self.selector.register(self.server, selectors.EVENT_READ, self._accept)
        now = self.monotonic()
        if now < self._next_check:
            return
        self._next_check = now + TCP_CHECK_S
        for client in list(self.clients.values()):
            pending = client.check(now)
            if client.ended is not None and now - client.ended > TCP_ENDED_QUIET_S:
                self._drop(client, "client_disconnected")
            elif pending > self.limits.max_pending_bytes:
                self._drop(client, "client_too_slow")
            elif now - client.progress > self.limits.stall_s:
                self._drop(client, "client_stalled")

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) (useful with port 0)."""
        if self.server is None:
            return self.host, self.port
        host, port = self.server.getsockname()[:2]
        return str(host), int(port)

    def fileno(self) -> int:
        return self.server.fileno() if self.server is not None else -1

    def _note(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, detail)

    def _accept(self) -> None:
        """Accept what waits (at most :data:`ACCEPTS_PER_ROUND`): each connection past the
        budget is reset, and the listener then rests for :data:`THROTTLE_PAUSE_S`."""
        throttled = False
        for _ in range(ACCEPTS_PER_ROUND):
            if self.server is None:
                break
            try:
                sock, addr = self.server.accept()
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self.counters.errors += 1
                if self.pause.failed(exc):
                    self._stop_listening()
                return
            self.pause.accepted()
            if not self.budget.admit(str(addr[0])):
                _reset(sock)
                self.counters.throttled += 1
                self._note("client_throttled", str(addr))
                throttled = True
                continue
            self._admit(sock, addr)
        if throttled:
            self.pause.hold(THROTTLE_PAUSE_S)
            self._stop_listening()

    def _stop_listening(self) -> None:
        if self.selector is not None and self.server is not None:
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(self.server)

    def _admit(self, sock: socket.socket, addr: object) -> None:
        """Make a client of an accepted connection (evicting one at the limit)."""
        now = self.monotonic()
        while self.clients and len(self.clients) >= self.limits.max_clients:
            self._drop(self._eviction_candidate(now), "client_evicted")
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock, addr, now)
        self.clients[sock.fileno()] = client
        self.counters.clients = len(self.clients)
        if self.selector is not None:
            self.selector.register(sock, selectors.EVENT_READ, lambda c=client: self._drain(c))
        self._note("client_connected", str(addr))

    def _eviction_candidate(self, now: float) -> _Client:
        """The client to close for a newcomer: the one that ended its sending first (it
        may be gone), else the one stalled longest among those with output pending that
        took nothing since the last check (a reader with bytes in flight took some), else
        the most recently connected."""
        ended = [c for c in self.clients.values() if c.ended is not None]
        if ended:
            return min(ended, key=lambda c: c.connected)
        stalled = [c for c in self.clients.values() if c.check(now) > 0 and c.progress < now]
        if stalled:
            return min(stalled, key=lambda c: (c.progress, c.connected))
        return max(self.clients.values(), key=lambda c: c.connected)

    def on_readable(self) -> None:
        """Accept pending clients (when used without a selector)."""
        self._accept()

    def _drain(self, client: _Client) -> None:
        """A client sent something or ended its sending: discard input within the
        client's budget (closed past it); at its end, stop reading it (end of file stays
        readable) and serve it on (:data:`TCP_ENDED_QUIET_S`)."""
        try:
            data = client.sock.recv(TCP_INPUT_BURST)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._drop(client, "client_disconnected")
            return
        if not data:
            client.ended = self.monotonic()
            if self.selector is not None:
                with contextlib.suppress(KeyError, ValueError):
                    self.selector.unregister(client.sock)
            return
        now = self.monotonic()
        refill = (now - client.heard) * TCP_INPUT_RATE
        client.heard = now
        client.allowance = min(client.allowance + refill, TCP_INPUT_BURST) - len(data)
        if client.allowance < 0:
            self._drop(client, "client_sent_data")

    def _drop(self, client: _Client, why: str) -> None:
        fd = client.sock.fileno()
        if self.selector is not None and fd >= 0:
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(client.sock)
        self.clients.pop(fd, None)
        reason = DROP_REASONS.get(why)
        if reason is not None:  # reset: output queued for a client that does not take it
            _reset(client.sock)  # would hold the FIN, and kernel memory
        else:
            client.sock.close()
        self.counters.clients = len(self.clients)
        if reason is not None:
            self.counters.dropped_clients += 1
            setattr(self.counters, reason, getattr(self.counters, reason) + 1)
        self._note(why, str(client.addr))

    def write(self, line: bytes) -> None:
        self.counters.sentences += 1
        for client in list(self.clients.values()):
            buf = client.backlog
            buf += line
            try:
                sent = client.sock.send(buf)
            except (BlockingIOError, InterruptedError):
                sent = 0
            except OSError:
                self._drop(client, "client_disconnected")
                continue
            self.counters.bytes += sent
            client.queued += sent
            if sent and client.ended is not None:
                client.ended = self.monotonic()
            del buf[:sent]
            if len(buf) > self.limits.max_pending_bytes:
                self._drop(client, "client_too_slow")

    def close(self) -> None:
        for client in list(self.clients.values()):
            self._drop(client, "client_disconnected")
        if self.server is not None:
            if self.selector is not None:
                with contextlib.suppress(KeyError, ValueError):
                    self.selector.unregister(self.server)
            self.server.close()


LINK_CHECK_S = 2.0
"""How often a pty output checks that its link still names its pty, s: a link removed
(by hand, a clean-up of the run directory) is published again, since a reader that
opens the pty by its link (an autopilot after its own restart) found nothing there
until the daemon's restart. A link naming something else is logged and left as it is.
The pty's modes are checked as often (:meth:`drivers.io.vpty.VirtualPort.check_modes`)."""

MODES_LOG_S = 60.0
"""Least time between two ``pty_modes_restored`` lines of one pty, s: a reader that sets
its modes at every open is one line a minute (:class:`~emlogd.daemon.logsetup.EventLimiter`)."""


class PtySink:
    """Sentences on a virtual serial port published at a stable symlink.

    Args:
        link: the symlink's path.
        mode: permission bits of the pty.
        group: the pty's group (None: unchanged).
        on_event: called as ``on_event(kind, detail)`` when the link was published again
            (``pty_link_restored``) or names something else (``pty_link``, once).
        monotonic: the clock of the link's checks.
    """

    def __init__(
        self,
        link: str | Path,
        mode: int = 0o660,
        group: str | None = None,
        *,
        on_event: Callable[[str, str], None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        from drivers.io.vpty import VirtualPort

        self.name = f"pty:{link}"
        self.counters = SinkCounters()
        self.state = "open"
        self.port = VirtualPort(link, mode=mode, group=group)
        self.on_event = on_event
        self.monotonic = monotonic
        self._next_check = monotonic() + LINK_CHECK_S
        self._problem = ""
        self._modes_told = EventLimiter(MODES_LOG_S, frozenset({"pty_modes_restored"}))

    def housekeep(self) -> None:
        """Every :data:`LINK_CHECK_S`: the link published again if it was removed, the
        pty's modes put back to raw if a reader changed them (``pty_modes_restored``, at
        most one line per :data:`MODES_LOG_S` with the count since the line before)."""
        now = self.monotonic()
        if now < self._next_check:
            return
        self._next_check = now + LINK_CHECK_S
        if self.port.check_modes():
            untold = self._modes_told.allow(self.name, "pty_modes_restored", now)
            if untold is not None:
                n = untold + 1
                self._note(
                    "pty_modes_restored",
                    f"{self.port.link}: a reader changed the pty's modes; put back to raw "
                    f"({n} time{'s' if n > 1 else ''})",
                )
        why = self.port.check_link()
        if why == "restored":
            why = ""
            self._note("pty_link_restored", f"{self.port.link}: removed, published again")
        elif why and why != self._problem:
            self._note("pty_link", f"{self.port.link}: {why}")
        self._problem = why

    def _note(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, detail)

    def write(self, line: bytes) -> None:
        try:
            n = self.port.write(line)
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EIO):
                self.counters.errors += 1
            return
        if n:  # 0: nobody reads the pty (or it is full); VirtualPort counts the drop
            self.counters.sentences += 1
            self.counters.bytes += n

    def close(self) -> None:
        self.port.close()


def stdout_sink() -> StreamSink:
    """A sink on the process's stdout (binary, unbuffered per sentence)."""
    return StreamSink("stdout", os.fdopen(os.dup(1), "wb"), close_stream=True)
