"""structlog configuration: JSON lines when the stream is not a terminal, console otherwise;
the daemon's limit on repeated events and its one-line status for a terminal.

Library modules only call ``structlog.get_logger(__name__)``; the CLI calls
:func:`configure_logging` once. The stdlib root logger is never configured.

Writing a log line never raises and never waits (:class:`LogStream`): a stream whose
reader went away (a pipe closed, journald stopped: ``EPIPE``) or that fails otherwise
costs that line, counted by :func:`lost_lines`, never the daemon (a ``BrokenPipeError``
out of a log call ended ``emlogd run`` with exit code 0, which systemd's
``Restart=on-failure`` does not restart); a reader that is alive but does not read
(a stopped ``emlogd run | less``, a journald stuck) costs the lines past
:data:`LOG_BACKLOG_BYTES`, counted alike (a blocking write held the daemon's one thread,
its outputs and its control socket, for as long as the reader slept).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import select
import stat
import sys
import threading
import time
from collections.abc import Callable
from typing import Any, Literal, TextIO

import structlog

LogFormat = Literal["auto", "json", "console"]

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
}


_console = False
_lost = 0

LOG_BACKLOG_BYTES = 64 * 1024
"""Most log output held back while the log's reader does not take it; a line that would
pass it is dropped whole and counted (:func:`lost_lines`)."""

LOG_EXIT_FLUSH_S = 1.0
"""How long the daemon's last lines may wait for a slow reader when it exits."""


def lost_lines() -> int:
    """Log lines this process could not write (the stream failed, or its reader did not
    take them)."""
    return _lost


class LogStream:
    """Log lines to a stream without ever blocking on its reader.

    A pipe, FIFO or terminal is written through a non-blocking descriptor of its own
    (the stream's reopened through ``/proc/self/fd``, so the flags of a descriptor
    shared with a shell or a supervisor are untouched); a socket (journald's stream),
    or a pipe that cannot be reopened, through the stream's descriptor whenever it polls
    writable. Each write is whole lines of at most ``PIPE_BUF`` bytes (a pipe takes such
    a write whole or not at all; a longer line goes in ``PIPE_BUF`` pieces). What the
    reader does not take waits in a backlog of at most :data:`LOG_BACKLOG_BYTES`; a line
    that would pass it is dropped. A regular file or
    a stream without a descriptor is written as it is (a disk does not wait for a
    reader; a full one fails, and the line is counted lost).
    """

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.pending = bytearray()
        self._lock = threading.Lock()
        self.fd = -1
        self._own = False
        self._ready: select.poll | None = None
        try:
            fd = stream.fileno()
            mode = os.fstat(fd).st_mode
        except (OSError, ValueError, AttributeError):  # in memory
            return
        if stat.S_ISREG(mode) or not (
            stat.S_ISFIFO(mode) or stat.S_ISCHR(mode) or stat.S_ISSOCK(mode)
        ):
            return
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
        if not stat.S_ISSOCK(mode):
            with contextlib.suppress(OSError):
                flags = os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC
                self.fd, self._own = os.open(f"/proc/self/fd/{fd}", flags), True
                return
        self.fd = fd
        self._ready = select.poll()
        self._ready.register(fd, select.POLLOUT)

    def write(self, line: str) -> None:
        """Write one line (its newline included), or hold it, or drop it (counted)."""
        global _lost
        if self.fd < 0:
            try:
                self.stream.write(line)
                self.stream.flush()
            except (OSError, ValueError):  # EPIPE, EIO, ENOSPC; ValueError: the stream closed
                _lost += 1
            return
        data = line.encode("utf-8", "replace")
        with self._lock:
            self._flush()
            if len(self.pending) + len(data) > LOG_BACKLOG_BYTES:
                _lost += 1
                return
            self.pending += data
            self._flush()

    def flush(self, timeout_s: float = 0.0) -> None:
        """Write what is held back, waiting up to ``timeout_s`` for the reader."""
        end = time.monotonic() + timeout_s
        with self._lock:
            self._flush()
            while self.pending and self.fd >= 0 and (left := end - time.monotonic()) > 0:
                with contextlib.suppress(OSError):
                    select.select([], [self.fd], [], left)
                self._flush()

    def _flush(self) -> None:
        global _lost
        while self.pending:
            if self._ready is not None and not self._ready.poll(0):
                return
            # whole lines of at most PIPE_BUF bytes: a pipe takes them whole or not at all
            end = self.pending.rfind(b"\n", 0, select.PIPE_BUF) + 1 or select.PIPE_BUF
            try:
                n = os.write(self.fd, self.pending[:end])
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # the reader is gone: what is held is lost
                _lost += max(self.pending.count(b"\n"), 1)
                self.pending.clear()
                return
            del self.pending[:n]

    def close(self) -> None:
        """Release the descriptor of its own (what is held is dropped)."""
        if self._own and self.fd >= 0:
            os.close(self.fd)
        self.fd = -1


