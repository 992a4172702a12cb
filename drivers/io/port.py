"""Serial input: a port opened through ``serial.serial_for_url``, read in chunks.

``serial_for_url`` means ``/dev/ttyUSB0``, ``/dev/pts/N``, ``loop://``,
``socket://host:port`` and ``spy://...`` all work. This is the only module that
opens serial ports. A :class:`SerialSource`:

- reads whatever is waiting in one non-blocking call (never byte-at-a-time
  ``readline``) and stamps it with the receive time (a :data:`Chunk`);
- survives unplugging: an error or EOF closes the port, emits ``disconnected`` and
  retries with backoff (``backoff_s``) from :meth:`poll`; a device missing at start is
  the same case, not a crash;
- detects silence: no data for ``stale_timeout_s`` emits one ``stale`` event, data
  coming back emits ``alive``;
- follows its path: a device silent for :data:`DEVICE_CHECK_S` whose path is gone or
  names another device (a pty re-created at the same link, an adapter re-enumerated
  under its udev name) while the old one stays open is closed and opened again at its
  path (the old descriptor would be read, silent, for ever);
- keeps its modes: the terminal modes pyserial set at the open (raw) are checked every
  :data:`DEVICE_CHECK_S` and put back if another process changed them (``stty -F
  /dev/ttyUSB0 sane`` by hand: canonical mode held a binary DVL's data back for good,
  and echo sent everything the device said back to it), one ``modes_restored`` event
  per :data:`MODES_EVENT_S` with the count since the one before;
- keeps to its pty: a link that named a pty the port read (a fake device's, a
  multiplexer's) and now, unchanged, names a pty made since under the same number (the
  device went away and another program's pty took the freed number) is not opened
  until the link is made again (:func:`pty_reused`): the other program's session is
  no device of this port's.

Events are queued and drained with :meth:`events`. The daemon registers
:meth:`fileno` in its selector (sources without a file descriptor, like
``loop://``, are read each loop turn).

A ``socket://host:port`` input is connected without blocking (pyserial's own open
waits up to 5 s for the connect, and then drains whatever the peer has sent for as
long as more keeps coming): :meth:`open` starts the connect and each :meth:`poll`
looks whether it is done, for at most :data:`CONNECT_TIMEOUT_S`; the connected socket
is then read like a device, with one ``os.read``. Its host must be an IP address
(:func:`socket_url_problem`): a host name would be resolved by the system's resolver,
which can wait for seconds in the caller's one thread at every retry. An ``rfc2217://``
input is refused for the same reason (:func:`url_problem`).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import math
import os
import select
import socket
import stat
import termios
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal
from urllib.parse import urlsplit

import serial

from drivers.errors import DeviceError

EMPTY_READS_LOST = 50
"""Consecutive empty reads of a raw descriptor after which the port counts as lost."""

DEVICE_CHECK_S = 2.0
"""Silence after which a device port checks, at most once per this long, that its path
still names the device it holds open."""

CONNECT_TIMEOUT_S = 5.0
"""Longest a ``socket://`` input's connect may take; then it failed, and is retried."""

CONNECT_POLL_S = 0.05
"""How often a ``socket://`` connect in progress is looked at, s."""

PTY_MAJORS = range(136, 144)
"""The major device numbers of Unix98 pty slaves (``/dev/pts/N``)."""

MODES_EVENT_S = 60.0
"""Least time between two ``modes_restored`` events of one port, s."""

EventKind = Literal["connected", "disconnected", "stale", "alive", "error", "modes_restored"]


Chunk = tuple[float, bytes]
"""Bytes read in one call, after their receive time (s since the epoch): ``(t, data)``.
A plain tuple: the daemon builds one per wake-up, and at live rates a read took
29–34 µs of CPU with a frozen dataclass, 22–23 µs without (``bench/bench_wake_costs.py``,
docs/BENCHMARKS.md)."""


class _TcpStream:
    """A connected ``socket://`` input: what :class:`SerialSource` needs of a port."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock

    def fileno(self) -> int:
        return self.sock.fileno()

    def read(self, size: int) -> bytes:
        return self.sock.recv(size)

    def close(self) -> None:
        self.sock.close()


@dataclass(frozen=True, slots=True)
class PortEvent:
    """A change of a port's state."""

    t: float
    port: str
    kind: EventKind
    detail: str


