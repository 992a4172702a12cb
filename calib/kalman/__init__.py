"""Kalman filters KF-EM1..KF-EM4 (paper sections II-B and III-C-2), with optional current.

- :mod:`calib.kalman.reference`: the numpy textbook filter (the oracle);
- :mod:`calib.kalman.kernels`: the per-sample scalar update over plain floats, the
  Gaussian conditional on a known state, the covariance check;
- :mod:`calib.kalman.filters`: :class:`KfCalibrator`, the online filter the daemon runs;
- :mod:`calib.kalman.batch`: :func:`run_kf` over recorded arrays (offline commands).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from calib.kalman.batch import KfRun, run_kf
from calib.kalman.filters import (
    DEFAULT_R_RAW_MPS2,
    DEFAULT_R_REF_MPS2,
    KfCalibrator,
    KfConfig,
    StepResult,
)
from calib.kalman.kernels import P_FLOOR, check_covariance, scalar_update
from calib.kalman.reference import Innovation, KalmanModel, State, make_state, predict, update

__all__ = [
    "DEFAULT_R_RAW_MPS2",
    "DEFAULT_R_REF_MPS2",
    "P_FLOOR",
    "Innovation",
    "KalmanModel",
    "KfCalibrator",
    "KfConfig",
    "KfRun",
    "State",
    "StepResult",
    "check_covariance",
    "make_state",
    "predict",
    "run_kf",
    "scalar_update",
    "update",
]
