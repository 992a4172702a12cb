"""The error hierarchy shared by drivers and the application (docs/ARCHITECTURE.md, "Records and errors").

Every error emlogd raises on purpose derives from :class:`EmlogdError`, so one
``except EmlogdError`` at the CLI boundary turns them into a one-line message.
pyserial exceptions are translated into :class:`DeviceError` in ``drivers.io.port``.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from typing import Literal, get_args

RejectReason = Literal[
    "checksum",
    "missing_checksum",
    "framing",
    "too_long",
    "unknown_sentence",
    "bad_field",
    "out_of_range",
    "internal",
]
"""Why a frame was rejected. Every rejection increments exactly one counter.

``internal``: handling the frame failed in a way no check foresaw (an exception that is
no :class:`FrameError`, in the decoder or in the pipeline after it): the frame is
dropped, counted and logged, and the run goes on."""

REJECT_REASONS: tuple[RejectReason, ...] = get_args(RejectReason)
"""Every :data:`RejectReason`, in its order (one counter each)."""


class EmlogdError(Exception):
    """Root of every error emlogd raises on purpose."""


class FrameError(EmlogdError):
    """A frame (line, ensemble, binary packet) could not be decoded.

    Args:
        message: what is wrong, for a human.
        raw: the offending bytes (possibly truncated to a sensible length).
        offset: byte offset of the problem inside ``raw`` (0 if unknown).
        reason: the reject counter this error increments.
    """

    reason: RejectReason = "framing"

    def __init__(
        self,
        message: str,
        raw: bytes = b"",
        offset: int = 0,
        reason: RejectReason | None = None,
    ) -> None:
        super().__init__(message)
        self.raw = raw[:256]
        self.offset = offset
        if reason is not None:
            self.reason = reason


class ChecksumError(FrameError):
    """The frame's checksum does not match its content."""

    reason: RejectReason = "checksum"


class MissingChecksumError(ChecksumError):
    """The frame has no checksum and the port requires one."""

    reason: RejectReason = "missing_checksum"


class TooLongError(FrameError):
    """The frame exceeds the configured length limit."""

    reason: RejectReason = "too_long"


class UnknownSentenceError(FrameError):
    """The frame is well formed but of a type this decoder does not know."""

    reason: RejectReason = "unknown_sentence"


class FieldError(FrameError):
    """A field is missing, not a number, or has the wrong shape."""

    reason: RejectReason = "bad_field"


class OutOfRangeError(FieldError):
    """A field parsed but its value is physically impossible."""

    reason: RejectReason = "out_of_range"


class UnknownProtocolError(EmlogdError, ValueError):
    """A protocol name that is not in ``drivers.PROTOCOLS``."""


class CaptureFormatError(EmlogdError, ValueError):
    """A capture file is malformed; the message names the file and the line.

    Args:
        path: the capture file.
        line: 1-based line number of the problem.
        message: what is wrong.
    """

    def __init__(self, path: str, line: int, message: str) -> None:
        super().__init__(f"{path}:{line}: {message}")
        self.path = path
        self.line = line
        self.message = message

    def __reduce__(self) -> tuple[type[CaptureFormatError], tuple[str, int, str]]:
        """Rebuilt from its three arguments: a capture read in a worker process (the
        offline commands' pool) raises it in the parent as it is."""
        return type(self), (self.path, self.line, self.message)


class DeviceError(EmlogdError):
    """A serial device or pty could not be opened, read or written."""


class ConfigError(EmlogdError, ValueError):
    """A configuration value is missing, unknown, of the wrong type, or out of range."""