class SerialSource:
    """One input port.

    Args:
        name: port name (records and events carry it).
        url: a device path or any pyserial URL.
        baudrate: serial rate, bit/s.
        stale_timeout_s: silence after which a ``stale`` event is emitted.
        read_size: most bytes read in one call.
        backoff_s: reconnect delays, the last one repeating.
        clock: receive-time clock (epoch seconds).
        monotonic: clock for timeouts and backoff.

    Raises:
        DeviceError: the URL scheme is not one pyserial knows.
    """

    def __init__(
        self,
        name: str,
        url: str,
        *,
        baudrate: int = 9600,
        stale_timeout_s: float = 5.0,
        read_size: int = 4096,
        backoff_s: Sequence[float] = (0.5, 1.0, 2.0, 5.0),
        clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        if not backoff_s:
            raise ValueError("backoff_s needs at least one delay")
        self.name = name
        self.url = url
        self.baudrate = baudrate
        self.stale_timeout_s = stale_timeout_s
        self.read_size = read_size
        self.backoff_s = tuple(backoff_s)
        self.clock = clock
        self.monotonic = monotonic
        self._ser: serial.SerialBase | _TcpStream | None = None
        self._tcp: tuple[str, int] | None = _tcp_address(url)
        """A ``socket://`` URL's host and port (connected here, without blocking)."""
        self._connecting: tuple[socket.socket, float, bool] | None = None
        """A connect in progress: its socket, its deadline, and whether it is the first
        attempt (its failure is then the ``disconnected`` event)."""
        self._raw_fd: int | None = None
        self._held_pty: HeldPty | None = None
        """The link and the pty it named when the port last opened through a link to a
        pty (:func:`pty_reused`); None otherwise."""
        self._empty = 0
        self._events: list[PortEvent] = []
        self._attempt = 0
        self._next_try: float | None = None
        self._last_data: float | None = None
        self._next_check = -math.inf
        """When a silent device may next be checked against its path."""
        self._modes: list[Any] | None = None
        """The device's terminal modes as set at the open (``tcgetattr``); None for a
        socket or a port without a descriptor."""
        self._next_modes = -math.inf
        self._next_modes_event = -math.inf
        self._modes_untold = 0
        self.modes_restored = 0
        """How often the device's modes were put back (:meth:`_keep_modes`)."""
        self._stale = False
        self._ever_connected = False
        self.why_closed: str | None = "not opened yet"
        """Why the port is not open (None: it is)."""
        self.bytes = 0
        self.chunks = 0
        self.reconnects = 0
        self.errors = 0
        self._check_url()

    def _check_url(self) -> None:
        problem = url_problem(self.url)
        if problem is not None:
            raise DeviceError(f"port {self.name}: {problem}")

    # -- state ----------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        """The port is open."""
        return self._ser is not None

    def _event(self, kind: EventKind, detail: str = "") -> None:
        self._events.append(PortEvent(self.clock(), self.name, kind, detail))

    @property
    def has_events(self) -> bool:
        """Events are queued (a cheap check before :meth:`events`)."""
        return bool(self._events)

    def events(self) -> list[PortEvent]:
        """Drain the queued events."""
        out, self._events = self._events, []
        return out

    def counters_dict(self, *, stale: bool = True) -> dict[str, object]:
        """Figures for the status event (``stale``: with the port's own staleness)."""
        figures: dict[str, object] = {
            "open": self.is_open,
            "why_closed": None if self.is_open else self.why_closed,
            "bytes": self.bytes,
            "chunks": self.chunks,
            "reconnects": self.reconnects,
            "errors": self.errors,
        }
        if stale:
            figures["stale"] = self._stale
        return figures

    # -- open / close ---------------------------------------------------------

    def open(self) -> bool:
        """Try to open the port now; on failure schedule a retry. Returns success."""
        if self._ser is not None:
            return True
        if self._tcp is not None:
            return self._open_tcp(*self._tcp)
        reused = pty_reused(self.url, self._held_pty)
        if reused is not None:
            self._schedule(reused)
            return False
        try:
            ser = serial.serial_for_url(
                self.url, baudrate=self.baudrate, timeout=0, do_not_open=True
            )
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            kind = _not_a_device(self.url)
            self._schedule(f"cannot open {self.url}: {kind or exc}")
            return False
        self._ser = ser
        # A plain POSIX port (device, pty) is read with one os.read on its
        # non-blocking descriptor: pyserial's read adds an ioctl and a select per call.
        # Other URL handlers (spy://, loop://) keep pyserial's read.
        self._connected(self.fileno() if type(ser).__module__ == "serial.serialposix" else None)
        return True

    def _open_tcp(self, host: str, port: int) -> bool:
        """Start or look at the non-blocking connect of a ``socket://`` input."""
        now = self.monotonic()
        if self._connecting is None:
            first = self._next_try is None and self._attempt == 0
            try:
                family, kind, proto, _, addr = socket.getaddrinfo(
                    host, port, type=socket.SOCK_STREAM, flags=socket.AI_NUMERICHOST
                )[0]
                sock = socket.socket(family, kind, proto)
            except OSError as exc:
                self._schedule(f"cannot open {self.url}: {exc}")
                return False
            sock.setblocking(False)
            err = sock.connect_ex(addr)
            if err not in (0, errno.EINPROGRESS):
                sock.close()
                self._schedule(f"cannot open {self.url}: {os.strerror(err)}")
                return False
            self._connecting = (sock, now + CONNECT_TIMEOUT_S, first)
            self.why_closed = f"connecting to {host}:{port}"
        sock, deadline, first = self._connecting
        _, done, _ = select.select([], [sock], [], 0)
        if not done and now < deadline:
            self._next_try = now + CONNECT_POLL_S
            return False
        self._connecting = None
        err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) if done else errno.ETIMEDOUT
        if err:
            sock.close()
            if first:
                self._next_try = None
            self._schedule(f"cannot open {self.url}: {os.strerror(err)}")
            return False
        self._ser = _TcpStream(sock)
        self._connected(sock.fileno())
        return True

    def _connected(self, raw_fd: int | None) -> None:
        self.why_closed = None
        self._raw_fd = raw_fd
        if self._tcp is None and raw_fd is not None:
            self._held_pty = held_pty(self.url, raw_fd)
            try:
                self._modes = termios.tcgetattr(raw_fd)
            except (termios.error, OSError):
                self._modes = None
        if self._ever_connected:
            self.reconnects += 1
        self._ever_connected = True
        self._attempt = 0
        self._next_try = None
        self._last_data = self.monotonic()
        self._event("connected", self.url)

    def _schedule(self, why: str) -> None:
        self.why_closed = why
        delay = self.backoff_s[min(self._attempt, len(self.backoff_s) - 1)]
        first = self._next_try is None and self._attempt == 0
        self._attempt += 1
        self._next_try = self.monotonic() + delay
        if first:
            self._event("disconnected", why)

    def _lost(self, why: str) -> None:
        self.errors += 1
        self._close_port()
        self._attempt = 0
        self._next_try = None
        self._schedule(why)

    def _close_port(self) -> None:
        ser, self._ser = self._ser, None
        self._raw_fd = None
        self._modes = None
        if ser is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                ser.close()

    def close(self) -> None:
        """Close the port and stop retrying."""
        self._close_port()
        if self._connecting is not None:
            self._connecting[0].close()
            self._connecting = None
        self._next_try = None

    def fileno(self) -> int | None:
        """File descriptor to select on, or None (closed, or a URL without one)."""
        ser = self._ser
        if ser is None:
            return None
        try:
            fd = ser.fileno()
        except (AttributeError, serial.SerialException, OSError, NotImplementedError):
            return None
        return fd if isinstance(fd, int) and fd >= 0 else None

    # -- data -----------------------------------------------------------------

    def read(self) -> Chunk | None:
        """Read what is waiting (non-blocking). None if nothing, or the port was lost."""
        ser = self._ser
        if ser is None:
            return None
        try:
            if self._raw_fd is not None:
                try:
                    data = os.read(self._raw_fd, self.read_size)
                except BlockingIOError:
                    return None
                if not data:
                    # a raw tty with VMIN = 0 reads empty when nothing waits; a port that
                    # keeps reading empty while select says readable is gone
                    readable, _, _ = select.select([self._raw_fd], [], [], 0)
                    self._empty = self._empty + 1 if readable else 0
                    if self._empty >= EMPTY_READS_LOST:
                        raise OSError("device reports readiness to read but returns no data")
                    return None
                self._empty = 0
            else:
                waiting = int(getattr(ser, "in_waiting", 0))
                data = ser.read(min(max(waiting, 1), self.read_size) if waiting else self.read_size)
        except (serial.SerialException, OSError) as exc:
            self._lost(f"read failed: {exc}")
            return None
        if not data:
            return None
        now = self.clock()
        self._last_data = self.monotonic()
        self.bytes += len(data)
        self.chunks += 1
        if self._stale:
            self._stale = False
            self._event("alive", "data again")
        return now, data

    def poll(self) -> list[PortEvent]:
        """Drive reconnects and silence detection; return (and drain) the events."""
        now = self.monotonic()
        if self._ser is None and self._next_try is not None and now >= self._next_try:
            self.open()
        if (
            self._raw_fd is not None
            and self._tcp is None
            and self._last_data is not None
            and now - self._last_data >= DEVICE_CHECK_S
            and now >= self._next_check
        ):
            self._next_check = now + DEVICE_CHECK_S
            why = _path_moved(self.url, self._raw_fd)
            if why is not None:
                self._lost(why)
        if self._raw_fd is not None and self._modes is not None and now >= self._next_modes:
            self._next_modes = now + DEVICE_CHECK_S
            self._keep_modes(self._raw_fd, self._modes, now)
        if (
            self._ser is not None
            and not self._stale
            and self._last_data is not None
            and now - self._last_data > self.stale_timeout_s
        ):
            self._stale = True
            self._event("stale", f"no data for {now - self._last_data:.1f} s")
        return self.events()

    def _keep_modes(self, fd: int, modes: list[Any], now: float) -> None:
        """Put the device's terminal modes back to ``modes`` if another process changed
        them; say so at most once per :data:`MODES_EVENT_S`."""
        try:
            if termios.tcgetattr(fd) == modes:
                return
            termios.tcsetattr(fd, termios.TCSANOW, modes)
        except (termios.error, OSError):
            return
        self.modes_restored += 1
        self._modes_untold += 1
        if now >= self._next_modes_event:
            self._next_modes_event = now + MODES_EVENT_S
            n, self._modes_untold = self._modes_untold, 0
            self._event(
                "modes_restored",
                f"{self.url}: its terminal modes were changed by another process; put back "
                f"({n} time{'s' if n > 1 else ''})",
            )