_stream: LogStream | None = None


def flush_log(timeout_s: float = LOG_EXIT_FLUSH_S) -> None:
    """Write the log lines held back, waiting up to ``timeout_s`` for the reader (at
    exit); the lines still held then are counted lost."""
    global _lost
    if _stream is not None:
        _stream.flush(timeout_s)
        if timeout_s > 0 and _stream.pending:
            _lost += max(_stream.pending.count(b"\n"), 1)
            _stream.pending.clear()


class SafePrintLogger(structlog.PrintLogger):
    """A :class:`structlog.PrintLogger` whose writes go through a :class:`LogStream`:
    never raise, never block."""

    def __init__(self, out: LogStream) -> None:
        super().__init__(out.stream)
        self._out = out

    def msg(self, message: str) -> None:
        self._out.write(message + "\n")

    log = debug = info = warn = warning = msg
    fatal = failure = err = error = critical = exception = msg


class SafePrintLoggerFactory:
    """Makes :class:`SafePrintLogger` instances on one stream."""

    def __init__(self, out: LogStream) -> None:
        self._out = out

    def __call__(self, *args: object) -> SafePrintLogger:
        return SafePrintLogger(self._out)


def is_console() -> bool:
    """Events are rendered for a person (a terminal): keep periodic ones to one line."""
    return _console


def configure_logging(
    fmt: LogFormat = "auto", level: str = "info", stream: TextIO | None = None
) -> None:
    """Configure structlog for the process.

    Args:
        fmt: ``"json"``, ``"console"``, or ``"auto"`` (console on a terminal, else JSON).
        level: ``debug``, ``info``, ``warning`` or ``error``.
        stream: where events go (default stdout, as a systemd service expects).

    Raises:
        ValueError: unknown format or level.
    """
    if fmt not in ("auto", "json", "console"):
        raise ValueError(f"log format must be auto, json or console, not {fmt!r}")
    if level not in _LEVELS:
        raise ValueError(f"log level must be one of {', '.join(_LEVELS)}, not {level!r}")
    out = stream if stream is not None else sys.stdout
    console = fmt == "console" or (fmt == "auto" and out.isatty())
    global _console, _stream
    _console = console
    if _stream is not None:
        _stream.close()
    _stream = LogStream(out)
    renderer: structlog.typing.Processor = (
        structlog.dev.ConsoleRenderer(colors=out.isatty())
        if console
        else structlog.processors.JSONRenderer()
    )
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.format_exc_info,
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(_LEVELS[level]),
        logger_factory=SafePrintLoggerFactory(_stream),
        cache_logger_on_first_use=False,
    )


_follows: tuple[LogFormat, str, bool] | None = None
"""The settings the daemon's log was configured from (:func:`configure_daemon_logging`),
which a reload follows; None when the process configured its log otherwise."""


def configure_daemon_logging(fmt: LogFormat, level: str, nmea_on_stdout: bool) -> None:
    """The daemon's log (:func:`configure_logging`): on stdout, or on stderr when the
    corrected NMEA goes to stdout (``outputs.stdout``): the two never share it."""
    global _follows
    configure_logging(fmt, level, sys.stderr if nmea_on_stdout else None)
    _follows = (fmt, level, nmea_on_stdout)


def follow_config(fmt: LogFormat, level: str, nmea_on_stdout: bool) -> bool:
    """At a reload, before the outputs are opened: the daemon's log configured again when
    these settings changed (True); a log configured otherwise is left as it is. Kept
    from the start, the log went on writing to stdout between the NMEA of an
    ``outputs.stdout`` a reload turned on."""
    if _follows is None or _follows == (fmt, level, nmea_on_stdout):
        return False
    flush_log(0.0)
    configure_daemon_logging(fmt, level, nmea_on_stdout)
    return True


REPEATING_EVENTS = frozenset(
    {"reference", "stale", "alive", "state", "lag_retry", "identifiability", "gnss_repeated"}
)
"""Events a flapping input repeats (bottom lock coming and going): logged at most once
per :data:`EVENT_INTERVAL_S` per port, the next line saying how many were left out."""

EVENT_INTERVAL_S = 10.0
"""The least time between two lines of one repeating event of one port, s."""


CLIENT_EVENTS = frozenset(
    {
        "client_connected",
        "client_disconnected",
        "client_evicted",
        "client_sent_data",
        "client_stalled",
        "client_throttled",
        "client_too_slow",
    }
)
"""What a TCP output logs of its clients, each line with the peer's address: a client
connecting and closing in a loop would repeat them without end (and a journal that
rate-limits the service would then drop the daemon's other lines too)."""

CLIENT_EVENT_BURST = 20
"""Most lines of one client event of one TCP output per :data:`EVENT_INTERVAL_S`."""


