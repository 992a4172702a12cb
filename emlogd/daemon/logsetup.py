"""structlog configuration: JSON lines when the stream is not a terminal, console otherwise;
the daemon's limit on repeated events and its one-line status for a terminal.

Library modules only call ``structlog.get_logger(__name__)``; the CLI calls
:func:`configure_logging` once. The stdlib root logger is never configured.

Writing a log line never raises: a stream whose reader went away (a pipe closed,
journald stopped: ``EPIPE``) or that fails otherwise costs that line, counted by
:func:`lost_lines`, never the daemon (a ``BrokenPipeError`` out of a log call ended
``emlogd run`` with exit code 0, which systemd's ``Restart=on-failure`` does not restart).
"""

from __future__ import annotations

import logging
import math
import sys
from typing import Literal, TextIO

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


def lost_lines() -> int:
    """Log lines this process could not write (the stream failed)."""
    return _lost


class SafePrintLogger(structlog.PrintLogger):
    """A :class:`structlog.PrintLogger` whose writes never raise: a failed write is
    counted (:func:`lost_lines`) and the line dropped."""

    def msg(self, message: str) -> None:
        global _lost
        try:
            super().msg(message)
        except (OSError, ValueError):  # EPIPE, EIO, ENOSPC; ValueError: the stream closed
            _lost += 1

    log = debug = info = warn = warning = msg
    fatal = failure = err = error = critical = exception = msg


class SafePrintLoggerFactory:
    """Makes :class:`SafePrintLogger` instances on one stream."""

    def __init__(self, file: TextIO) -> None:
        self._file = file

    def __call__(self, *args: object) -> SafePrintLogger:
        return SafePrintLogger(self._file)


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
    global _console
    _console = console
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
        logger_factory=SafePrintLoggerFactory(out),
        cache_logger_on_first_use=False,
    )


REPEATING_EVENTS = frozenset(
    {"reference", "stale", "alive", "state", "lag_retry", "identifiability"}
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


def status_line(status: dict[str, object]) -> dict[str, str]:
    """Each UUT's state and calibration, each port's record count, in a few words."""
    out: dict[str, str] = {}
    uuts = status.get("uuts")
    if isinstance(uuts, dict):
        for name, u in uuts.items():
            params = u.get("params") or {}
            cal = " ".join(f"{k}={v:+.3f}" for k, v in params.items()) or "raw"
            out[name] = f"{u.get('state')} {cal} ref {u.get('reference')}"
    ports = status.get("ports")
    if isinstance(ports, dict):
        out["records"] = " ".join(f"{n}={p.get('records')}" for n, p in ports.items())
    return out