_NOT_DEVICES = (
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISREG, "a regular file"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)
"""The kinds of file at an input's path that are no serial device, and their names."""


def _not_a_device(url: str) -> str | None:
    """What the file at the path ``url`` is when it is no device (a FIFO, a regular file,
    a socket, a directory: an operator's ``mkfifo`` or capture left where the device
    belongs), said in place of the termios error pyserial gives; None for a device, a
    URL or a path that is not there."""
    if "://" in url:
        return None
    try:
        mode = Path(url).stat().st_mode
    except OSError:
        return None
    for test, kind in _NOT_DEVICES:
        if test(mode):
            return f"{kind}, not a serial device or pty (tried again with backoff)"
    return None


def _path_moved(url: str, fd: int) -> str | None:
    """Why the device path ``url`` no longer names the device open on ``fd``; None while
    it does (or it is no path)."""
    if "://" in url:
        return None
    try:
        held = os.fstat(fd)
        named = Path(url).stat()
    except FileNotFoundError:
        return f"{url} is gone"
    except OSError:
        return None
    if (named.st_dev, named.st_ino, named.st_rdev) != (held.st_dev, held.st_ino, held.st_rdev):
        return f"{url} now names another device"
    return None


@dataclass(frozen=True, slots=True)
class HeldPty:
    """A pty a port opened through a link: the link's identity and the pty's."""

    link: tuple[int, int, int]
    """The link's own (st_dev, st_ino, st_ctime_ns): another link made at the path
    differs."""
    rdev: int
    """The pty's device number (its major and its number under ``/dev/pts``)."""
    born_ns: int
    """The pty's ``st_ctime_ns``: devpts makes its node when the pty is made, and a pty
    made later under the same number has a later one (reading and writing leave it)."""


