"""The error hierarchy (docs/ARCHITECTURE.md, "Records and errors")."""

from __future__ import annotations

import pytest

from drivers import errors

FRAME_ERRORS: tuple[type[errors.FrameError], ...] = (
    errors.FrameError,
    errors.ChecksumError,
    errors.MissingChecksumError,
    errors.TooLongError,
    errors.UnknownSentenceError,
    errors.FieldError,
    errors.OutOfRangeError,
)
"""The frame error classes (each names a reject reason)."""


class TestHierarchy:
    """Every public error is an EmlogdError with the documented extra bases."""

    @pytest.mark.parametrize(
        "cls", [*FRAME_ERRORS, errors.UnknownProtocolError, errors.DeviceError, errors.ConfigError]
    )
    def test_catching_emlogd_error_covers_it(self, cls: type[Exception]) -> None:
        """``except EmlogdError`` catches every public error class."""
        assert issubclass(cls, errors.EmlogdError)

    def test_dual_inheritance(self) -> None:
        """Config and capture-format errors are ValueErrors."""
        assert issubclass(errors.ConfigError, ValueError)
        assert issubclass(errors.CaptureFormatError, ValueError)

    def test_reasons_map_to_counters(self) -> None:
        """Each frame error class names one of the documented reject reasons."""
        for cls in FRAME_ERRORS:
            assert cls("x").reason in errors.REJECT_REASONS

    def test_capture_error_names_file_and_line(self) -> None:
        """A capture format error's message starts with file:line."""
        exc = errors.CaptureFormatError("a.cap", 12, "bad time")
        assert str(exc) == "a.cap:12: bad time"
        assert (exc.path, exc.line) == ("a.cap", 12)

    def test_raw_is_truncated(self) -> None:
        """A frame error keeps at most 256 bytes of the offending input."""
        assert len(errors.FrameError("x", b"a" * 1000).raw) == 256
