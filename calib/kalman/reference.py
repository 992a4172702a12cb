"""The numpy reference Kalman filter: readable, exact, the oracle of the fast path.

:class:`KalmanModel` (F, H, Q, R), :class:`State` (x, P) and the pure steps
:func:`predict` (the paper's eqs. (5)–(6)) and :func:`update` (eqs. (7)–(8) with the
Joseph-form covariance, innovation eqs. (29)–(31)). Offline code and tests use it;
the per-sample filter of :mod:`calib.kalman.filters` is tested against it.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from calib.errors import ModelError
from calib.models import FloatArray


def _as_matrix(name: str, value: npt.ArrayLike, shape: tuple[int, int]) -> FloatArray:
    """A read-only float64 copy of ``value`` with the given shape, or ModelError."""
    arr = np.array(value, dtype=np.float64, ndmin=2)
    if arr.shape != shape:
        raise ModelError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{name} has non-finite entries")
    arr.setflags(write=False)
    return arr


def _check_covariance(name: str, M: FloatArray, *, definite: bool) -> None:
    """Raise ModelError unless M is symmetric and positive (semi-)definite."""
    scale = max(float(np.max(np.abs(M))), 1e-300)
    if not np.allclose(M, M.T, rtol=0.0, atol=1e-12 * scale):
        raise ModelError(f"{name} is not symmetric")
    eig = np.linalg.eigvalsh(M)
    tol = 1e-12 * scale
    if definite and not float(eig[0]) > 0.0:
        raise ModelError(f"{name} is not positive definite (smallest eigenvalue {eig[0]:.3g})")
    if float(eig[0]) < -tol:
        raise ModelError(f"{name} is not positive semi-definite (smallest eigenvalue {eig[0]:.3g})")


@dataclass(frozen=True, eq=False)
class KalmanModel:
    """A linear Gaussian model with a scalar measurement (filterpy's textbook names).

    A vector measurement with uncorrelated noise is processed as a sequence of
    scalar updates (one :func:`update` per component), which is exact.

    Attributes:
        F: state transition Φ, shape (n, n) (eq. (3)).
        H: measurement row, shape (1, n) (eq. (4)); time-varying (pseudo-linear)
            rows are passed to :func:`update` directly.
        Q: process-noise covariance, shape (n, n), symmetric PSD, state units².
        R: measurement-noise variance, shape (1, 1), positive, measurement units².

    Raises:
        ModelError: wrong shape, non-finite, non-symmetric or not (semi-)definite.
    """

    F: FloatArray
    H: FloatArray
    Q: FloatArray
    R: FloatArray

    def __post_init__(self) -> None:
        F = np.array(self.F, dtype=np.float64, ndmin=2)
        n = F.shape[0]
        object.__setattr__(self, "F", _as_matrix("F", F, (n, n)))
        object.__setattr__(self, "H", _as_matrix("H", self.H, (1, n)))
        object.__setattr__(self, "Q", _as_matrix("Q", self.Q, (n, n)))
        object.__setattr__(self, "R", _as_matrix("R", self.R, (1, 1)))
        _check_covariance("Q", self.Q, definite=False)
        if not float(self.R[0, 0]) > 0.0:
            raise ModelError(f"R must be positive, got {float(self.R[0, 0])!r}")

    @classmethod
    def of(
        cls, F: npt.ArrayLike, H: npt.ArrayLike, Q: npt.ArrayLike, R: npt.ArrayLike
    ) -> KalmanModel:
        """Build a model from array-likes (nested lists, scalars for 1×1), validated.

        Raises:
            ModelError: as the constructor.
        """
        return cls(
            np.array(F, dtype=np.float64, ndmin=2),
            np.array(H, dtype=np.float64, ndmin=2),
            np.array(Q, dtype=np.float64, ndmin=2),
            np.array(R, dtype=np.float64, ndmin=2),
        )

    @property
    def n(self) -> int:
        """Number of states."""
        return int(self.F.shape[0])


class State(NamedTuple):
    """A Gaussian state estimate.

    Attributes:
        x: state mean, shape (n,).
        P: state covariance, shape (n, n), symmetric positive definite.
    """

    x: FloatArray
    P: FloatArray


class Innovation(NamedTuple):
    """The innovation of one scalar update (eqs. (29)–(31)).

    Attributes:
        y: innovation ``z − H·x⁻`` in measurement units (m/s).
        S: innovation variance ``H·P⁻·Hᵀ + R`` in measurement units² (m²/s²).
        nis: normalised innovation squared ``y²/S`` (dimensionless, χ²(1) if consistent).
    """

    y: float
    S: float
    nis: float


def make_state(x: npt.ArrayLike, P: npt.ArrayLike) -> State:
    """Build and validate a :class:`State`.

    Args:
        x: mean, shape (n,).
        P: covariance, shape (n, n), symmetric positive definite.

    Returns:
        The state as float64 arrays.

    Raises:
        ModelError: wrong shapes or a covariance that is not SPD.
    """
    xa = np.array(x, dtype=np.float64).reshape(-1)
    Pa = np.array(P, dtype=np.float64, ndmin=2)
    if Pa.shape != (xa.size, xa.size):
        raise ModelError(f"P must have shape ({xa.size}, {xa.size}), got {Pa.shape}")
    _check_covariance("P", Pa, definite=True)
    return State(xa, Pa)


def predict(state: State, model: KalmanModel) -> State:
    """Time update (eqs. (5)–(6)): ``x⁻ = Φx``, ``P⁻ = ΦPΦᵀ + Q``.

    Args:
        state: the a-posteriori state at k−1.
        model: the model (F, Q used).

    Returns:
        The a-priori state at k.
    """
    x = model.F @ state.x
    P = model.F @ state.P @ model.F.T + model.Q
    return State(x, 0.5 * (P + P.T))


def update(
    state: State,
    z: float | None,
    model: KalmanModel,
    *,
    H: npt.ArrayLike | None = None,
    free: Sequence[bool] | None = None,
) -> tuple[State, Innovation | None]:
    """Measurement update (eqs. (7)–(8)) with the Joseph-form covariance.

    ``K = P⁻Hᵀ/S``, ``x = x⁻ + K·y``, ``P = (I − KH)P⁻(I − KH)ᵀ + K·R·Kᵀ``. The Joseph
    form is valid for any gain, which the ``free`` option relies on.

    Args:
        state: the a-priori state.
        z: the scalar measurement, or None for no measurement (state returned as is).
        model: the model (H, R used).
        H: optional measurement row for this step, shape (n,) or (1, n), overriding
            ``model.H`` (pseudo-linear models whose H changes every sample).
        free: optional mask, shape (n,): states marked False get zero gain (held
            fixed, "consider" states, e.g. frozen calibration parameters).

    Returns:
        ``(state, innovation)``; the innovation is None when ``z`` is None.

    Raises:
        ModelError: H or free of the wrong length.
    """
    if z is None:
        return state, None
    n = state.x.size
    h = model.H[0] if H is None else np.asarray(H, dtype=np.float64).reshape(-1)
    if h.size != n:
        raise ModelError(f"H must have {n} entries, got {h.size}")
    r = float(model.R[0, 0])
    u = state.P @ h
    S = float(h @ u) + r
    y = float(z) - float(h @ state.x)
    K = u / S
    if free is not None:
        mask = np.asarray(free, dtype=bool)
        if mask.shape != (n,):
            raise ModelError(f"free must have {n} entries, got {mask.shape}")
        K = np.where(mask, K, 0.0)
    x = state.x + K * y
    A = np.eye(n) - np.outer(K, h)
    P = A @ state.P @ A.T + r * np.outer(K, K)
    return State(x, 0.5 * (P + P.T)), Innovation(y, S, y * y / S)