def held_pty(url: str, fd: int) -> HeldPty | None:
    """What :func:`pty_reused` needs of a port opened at the path ``url`` on ``fd``: None
    unless ``url`` is a symbolic link and ``fd`` a pty slave."""
    if "://" in url:
        return None
    try:
        link = Path(url).lstat()
        held = os.fstat(fd)
    except OSError:
        return None
    if not stat.S_ISLNK(link.st_mode) or os.major(held.st_rdev) not in PTY_MAJORS:
        return None
    return HeldPty((link.st_dev, link.st_ino, link.st_ctime_ns), held.st_rdev, held.st_ctime_ns)


def pty_reused(url: str, held: HeldPty | None) -> str | None:
    """Why the port must not open ``url`` again: the link it opened a pty through
    (``held``) is the same link, and it names a pty under the same number made since —
    the port's device is gone and another program's pty took its number; None when the
    link was made again (a restarted fake device, a multiplexer's new session) or names
    the pty it did."""
    if held is None:
        return None
    try:
        path = Path(url)
        link = path.lstat()
        named = path.stat()
        target = path.readlink()
    except OSError:
        return None
    if (link.st_dev, link.st_ino, link.st_ctime_ns) != held.link:
        return None
    if named.st_rdev != held.rdev or named.st_ctime_ns == held.born_ns:
        return None
    return (
        f"{url} still names {target}, a pty made since under the number of the "
        "one it named: another program's (not read until the link is made again)"
    )