class EventLimiter:
    """At most ``burst`` log lines per (port, kind) of ``kinds`` per interval.

    Args:
        interval_s: the interval.
        kinds: the events limited (others always pass).
        burst: lines let through per interval and key.
    """

    def __init__(
        self,
        interval_s: float = EVENT_INTERVAL_S,
        kinds: frozenset[str] = REPEATING_EVENTS,
        burst: int = 1,
    ) -> None:
        self.interval_s = interval_s
        self.kinds = kinds
        self.burst = burst
        self.window: dict[tuple[str, str], tuple[float, int]] = {}
        """Per key: when its interval began, and the lines let through in it."""
        self.dropped: dict[tuple[str, str], int] = {}

    def allow(self, port: str, kind: str, now: float) -> int | None:
        """None: leave this one out; else log it, with how many were left out before."""
        if kind not in self.kinds:
            return 0
        key = (port, kind)
        start, n = self.window.get(key, (-math.inf, 0))
        if now - start >= self.interval_s:
            start, n = now, 0
        if n >= self.burst:
            self.dropped[key] = self.dropped.get(key, 0) + 1
            return None
        self.window[key] = (start, n + 1)
        return self.dropped.pop(key, 0)


CONTROL_EVENTS = frozenset({"control_freeze", "control_learn", "control_reset"})
"""What the daemon logs of the operators' commands: a client sending thousands a second
would write a line each (and a journal that rate-limits the service would then drop
the daemon's other lines too)."""

CONTROL_EVENT_BURST = 20
"""Most lines of one operators' command per :data:`EVENT_INTERVAL_S`, the next line
after the interval saying how many were left out (``suppressed``)."""


class ControlLog:
    """The log of the operators' commands (:data:`CONTROL_EVENTS`): at most
    :data:`CONTROL_EVENT_BURST` lines of each per :data:`EVENT_INTERVAL_S`, the first
    line after saying how many were left out (``suppressed``).

    Args:
        log: a structlog-style logger.
        monotonic: the clock, s.
    """

    def __init__(self, log: Any, monotonic: Callable[[], float]) -> None:
        self.log = log
        self.monotonic = monotonic
        self.limiter = EventLimiter(kinds=CONTROL_EVENTS, burst=CONTROL_EVENT_BURST)

    def info(self, kind: str, **kw: Any) -> None:
        """Log ``kind`` at info level, if its lines are not too many."""
        self._emit(self.log.info, kind, kw)

    def warning(self, kind: str, **kw: Any) -> None:
        """Log ``kind`` at warning level, if its lines are not too many."""
        self._emit(self.log.warning, kind, kw)

    def _emit(self, emit: Callable[..., Any], kind: str, kw: dict[str, Any]) -> None:
        suppressed = self.limiter.allow("control", kind, self.monotonic())
        if suppressed is not None:
            emit(kind, **kw, **({"suppressed": suppressed} if suppressed else {}))


STATUS_LOG_MAX_ITEMS = 12
"""The most UUTs, ports, sources and sinks the periodic status line of the log names,
each section's first in config order; how many more each section holds is its line's
``left_out`` (``emlogd status`` has them all). About 2 KB a UUT: with 1000 UUTs the line
was 2.2 MB, past :data:`LOG_BACKLOG_BYTES` into a pipe (dropped whole every time) and
journald's line limit (48 KiB)."""


def capped_sections(sections: dict[str, Any], limit: int = STATUS_LOG_MAX_ITEMS) -> dict[str, Any]:
    """``sections`` with each dict among them cut to its first ``limit`` entries and
    ``left_out`` counting, per section cut, the entries left out."""
    out: dict[str, Any] = {}
    left: dict[str, int] = {}
    for key, value in sections.items():
        if isinstance(value, dict) and len(value) > limit:
            out[key] = dict(list(value.items())[:limit])
            left[key] = len(value) - limit
        else:
            out[key] = value
    if left:
        out["left_out"] = left
    return out


def status_line(status: dict[str, object]) -> dict[str, Any]:
    """Each UUT's state and calibration, each port's record count, in a few words (at
    most :data:`STATUS_LOG_MAX_ITEMS` of each, ``left_out`` counting the rest)."""
    out: dict[str, Any] = {}
    capped = capped_sections({"uuts": status.get("uuts"), "ports": status.get("ports")})
    uuts = capped["uuts"]
    if isinstance(uuts, dict):
        for name, u in uuts.items():
            params = u.get("params") or {}
            cal = " ".join(f"{k}={v:+.3f}" for k, v in params.items()) or "raw"
            out[name] = f"{u.get('state')} {cal} ref {u.get('reference')}"
    ports = capped["ports"]
    if isinstance(ports, dict):
        out["records"] = " ".join(f"{n}={p.get('records')}" for n, p in ports.items())
    if "left_out" in capped:
        out["left_out"] = capped["left_out"]
    return out
