"""Output sinks for the corrected NMEA: pty, TCP server, UDP, stdout, file.

Every sink takes whole sentences (bytes ending in CR LF) and never blocks the
daemon loop: writes are non-blocking, a TCP client that stops reading is dropped
once its bounded backlog is full, UDP send errors are counted and skipped. Sinks
that need the selector (the TCP server) expose their file descriptors.

A network output never stops the daemon: a TCP address that cannot be bound (in
use, not yet configured) or a UDP destination that does not resolve leaves the sink
``unbound``/``unresolved`` (its :attr:`state`) and is retried from
:meth:`housekeep` with a growing delay (:data:`RETRY_S`). Addresses are resolved
once, never per sentence. The TCP server takes at most :data:`MAX_TCP_CLIENTS`
(the next ones are closed at once) and pauses when ``accept`` runs out of
descriptors (:mod:`emlogd.daemon.listen`).
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import selectors
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

from drivers.errors import ConfigError
from emlogd.daemon.listen import AcceptPause

TCP_BACKLOG_BYTES = 64 * 1024
"""Largest unsent backlog per TCP client before it is dropped."""

MAX_TCP_CLIENTS = 32
"""Most clients of the TCP output at a time; the next ones are closed at once."""

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


@dataclass(slots=True)
class SinkCounters:
    """Per-sink figures for the status event."""

    sentences: int = 0
    bytes: int = 0
    errors: int = 0
    dropped_clients: int = 0
    clients: int = 0

    def as_dict(self) -> dict[str, int]:
        """Plain types."""
        return {
            "sentences": self.sentences,
            "bytes": self.bytes,
            "errors": self.errors,
            "dropped_clients": self.dropped_clients,
            "clients": self.clients,
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
    """Sentences to a binary stream (stdout or a file), flushed per sentence."""

    name: str
    stream: BinaryIO
    close_stream: bool = False
    counters: SinkCounters = field(default_factory=SinkCounters)
    state: str = "open"

    def housekeep(self) -> None:
        pass

    def write(self, line: bytes) -> None:
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


class UdpSink:
    """Sentences as UDP datagrams to one destination (broadcast allowed).

    The destination is resolved once; one that does not resolve is retried from
    :meth:`housekeep` (sentences meanwhile are counted as errors).
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
        self.addr: tuple[str, int] | None = None
        self.state = "unresolved"
        self.retry = _Retry(monotonic)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self.sock.setblocking(False)
        self.housekeep()

    def housekeep(self) -> None:
        if self.addr is not None or not self.retry.due():
            return
        try:
            info = socket.getaddrinfo(self.host, self.port, socket.AF_INET, socket.SOCK_DGRAM)
            addr = info[0][4]
            self.addr = (str(addr[0]), int(addr[1]))
        except (OSError, IndexError) as exc:
            delay = self.retry.failed()
            self.state = f"unresolved: {exc}"
            if self.on_event is not None:
                self.on_event("output_unresolved", f"{self.name}: {exc}; retry in {delay:g} s")
            return
        self.state = "open"

    def write(self, line: bytes) -> None:
        if self.addr is None:
            self.counters.errors += 1
            return
        try:
            self.sock.sendto(line, self.addr)
        except OSError:
            self.counters.errors += 1
            return
        self.counters.sentences += 1
        self.counters.bytes += len(line)

    def close(self) -> None:
        self.sock.close()


class _Client:
    __slots__ = ("addr", "backlog", "sock")

    def __init__(self, sock: socket.socket, addr: object) -> None:
        self.sock = sock
        self.addr = addr
        self.backlog = bytearray()


class TcpServerSink:
    """NMEA over TCP: several clients, each with a bounded backlog.

    Register :meth:`fileno` for reading in the daemon's selector and call
    :meth:`on_readable` when it fires (accepts clients, and discards anything a
    client sends). Writes go straight to each client's socket; what the kernel
    does not take is kept up to :data:`TCP_BACKLOG_BYTES`, then the client is
    dropped (a client that stops reading never blocks the loop). An address that
    cannot be bound leaves the sink ``unbound`` and is retried from :meth:`housekeep`.
    """

    def __init__(
        self,
        listen: str,
        *,
        selector: selectors.BaseSelector | None = None,
        on_event: Callable[[str, str], None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = f"tcp:{listen}"
        self.counters = SinkCounters()
        self.host, self.port = parse_hostport(listen, allow_zero=True)
        self.clients: dict[int, _Client] = {}
        self.selector = selector
        self.on_event = on_event
        self.server: socket.socket | None = None
        self.state = "unbound"
        self.refused = 0
        self.retry = _Retry(monotonic)
        self.pause = AcceptPause(lambda d: self._note("accept_error", d), monotonic)
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
        """Bind again if unbound (when due); listen again once an accept pause is over."""
        if self.server is None:
            if self.retry.due():
                self._bind()
            return
        if self.pause.resume_due() and self.selector is not None:
            self.selector.register(self.server, selectors.EVENT_READ, self._accept)

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
        while self.server is not None:
            try:
                sock, addr = self.server.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self.counters.errors += 1
                if self.pause.failed(exc) and self.selector is not None:
                    with contextlib.suppress(KeyError, ValueError):
                        self.selector.unregister(self.server)
                return
            self.pause.accepted()
            if len(self.clients) >= MAX_TCP_CLIENTS:
                self.refused += 1
                sock.close()
                continue
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _Client(sock, addr)
            self.clients[sock.fileno()] = client
            self.counters.clients = len(self.clients)
            if self.selector is not None:
                self.selector.register(sock, selectors.EVENT_READ, lambda c=client: self._drain(c))
            self._note("client_connected", str(addr))

    def on_readable(self) -> None:
        """Accept pending clients (when used without a selector)."""
        self._accept()

    def _drain(self, client: _Client) -> None:
        """A client sent something or hung up: discard input, notice the close."""
        try:
            data = client.sock.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(client, "client_disconnected")

    def _drop(self, client: _Client, why: str) -> None:
        fd = client.sock.fileno()
        if self.selector is not None and fd >= 0:
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(client.sock)
        self.clients.pop(fd, None)
        client.sock.close()
        self.counters.clients = len(self.clients)
        if why != "client_disconnected":
            self.counters.dropped_clients += 1
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
            del buf[:sent]
            if len(buf) > TCP_BACKLOG_BYTES:
                self._drop(client, "client_too_slow")

    def close(self) -> None:
        for client in list(self.clients.values()):
            self._drop(client, "client_disconnected")
        if self.server is not None:
            if self.selector is not None:
                with contextlib.suppress(KeyError, ValueError):
                    self.selector.unregister(self.server)
            self.server.close()


class PtySink:
    """Sentences on a virtual serial port published at a stable symlink."""

    def __init__(self, link: str | Path, mode: int = 0o660, group: str | None = None) -> None:
        from drivers.io.vpty import VirtualPort

        self.name = f"pty:{link}"
        self.counters = SinkCounters()
        self.state = "open"
        self.port = VirtualPort(link, mode=mode, group=group)

    def housekeep(self) -> None:
        pass

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