def _tcp_address(url: str) -> tuple[str, int] | None:
    """The host and port of a ``socket://host:port`` URL, else None (pyserial checks the
    URL itself: :meth:`SerialSource._check_url`)."""
    if not url.lower().startswith("socket://"):  # pyserial takes the scheme in any case
        return None
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        return None
    if parts.hostname is None or port is None:
        return None
    return parts.hostname, port


BLOCKING_SCHEMES = ("rfc2217",)
"""pyserial URL schemes whose open waits in the caller's thread: ``rfc2217://`` resolves
its host, connects and negotiates the telnet options with timeouts of seconds (3.4 s
against a server that never answers, 5 s against one that is off, measured in the
daemon), at every retry."""


def url_problem(url: str) -> str | None:
    """Why ``url`` cannot be an input (no URL pyserial knows, a scheme of
    :data:`BLOCKING_SCHEMES`, or a ``socket://`` host that is not an IP address:
    :func:`socket_url_problem`), else None. The config's check: a URL refused only when
    its port is made would end the daemon at a reload, after the new config was taken."""
    try:
        serial.serial_for_url(url, do_not_open=True)
    except ValueError as exc:
        return f"invalid URL {url!r}: {exc}"
    except (serial.SerialException, OSError):
        pass  # a device that is missing now is retried later
    scheme = url.partition("://")[0].lower() if "://" in url else ""
    if scheme in BLOCKING_SCHEMES:
        return (
            f"{url!r}: pyserial opens a {scheme}:// input in the daemon's one thread, its "
            "connect and negotiation waiting for seconds at every retry; give the device "
            "server's raw TCP port as socket://ADDRESS:PORT"
        )
    return socket_url_problem(url)


def socket_url_problem(url: str) -> str | None:
    """Why ``url``, a ``socket://`` URL, cannot be an input (its host is not an IP
    address: resolving a name could hold the daemon's one thread), else None (any other
    URL too)."""
    address = _tcp_address(url)
    if address is None:
        return None
    try:
        ipaddress.ip_address(address[0])
    except ValueError:
        return (
            f"{url!r}: a socket:// input needs an IP address, not a host name (resolving "
            "one could hold the daemon for seconds); write the address, e.g. "
            "socket://127.0.0.1:10110"
        )
    return None
