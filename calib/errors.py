"""Errors raised by the calibration mathematics.

``calib`` must not import ``drivers`` or ``emlogd``, so it has its own small
hierarchy rooted in :class:`CalibrationError` (a :class:`ValueError`: every one of
them is a bad argument or bad data handed to a pure function). The application
translates them into its own ``EmlogdError`` family at its boundary.

Must not import: drivers, emlogd, or any I/O module.
"""

from __future__ import annotations


class CalibrationError(ValueError):
    """Root of every error ``calib`` raises on purpose."""


class ModelError(CalibrationError):
    """An unknown model or estimator name, or a malformed model/filter specification.

    Raised, for example, by :class:`calib.kalman.KalmanModel` when a matrix has the
    wrong shape, is not symmetric or is not positive semi-definite.
    """


class DataError(CalibrationError):
    """Input series that cannot be used: wrong shape, mismatched lengths, not finite,
    too short, or time stamps that do not increase."""
