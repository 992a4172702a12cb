"""Output sinks for the corrected NMEA: pty, TCP server, UDP, stdout, file.

Every sink takes whole sentences (bytes ending in CR LF) and never blocks the
daemon loop: writes are non-blocking, a TCP client that stops reading is dropped
once its bounded backlog is full, UDP send errors are counted and skipped. Sinks
that need the selector (the TCP server) expose their file descriptors.
"""

from __future__ import annotations

import contextlib
import errno
import os
import selectors
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

from drivers.errors import ConfigError, DeviceError

TCP_BACKLOG_BYTES = 64 * 1024
"""Largest unsent backlog per TCP client before it is dropped."""


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

    def write(self, line: bytes) -> None:
        """Send one sentence (CR LF included); never blocks, never raises for I/O."""

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
    """Sentences as UDP datagrams to one destination (broadcast allowed)."""

    def __init__(self, dest: str) -> None:
        self.name = f"udp:{dest}"
        self.counters = SinkCounters()
        self.addr = parse_hostport(dest, default_host="127.0.0.1")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self.sock.setblocking(False)

    def write(self, line: bytes) -> None:
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
    dropped (a client that stops reading never blocks the loop).

    Raises:
        DeviceError: the address cannot be bound.
    """

    def __init__(
        self,
        listen: str,
        *,
        selector: selectors.BaseSelector | None = None,
        on_event: Callable[[str, str], None] | None = None,
    ) -> None:
        self.name = f"tcp:{listen}"
        self.counters = SinkCounters()
        host, port = parse_hostport(listen, allow_zero=True)
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.server.bind((host, port))
        except OSError as exc:
            self.server.close()
            raise DeviceError(f"TCP output {listen}: {exc.strerror or exc}") from None
        self.server.listen(8)
        self.server.setblocking(False)
        self.clients: dict[int, _Client] = {}
        self.selector = selector
        self.on_event = on_event
        if selector is not None:
            selector.register(self.server, selectors.EVENT_READ, self._accept)

    @property
    def address(self) -> tuple[str, int]:
        """The bound (host, port) (useful with port 0)."""
        host, port = self.server.getsockname()[:2]
        return str(host), int(port)

    def fileno(self) -> int:
        return self.server.fileno()

    def _note(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, detail)

    def _accept(self) -> None:
        while True:
            try:
                sock, addr = self.server.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self.counters.errors += 1
                self._note("accept_error", str(exc))
                return
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
        if self.selector is not None:
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(self.server)
        self.server.close()


class PtySink:
    """Sentences on a virtual serial port published at a stable symlink."""

    def __init__(self, link: str | Path, mode: int = 0o660) -> None:
        from drivers.io.vpty import VirtualPort

        self.name = f"pty:{link}"
        self.counters = SinkCounters()
        self.port = VirtualPort(link, mode=mode)

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
