"""structlog configuration: JSON lines when the stream is not a terminal, console otherwise.

Library modules only call ``structlog.get_logger(__name__)``; the CLI calls
:func:`configure_logging` once. The stdlib root logger is never configured.
"""

from __future__ import annotations

import logging
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
        logger_factory=structlog.PrintLoggerFactory(out),
        cache_logger_on_first_use=False,
    )
