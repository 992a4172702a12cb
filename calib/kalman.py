"""Kalman filters KF-EM1..KF-EM4 (paper sections II-B and III-C-2), two implementations.

1. **The reference implementation**, numpy, readable, for batch/offline work and
   as the oracle the fast path is tested against: :class:`KalmanModel` (F, H, Q, R),
   :class:`State` (x, P) and the pure steps :func:`predict` (eqs. (5)–(6)) and
   :func:`update` (eqs. (7)–(8), Joseph-form covariance, innovation eqs. (29)–(31)).

2. **The fast per-sample path** over plain Python floats that the daemon runs
   (a numpy step costs ~30 µs per sample here; a KF-EM3 sample ~1.5 µs): unrolled
   scalar-measurement updates for 1–4 states (:data:`KERNELS`), a generic loop
   for more, and fused predict+reference+raw steps (:data:`FUSED_STEPS`) for the
   common case, used by :class:`KfCalibrator` (state ``[v, θ]``) and
   :class:`RlsCalibrator` (state θ). Fixed memory: the state lives in two lists
   of floats (x and the upper triangle of P) that are updated in place.

The paper's KF-EMx (eqs. (22)–(24), extended to EM4)::

    x = [v, θ]            θ = [b] | [m] | [m, b] | [a, m, b]
    Φ = I                  P0 = 0.25·I, x0 = [v0, 0…0] (ideal sensor)
    raw = H_k·x + η        H_k = [1, h(v_ref,k)] = [1, 1] | [1, v] | [1, v, 1] | [1, v², v, 1]

``h`` is the design row of :mod:`calib.models`: the pseudo-linear operating point is
the reference speed, so the filter stays linear. Beyond the paper:

- The reference (DVL) is a second scalar measurement ``ref = v + ε`` (H = [1, 0…])
  that updates the speed state; measurements are processed sequentially,
  reference first, then raw. The innovation returned (and its NIS) is the raw
  one, against the state already updated with the simultaneous reference, so it
  measures the calibration model rather than the speed dynamics.
- Speed process noise: v is a random walk driven by acceleration white noise of
  spectral density ``accel_psd_m2ps3`` ((m/s²)²/Hz), ``q_v = accel_psd·dt``, so v
  follows a manoeuvring vessel. Parameter process noise is the paper's
  ``1e-7`` per step (random-walk parameters, "to prevent covariance collapse").
- **Reference outage** (``ref is None``): predict, then the raw reading updates
  the speed state only, parameters frozen (a Schmidt "consider" update: zero gain
  on θ, the Joseph form keeping P exact for that sub-optimal gain). The
  pseudo-linear operating point is then the *corrected raw reading* (inverse
  model with the frozen θ), not the state speed: with that choice the raw
  innovation is exactly ``corrected(raw) − v̂`` for every model, including EM4,
  and does not lag behind a manoeuvre like the predicted state would.

The parameter-only form (:class:`RlsCalibrator`) has state θ, measurement
``z = raw − ref`` and ``H = h(v_ref)``: recursive least squares with random-walk
parameters. With Q = 0 it reproduces batch least squares (:func:`calib.lsq.fit_ls`).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from calib.errors import DataError, ModelError
from calib.models import (
    PARAM_NAMES,
    FloatArray,
    ModelName,
    ParamName,
    Params,
    check_model,
    design_row,
    invert,
)

# ---------------------------------------------------------------------------
# The numpy reference implementation
# ---------------------------------------------------------------------------


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


_INF = math.inf

_new_innovation = tuple.__new__
"""``_new_innovation(Innovation, (y, S, nis))`` builds an Innovation without the
Python-level ``__new__`` of NamedTuple (a third of the cost, on the per-sample path)."""


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


# ---------------------------------------------------------------------------
# The fast path: scalar-measurement kernels over plain floats
# ---------------------------------------------------------------------------
#
# Every kernel has the signature
#     kernel(x, P, h, z, r, n_free) -> (y, S)
# x: list of n floats (mean), P: list of n(n+1)/2 floats (upper triangle of the
# covariance, row by row), h: n floats (measurement row), z: measurement, r: its
# variance, n_free: the first n_free states get gain, the others are held
# (consider states). Both lists are updated in place. The covariance update is
# the Joseph form expanded for a rank-one H:
#     (I − KH)P(I − KH)ᵀ + K r Kᵀ = P − K uᵀ − u Kᵀ + S K Kᵀ,   u = P hᵀ, S = h u + r,
# exact for any gain K, symmetric by construction (only one triangle is stored);
# diagonal entries are floored at P_FLOOR to keep P positive under rounding.

P_FLOOR = 1e-30
"""Smallest variance a diagonal element of P may take in the fast path."""

Kernel = Callable[
    [list[float], list[float], Sequence[float], float, float, int], tuple[float, float]
]


def _update1(
    x: list[float], P: list[float], h: Sequence[float], z: float, r: float, n_free: int
) -> tuple[float, float]:
    """Scalar update of a 1-state filter (see the kernel contract above)."""
    (h0,) = h
    p00 = P[0]
    u0 = p00 * h0
    s = h0 * u0 + r
    y = z - h0 * x[0]
    k0 = u0 / s
    x[0] += k0 * y
    d = p00 - k0 * u0
    P[0] = d if d > P_FLOOR else P_FLOOR
    return y, s


def _update2(
    x: list[float], P: list[float], h: Sequence[float], z: float, r: float, n_free: int
) -> tuple[float, float]:
    """Scalar update of a 2-state filter (see the kernel contract above)."""
    h0, h1 = h
    p00, p01, p11 = P
    u0 = p00 * h0 + p01 * h1
    u1 = p01 * h0 + p11 * h1
    s = h0 * u0 + h1 * u1 + r
    y = z - (h0 * x[0] + h1 * x[1])
    k0 = u0 / s
    k1 = u1 / s if n_free > 1 else 0.0
    x[0] += k0 * y
    x[1] += k1 * y
    d0 = p00 - 2.0 * k0 * u0 + s * k0 * k0
    d1 = p11 - 2.0 * k1 * u1 + s * k1 * k1
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - u0 * k1 + s * k0 * k1
    P[2] = d1 if d1 > P_FLOOR else P_FLOOR
    return y, s


def _update3(
    x: list[float], P: list[float], h: Sequence[float], z: float, r: float, n_free: int
) -> tuple[float, float]:
    """Scalar update of a 3-state filter (see the kernel contract above)."""
    h0, h1, h2 = h
    p00, p01, p02, p11, p12, p22 = P
    u0 = p00 * h0 + p01 * h1 + p02 * h2
    u1 = p01 * h0 + p11 * h1 + p12 * h2
    u2 = p02 * h0 + p12 * h1 + p22 * h2
    s = h0 * u0 + h1 * u1 + h2 * u2 + r
    y = z - (h0 * x[0] + h1 * x[1] + h2 * x[2])
    k0 = u0 / s
    if n_free > 1:
        k1 = u1 / s
        k2 = u2 / s if n_free > 2 else 0.0
    else:
        k1 = k2 = 0.0
    x[0] += k0 * y
    x[1] += k1 * y
    x[2] += k2 * y
    d0 = p00 - 2.0 * k0 * u0 + s * k0 * k0
    d1 = p11 - 2.0 * k1 * u1 + s * k1 * k1
    d2 = p22 - 2.0 * k2 * u2 + s * k2 * k2
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - u0 * k1 + s * k0 * k1
    P[2] = p02 - k0 * u2 - u0 * k2 + s * k0 * k2
    P[3] = d1 if d1 > P_FLOOR else P_FLOOR
    P[4] = p12 - k1 * u2 - u1 * k2 + s * k1 * k2
    P[5] = d2 if d2 > P_FLOOR else P_FLOOR
    return y, s


def _update4(
    x: list[float], P: list[float], h: Sequence[float], z: float, r: float, n_free: int
) -> tuple[float, float]:
    """Scalar update of a 4-state filter (see the kernel contract above)."""
    h0, h1, h2, h3 = h
    p00, p01, p02, p03, p11, p12, p13, p22, p23, p33 = P
    u0 = p00 * h0 + p01 * h1 + p02 * h2 + p03 * h3
    u1 = p01 * h0 + p11 * h1 + p12 * h2 + p13 * h3
    u2 = p02 * h0 + p12 * h1 + p22 * h2 + p23 * h3
    u3 = p03 * h0 + p13 * h1 + p23 * h2 + p33 * h3
    s = h0 * u0 + h1 * u1 + h2 * u2 + h3 * u3 + r
    y = z - (h0 * x[0] + h1 * x[1] + h2 * x[2] + h3 * x[3])
    k0 = u0 / s
    k1 = u1 / s if n_free > 1 else 0.0
    k2 = u2 / s if n_free > 2 else 0.0
    k3 = u3 / s if n_free > 3 else 0.0
    x[0] += k0 * y
    x[1] += k1 * y
    x[2] += k2 * y
    x[3] += k3 * y
    d0 = p00 - 2.0 * k0 * u0 + s * k0 * k0
    d1 = p11 - 2.0 * k1 * u1 + s * k1 * k1
    d2 = p22 - 2.0 * k2 * u2 + s * k2 * k2
    d3 = p33 - 2.0 * k3 * u3 + s * k3 * k3
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - u0 * k1 + s * k0 * k1
    P[2] = p02 - k0 * u2 - u0 * k2 + s * k0 * k2
    P[3] = p03 - k0 * u3 - u0 * k3 + s * k0 * k3
    P[4] = d1 if d1 > P_FLOOR else P_FLOOR
    P[5] = p12 - k1 * u2 - u1 * k2 + s * k1 * k2
    P[6] = p13 - k1 * u3 - u1 * k3 + s * k1 * k3
    P[7] = d2 if d2 > P_FLOOR else P_FLOOR
    P[8] = p23 - k2 * u3 - u2 * k3 + s * k2 * k3
    P[9] = d3 if d3 > P_FLOOR else P_FLOOR
    return y, s


def _update_any(
    x: list[float], P: list[float], h: Sequence[float], z: float, r: float, n_free: int
) -> tuple[float, float]:
    """Scalar update of an n-state filter with loops (any n; slower than the unrolled ones)."""
    n = len(x)
    u = [0.0] * n
    idx = 0
    for i in range(n):  # u = P hᵀ from the upper triangle
        for j in range(i, n):
            pij = P[idx]
            u[i] += pij * h[j]
            if j != i:
                u[j] += pij * h[i]
            idx += 1
    s = r + sum(hi * ui for hi, ui in zip(h, u, strict=True))
    y = z - sum(hi * xi for hi, xi in zip(h, x, strict=True))
    k = [u[i] / s if i < n_free else 0.0 for i in range(n)]
    idx = 0
    for i in range(n):
        x[i] += k[i] * y
        for j in range(i, n):
            pij = P[idx] - k[i] * u[j] - u[i] * k[j] + s * k[i] * k[j]
            if j == i and pij < P_FLOOR:
                pij = P_FLOOR
            P[idx] = pij
            idx += 1
    return y, s


KERNELS: dict[int, Kernel] = {1: _update1, 2: _update2, 3: _update3, 4: _update4}
"""Unrolled kernels by state count; :func:`kernel_for` falls back to the loop version."""


def kernel_for(n: int) -> Kernel:
    """The fastest scalar-update kernel for an n-state filter.

    Args:
        n: number of states (≥ 1).

    Returns:
        An unrolled kernel for n ≤ 4, the generic loop kernel otherwise.
    """
    return KERNELS.get(n, _update_any)


# Fused per-sample steps for the standard layout [v, θ] (one dynamic state): Φ = I
# predict, then the reference update (H = [1, 0…]), then the raw update (H = h),
# with the state kept in local variables in between. The Joseph form is written
# P − K uᵀ − w Kᵀ with w = u − S K, algebraically the same expansion as in the
# kernels (and still first-order insensitive to rounding in K: a gain error δ
# leaves only S δ δᵀ), with fewer operations. Signature:
#     step(x, P, q_v, q_p, z_ref, r_ref, h_fn, z_raw, r_raw) -> (y, S) of the raw update,
# where h_fn(v) gives the raw row at the operating point v = z_ref. A step may be
# specialised for one model and build its row inline (:func:`_step_em3`).

HRow = Callable[[float], tuple[float, ...]]

FusedStep = Callable[
    [list[float], list[float], float, float, float, float, HRow, float, float],
    tuple[float, float],
]


def _step2(
    x: list[float],
    P: list[float],
    q_v: float,
    q_p: float,
    z_ref: float,
    r_ref: float,
    h_fn: HRow,
    z: float,
    r: float,
) -> tuple[float, float]:
    """Fused predict + reference + raw update of a [v, θ1] filter."""
    h = h_fn(z_ref)
    p00, p01, p11 = P
    x0, x1 = x
    p00 += q_v
    p11 += q_p
    # reference, H = [1, 0]: u = (p00, p01); Joseph as P - K uᵀ - w Kᵀ, w = u - S K
    s = p00 + r_ref
    y = z_ref - x0
    k0 = p00 / s
    k1 = p01 / s
    w0 = p00 - s * k0
    w1 = p01 - s * k1
    x0 += k0 * y
    x1 += k1 * y
    p00, p01, p11 = (
        p00 - k0 * p00 - w0 * k0,
        p01 - k0 * p01 - w0 * k1,
        p11 - k1 * p01 - w1 * k1,
    )
    # raw, H = h
    h0, h1 = h
    u0 = p00 * h0 + p01 * h1
    u1 = p01 * h0 + p11 * h1
    s = h0 * u0 + h1 * u1 + r
    y = z - (h0 * x0 + h1 * x1)
    k0 = u0 / s
    k1 = u1 / s
    w0 = u0 - s * k0
    w1 = u1 - s * k1
    x[0] = x0 + k0 * y
    x[1] = x1 + k1 * y
    d0 = p00 - k0 * u0 - w0 * k0
    d1 = p11 - k1 * u1 - w1 * k1
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - w0 * k1
    P[2] = d1 if d1 > P_FLOOR else P_FLOOR
    return y, s


def _step3(
    x: list[float],
    P: list[float],
    q_v: float,
    q_p: float,
    z_ref: float,
    r_ref: float,
    h_fn: HRow,
    z: float,
    r: float,
) -> tuple[float, float]:
    """Fused predict + reference + raw update of a [v, θ1, θ2] filter."""
    h = h_fn(z_ref)
    p00, p01, p02, p11, p12, p22 = P
    x0, x1, x2 = x
    p00 += q_v
    p11 += q_p
    p22 += q_p
    # reference, H = [1, 0, 0]: u = (p00, p01, p02); Joseph as P - K uᵀ - w Kᵀ, w = u - S K
    s = p00 + r_ref
    y = z_ref - x0
    k0 = p00 / s
    k1 = p01 / s
    k2 = p02 / s
    w0 = p00 - s * k0
    w1 = p01 - s * k1
    w2 = p02 - s * k2
    x0 += k0 * y
    x1 += k1 * y
    x2 += k2 * y
    p00, p01, p02, p11, p12, p22 = (
        p00 - k0 * p00 - w0 * k0,
        p01 - k0 * p01 - w0 * k1,
        p02 - k0 * p02 - w0 * k2,
        p11 - k1 * p01 - w1 * k1,
        p12 - k1 * p02 - w1 * k2,
        p22 - k2 * p02 - w2 * k2,
    )
    # raw, H = h
    h0, h1, h2 = h
    u0 = p00 * h0 + p01 * h1 + p02 * h2
    u1 = p01 * h0 + p11 * h1 + p12 * h2
    u2 = p02 * h0 + p12 * h1 + p22 * h2
    s = h0 * u0 + h1 * u1 + h2 * u2 + r
    y = z - (h0 * x0 + h1 * x1 + h2 * x2)
    k0 = u0 / s
    k1 = u1 / s
    k2 = u2 / s
    w0 = u0 - s * k0
    w1 = u1 - s * k1
    w2 = u2 - s * k2
    x[0] = x0 + k0 * y
    x[1] = x1 + k1 * y
    x[2] = x2 + k2 * y
    d0 = p00 - k0 * u0 - w0 * k0
    d1 = p11 - k1 * u1 - w1 * k1
    d2 = p22 - k2 * u2 - w2 * k2
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - w0 * k1
    P[2] = p02 - k0 * u2 - w0 * k2
    P[3] = d1 if d1 > P_FLOOR else P_FLOOR
    P[4] = p12 - k1 * u2 - w1 * k2
    P[5] = d2 if d2 > P_FLOOR else P_FLOOR
    return y, s


def _step_em3(
    x: list[float],
    P: list[float],
    q_v: float,
    q_p: float,
    z_ref: float,
    r_ref: float,
    h_fn: HRow,
    z: float,
    r: float,
) -> tuple[float, float]:
    """:func:`_step3` specialised for KF-EM3: the raw row ``[1, v, 1]`` (eq. (24)) inline."""
    p00, p01, p02, p11, p12, p22 = P
    x0, x1, x2 = x
    p00 += q_v
    p11 += q_p
    p22 += q_p
    s = p00 + r_ref
    y = z_ref - x0
    k0 = p00 / s
    k1 = p01 / s
    k2 = p02 / s
    w0 = p00 - s * k0
    w1 = p01 - s * k1
    w2 = p02 - s * k2
    x0 += k0 * y
    x1 += k1 * y
    x2 += k2 * y
    p00, p01, p02, p11, p12, p22 = (
        p00 - k0 * p00 - w0 * k0,
        p01 - k0 * p01 - w0 * k1,
        p02 - k0 * p02 - w0 * k2,
        p11 - k1 * p01 - w1 * k1,
        p12 - k1 * p02 - w1 * k2,
        p22 - k2 * p02 - w2 * k2,
    )
    v = z_ref
    u0 = p00 + p01 * v + p02
    u1 = p01 + p11 * v + p12
    u2 = p02 + p12 * v + p22
    s = u0 + v * u1 + u2 + r
    y = z - (x0 + v * x1 + x2)
    k0 = u0 / s
    k1 = u1 / s
    k2 = u2 / s
    w0 = u0 - s * k0
    w1 = u1 - s * k1
    w2 = u2 - s * k2
    x[0] = x0 + k0 * y
    x[1] = x1 + k1 * y
    x[2] = x2 + k2 * y
    d0 = p00 - k0 * u0 - w0 * k0
    d1 = p11 - k1 * u1 - w1 * k1
    d2 = p22 - k2 * u2 - w2 * k2
    P[0] = d0 if d0 > P_FLOOR else P_FLOOR
    P[1] = p01 - k0 * u1 - w0 * k1
    P[2] = p02 - k0 * u2 - w0 * k2
    P[3] = d1 if d1 > P_FLOOR else P_FLOOR
    P[4] = p12 - k1 * u2 - w1 * k2
    P[5] = d2 if d2 > P_FLOOR else P_FLOOR
    return y, s


def _step_composed(
    x: list[float],
    P: list[float],
    q_v: float,
    q_p: float,
    z_ref: float,
    r_ref: float,
    h_fn: HRow,
    z: float,
    r: float,
) -> tuple[float, float]:
    """Predict + reference + raw update of an n-state [v, θ] filter from the kernels."""
    h = h_fn(z_ref)
    n = len(x)
    kernel = kernel_for(n)
    idx = 0
    for i in range(n):
        P[idx] += q_v if i == 0 else q_p
        idx += n - i
    kernel(x, P, (1.0,) + (0.0,) * (n - 1), z_ref, r_ref, n)
    return kernel(x, P, h, z, r, n)


FUSED_STEPS: dict[int, FusedStep] = {2: _step2, 3: _step3}
"""Fused steps by state count for one dynamic state; others use :func:`_step_composed`."""


def diag_indices(n: int) -> tuple[int, ...]:
    """Positions of the diagonal elements in the packed upper triangle of an n×n matrix."""
    out = []
    idx = 0
    for i in range(n):
        out.append(idx)
        idx += n - i
    return tuple(out)


def pack(P: npt.ArrayLike) -> list[float]:
    """Pack a symmetric n×n matrix into its upper triangle, row by row.

    Args:
        P: symmetric matrix, shape (n, n).

    Returns:
        ``n(n+1)/2`` floats.
    """
    M = np.asarray(P, dtype=np.float64)
    n = M.shape[0]
    return [float(M[i, j]) for i in range(n) for j in range(i, n)]


def unpack(packed: Sequence[float], n: int) -> list[list[float]]:
    """Expand a packed upper triangle to a full symmetric n×n matrix (plain lists).

    Args:
        packed: ``n(n+1)/2`` floats.
        n: matrix size.

    Returns:
        The full matrix as a list of n rows.
    """
    M = [[0.0] * n for _ in range(n)]
    idx = 0
    for i in range(n):
        for j in range(i, n):
            M[i][j] = M[j][i] = float(packed[idx])
            idx += 1
    return M


# ---------------------------------------------------------------------------
# Filter specifications and configuration
# ---------------------------------------------------------------------------


def _h_em1(v: float) -> tuple[float, ...]:
    return (1.0, 1.0)


def _h_em2(v: float) -> tuple[float, ...]:
    return (1.0, v)


def _h_em3(v: float) -> tuple[float, ...]:
    return (1.0, v, 1.0)


def _h_em4(v: float) -> tuple[float, ...]:
    return (1.0, v * v, v, 1.0)


@dataclass(frozen=True, slots=True)
class FilterSpec:
    """What a joint speed-and-calibration filter estimates: its states and its H row.

    States are ordered dynamic states first (they always get gain, e.g. the speed
    ``v_mps``; later a sea current), then the calibration parameters (frozen during
    a reference outage). Adding a model is adding a spec: the filter code is generic
    in the state count.

    Attributes:
        model: the error model whose parameters are the last states.
        states: state names with units, e.g. ``("v_mps", "m", "b_mps")``.
        n_dynamic: how many leading states are dynamic (≥ 1; state 0 is the speed
            the reference observes).
        h_raw: the raw measurement row as a function of the operating-point speed
            in m/s (eqs. (22)–(24)); returns ``len(states)`` floats.
    """

    model: ModelName
    states: tuple[str, ...]
    n_dynamic: int
    h_raw: Callable[[float], tuple[float, ...]] = field(compare=False)

    def __post_init__(self) -> None:
        check_model(self.model)
        n_par = len(PARAM_NAMES[self.model])
        if self.n_dynamic < 1 or self.n_dynamic + n_par != len(self.states):
            raise ModelError(
                f"{self.model} spec needs n_dynamic ≥ 1 plus {n_par} parameter states, "
                f"got {self.states} with n_dynamic={self.n_dynamic}"
            )
        if len(self.h_raw(1.0)) != len(self.states):
            raise ModelError("h_raw must return one entry per state")

    @property
    def n(self) -> int:
        """Number of states."""
        return len(self.states)


_STATE_NAMES: dict[ParamName, str] = {"a": "a_spm", "m": "m", "b": "b_mps"}

SPECS: dict[ModelName, FilterSpec] = {
    "EM1": FilterSpec("EM1", ("v_mps", "b_mps"), 1, _h_em1),
    "EM2": FilterSpec("EM2", ("v_mps", "m"), 1, _h_em2),
    "EM3": FilterSpec("EM3", ("v_mps", "m", "b_mps"), 1, _h_em3),
    "EM4": FilterSpec("EM4", ("v_mps", "a_spm", "m", "b_mps"), 1, _h_em4),
}
"""The KF-EM1..KF-EM4 specifications (paper eqs. (22)–(24), and EM4)."""

KNOT_MPS = 1852.0 / 3600.0

DEFAULT_R_RAW_MPS2 = (0.1 * KNOT_MPS) ** 2
"""EMlog1 (Airmar DX900+) specification ±0.1 kn, taken as 1σ: (0.0514 m/s)²."""

DEFAULT_R_REF_MPS2 = 0.01**2
"""DVL reference noise (Rowe SeaPILOT ±0.25 % ≈ 0.005 m/s at 2 m/s, doubled): (0.01 m/s)²."""


@dataclass(frozen=True, slots=True)
class KfConfig:
    """Tuning of the KF-EMx filters (paper section IV-A-4 defaults).

    Attributes:
        r_raw_mps2: raw EMlog measurement variance R, (m/s)², from the sensor spec.
        r_ref_mps2: reference (DVL) measurement variance, (m/s)².
        p0: initial variance of every state (paper: P0 = 0.25·I), state units².
        q_params: process noise added to each parameter variance per step
            (paper: Q = 1e-7·I), parameter units².
        accel_psd_m2ps3: spectral density of the speed random walk, (m/s²)²/Hz;
            ``q_v = accel_psd_m2ps3·dt`` (0.01 lets v move ~0.1 m/s per second).

    Raises:
        ValueError: a variance that is not positive (q_params may be 0).
    """

    r_raw_mps2: float = DEFAULT_R_RAW_MPS2
    r_ref_mps2: float = DEFAULT_R_REF_MPS2
    p0: float = 0.25
    q_params: float = 1e-7
    accel_psd_m2ps3: float = 0.01

    def __post_init__(self) -> None:
        for name in ("r_raw_mps2", "r_ref_mps2", "p0"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {value!r}")
        for name in ("q_params", "accel_psd_m2ps3"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be non-negative and finite, got {value!r}")


def r_from_accuracy(accuracy_mps: float) -> float:
    """Measurement variance from a datasheet accuracy taken as one standard deviation.

    Args:
        accuracy_mps: the ± accuracy in m/s (e.g. 0.1 kn → 0.0514 m/s).

    Returns:
        The variance in (m/s)².

    Raises:
        ValueError: a non-positive accuracy.
    """
    if not accuracy_mps > 0.0:
        raise ValueError("accuracy must be positive")
    return accuracy_mps * accuracy_mps


# ---------------------------------------------------------------------------
# Online filters over plain floats
# ---------------------------------------------------------------------------


class _FastFilter:
    """State storage shared by the online filters: x and packed P as float lists."""

    __slots__ = ("_P", "_diag", "_kernel", "_n", "_x")

    def __init__(self, x0: Sequence[float], P0: npt.ArrayLike) -> None:
        n = len(x0)
        M = np.asarray(P0, dtype=np.float64)
        if M.shape != (n, n):
            raise ModelError(f"P0 must have shape ({n}, {n}), got {M.shape}")
        _check_covariance("P0", M, definite=True)
        if not all(math.isfinite(v) for v in x0):
            raise ModelError("x0 must be finite")
        self._n = n
        self._x = [float(v) for v in x0]
        self._P = pack(M)
        self._diag = diag_indices(n)
        self._kernel = kernel_for(n)

    @property
    def x(self) -> tuple[float, ...]:
        """The state mean (a copy), in the order of the state names."""
        return tuple(self._x)

    def covariance(self) -> list[list[float]]:
        """The full state covariance P as plain lists (n rows of n floats)."""
        return unpack(self._P, self._n)

    def std(self) -> tuple[float, ...]:
        """Standard deviation of every state, ``√diag(P)``, in state units."""
        P = self._P
        return tuple(math.sqrt(P[i]) for i in self._diag)


def _check_export(
    data: dict[str, object], names: tuple[str, ...]
) -> tuple[list[float], FloatArray]:
    """Validate an exported state dict; return (x, P)."""
    states = data.get("states")
    if not isinstance(states, list | tuple) or tuple(states) != names:
        raise ModelError(f"exported states {data.get('states')!r} do not match {names}")
    x_raw = data.get("x")
    P_raw = data.get("P")
    if not isinstance(x_raw, list | tuple) or not isinstance(P_raw, list | tuple):
        raise ModelError("exported state needs lists 'x' and 'P'")
    try:
        x = [float(v) for v in x_raw]
        P = np.array(P_raw, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"exported state is not numeric: {exc}") from exc
    return x, P


class KfCalibrator(_FastFilter):
    """KF-EMx online: joint speed and calibration filter, O(1) per sample.

    One object per unit under test. Per sample call :meth:`update` with the raw
    reading, the lag-aligned reference (None during an outage) and the time step;
    the semantics are in the module docstring. The state is ``[v, θ]`` (see
    :data:`SPECS`); everything lives in a few floats.

    Args:
        model: ``"EM1"`` … ``"EM4"`` (or pass ``spec`` for a custom model).
        config: tuning (R, P0, Q).
        params0: initial parameters (default: the ideal sensor, θ = 0).
        P0: initial covariance, shape (n, n) (default ``config.p0·I``).
        v0_mps: initial speed in m/s.
        spec: a custom :class:`FilterSpec` instead of ``SPECS[model]``.

    Raises:
        ModelError: unknown model, params of another model, bad P0.
    """

    __slots__ = (
        "_abm",
        "_dt_q",
        "_fused",
        "_h_raw",
        "_h_ref",
        "_param_diag",
        "_q_par",
        "_r_raw",
        "_r_ref",
        "config",
        "spec",
    )

    def __init__(
        self,
        model: str = "EM3",
        config: KfConfig | None = None,
        *,
        params0: Params | None = None,
        P0: npt.ArrayLike | None = None,
        v0_mps: float = 0.0,
        spec: FilterSpec | None = None,
    ) -> None:
        self.spec = spec if spec is not None else SPECS[check_model(model)]
        self.config = config if config is not None else KfConfig()
        theta = params0.theta if params0 is not None else (0.0,) * len(PARAM_NAMES[self.spec.model])
        if params0 is not None and params0.model != self.spec.model:
            raise ModelError(f"params0 are {params0.model}, the filter is {self.spec.model}")
        n = self.spec.n
        x0 = [v0_mps] + [0.0] * (self.spec.n_dynamic - 1) + list(theta)
        super().__init__(x0, np.eye(n) * self.config.p0 if P0 is None else P0)
        nd = self.spec.n_dynamic
        self._param_diag = self._diag[nd:]
        self._q_par = self.config.q_params
        self._dt_q = self.config.accel_psd_m2ps3
        self._h_ref = (1.0,) + (0.0,) * (n - 1)
        self._r_raw = self.config.r_raw_mps2
        self._h_raw = self.spec.h_raw
        self._r_ref = self.config.r_ref_mps2
        self._fused: FusedStep | None = FUSED_STEPS.get(n, _step_composed) if nd == 1 else None
        if nd == 1 and self.spec.h_raw is _h_em3:
            self._fused = _step_em3  # the paper's KF-EM3 with its row built inline
        names = PARAM_NAMES[self.spec.model]
        self._abm = tuple(nd + names.index(p) if p in names else -1 for p in ("a", "m", "b"))

    # -- the per-sample path ------------------------------------------------

    def predict(self, dt_s: float) -> None:
        """Time update over ``dt_s`` seconds (Φ = I): add ``q_v = psd·dt`` and ``q_params``.

        Raises:
            DataError: a negative or non-finite time step.
        """
        if not 0.0 <= dt_s < _INF:
            raise DataError(f"dt_s must be finite and non-negative, got {dt_s!r}")
        P = self._P
        dq = self._dt_q * dt_s
        for i in self._diag[: self.spec.n_dynamic]:
            P[i] += dq
        q = self._q_par
        for i in self._param_diag:
            P[i] += q

    def update(
        self, raw_mps: float | None, ref_mps: float | None, dt_s: float, *, learn: bool = True
    ) -> Innovation | None:
        """One sample: predict over ``dt_s``, then the reference, then the raw update.

        Args:
            raw_mps: raw EMlog reading in m/s, or None if the UUT gave nothing.
            ref_mps: lag-aligned reference speed in m/s, or None during an outage.
            dt_s: seconds since the previous call (≥ 0).
            learn: False holds the parameters even with a reference (the supervisor
                froze them); the speed state is still updated.

        Returns:
            The raw-measurement innovation (y, S, NIS), or None without a raw reading.

        Raises:
            DataError: a negative or non-finite time step.
        """
        fused = self._fused
        if fused is not None and learn and ref_mps is not None and raw_mps is not None:
            # The common case, one fused call (same arithmetic as the path below).
            if not 0.0 <= dt_s < _INF:
                raise DataError(f"dt_s must be finite and non-negative, got {dt_s!r}")
            y, s = fused(
                self._x,
                self._P,
                self._dt_q * dt_s,
                self._q_par,
                ref_mps,
                self._r_ref,
                self._h_raw,
                raw_mps,
                self._r_raw,
            )
            return _new_innovation(Innovation, (y, s, y * y / s))
        self.predict(dt_s)
        x, P = self._x, self._P
        n_all = self._n if learn else self.spec.n_dynamic
        if ref_mps is not None:
            self._kernel(x, P, self._h_ref, ref_mps, self._r_ref, n_all)
        if raw_mps is None:
            return None
        if ref_mps is not None:
            v_op = ref_mps
            n_free = n_all
        else:
            v_op = self.corrected(raw_mps)
            if not math.isfinite(v_op):
                return None
            n_free = self.spec.n_dynamic
        y, s = self._kernel(x, P, self.spec.h_raw(v_op), raw_mps, self._r_raw, n_free)
        return _new_innovation(Innovation, (y, s, y * y / s))

    def corrected(self, raw_mps: float) -> float:
        """The raw reading corrected with the current parameters (inverse model), m/s.

        Same as ``self.params.correct(raw_mps)`` without building a Params object.
        """
        x = self._x
        ia, im, ib = self._abm
        return invert(
            x[ia] if ia >= 0 else 0.0, x[im] if im >= 0 else 0.0, x[ib] if ib >= 0 else 0.0, raw_mps
        )

    # -- read-outs ----------------------------------------------------------

    @property
    def params(self) -> Params:
        """The current parameter estimate θ̂ (frozen dataclass)."""
        return Params.from_theta(self.spec.model, self._x[self.spec.n_dynamic :])

    @property
    def param_std(self) -> tuple[float, ...]:
        """Standard deviations of θ̂ from P, in θ order and units."""
        P = self._P
        return tuple(math.sqrt(P[i]) for i in self._param_diag)

    def param_std_dict(self) -> dict[str, float]:
        """Standard deviations of θ̂ by short parameter name."""
        return dict(zip(PARAM_NAMES[self.spec.model], self.param_std, strict=True))

    @property
    def speed_mps(self) -> float:
        """The speed state v̂ in m/s."""
        return self._x[0]

    @property
    def speed_std_mps(self) -> float:
        """Standard deviation of v̂ in m/s."""
        return math.sqrt(self._P[0])

    # -- persistence --------------------------------------------------------

    def export_state(self) -> dict[str, object]:
        """The filter state as plain JSON/YAML types, for persistence.

        Returns:
            ``{"model", "states", "x", "P"}`` with P as a full list of rows.
        """
        return {
            "model": self.spec.model,
            "states": list(self.spec.states),
            "x": list(self._x),
            "P": self.covariance(),
        }

    @classmethod
    def from_state(
        cls,
        data: dict[str, object],
        config: KfConfig | None = None,
        *,
        spec: FilterSpec | None = None,
    ) -> KfCalibrator:
        """Resume a filter from :meth:`export_state` output.

        Args:
            data: the exported dict.
            config: tuning for the resumed filter.
            spec: custom spec if the filter was not a standard one.

        Returns:
            A filter with exactly the exported x and P.

        Raises:
            ModelError: unknown model, mismatched states, malformed or non-SPD P.
        """
        model = check_model(str(data.get("model")))
        use = spec if spec is not None else SPECS[model]
        x, P = _check_export(data, use.states)
        obj = cls(model, config, P0=P, spec=use)
        obj._x[:] = x
        return obj


class RlsCalibrator(_FastFilter):
    """Parameter-only filter: recursive least squares with random-walk parameters.

    State θ, measurement ``z = raw − ref = h(ref)·θ + η`` (eqs. (18)–(21) row by
    row), ``Φ = I``, process noise ``q`` per step on each parameter. With q = 0 it
    equals the batch least-squares solution of the same data plus the Gaussian
    prior (θ0, P0); started from a batch fit of the first samples with
    ``P0 = r·(H₀ᵀH₀)⁻¹`` it equals batch LS of all samples exactly.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        r_mps2: variance of z in (m/s)² (raw noise plus reference noise).
        q: process noise per step on each parameter, parameter units².
        params0: prior mean θ0 (default 0).
        P0: prior covariance, shape (p, p) (default 0.25·I).

    Raises:
        ModelError: unknown model or bad P0.
        ValueError: non-positive r or negative q.
    """

    __slots__ = ("model", "q", "r_mps2")

    def __init__(
        self,
        model: str = "EM3",
        r_mps2: float = DEFAULT_R_RAW_MPS2,
        *,
        q: float = 0.0,
        params0: Params | None = None,
        P0: npt.ArrayLike | None = None,
    ) -> None:
        self.model = check_model(model)
        if not (math.isfinite(r_mps2) and r_mps2 > 0.0):
            raise ValueError("r_mps2 must be positive")
        if not (math.isfinite(q) and q >= 0.0):
            raise ValueError("q must be non-negative")
        if params0 is not None and params0.model != self.model:
            raise ModelError(f"params0 are {params0.model}, the filter is {self.model}")
        p = len(PARAM_NAMES[self.model])
        theta = params0.theta if params0 is not None else (0.0,) * p
        super().__init__(theta, np.eye(p) * 0.25 if P0 is None else P0)
        self.r_mps2 = r_mps2
        self.q = q

    def update(self, raw_mps: float, ref_mps: float, weight: float = 1.0) -> Innovation:
        """One sample: add q, then update θ with ``z = raw − ref``, ``H = h(ref)``.

        Args:
            raw_mps: raw EMlog reading in m/s.
            ref_mps: lag-aligned reference speed in m/s.
            weight: relative sample weight (the measurement variance is ``r/weight``).

        Returns:
            The innovation of z.
        """
        P = self._P
        if self.q:
            for i in self._diag:
                P[i] += self.q
        y, s = self._kernel(
            self._x,
            P,
            design_row(self.model, ref_mps),
            raw_mps - ref_mps,
            self.r_mps2 / weight,
            self._n,
        )
        return Innovation(y, s, y * y / s)

    @property
    def params(self) -> Params:
        """The current estimate θ̂."""
        return Params.from_theta(self.model, self._x)

    @property
    def param_std(self) -> tuple[float, ...]:
        """Standard deviations of θ̂ from P."""
        return self.std()

    def corrected(self, raw_mps: float) -> float:
        """The raw reading corrected with the current parameters, m/s."""
        return self.params.correct(raw_mps)

    def export_state(self) -> dict[str, object]:
        """The filter state as plain types: ``{"model", "states", "x", "P"}``."""
        return {
            "model": self.model,
            "states": [_STATE_NAMES[n] for n in PARAM_NAMES[self.model]],
            "x": list(self._x),
            "P": self.covariance(),
        }

    @classmethod
    def from_state(cls, data: dict[str, object], r_mps2: float, *, q: float = 0.0) -> RlsCalibrator:
        """Resume from :meth:`export_state` output.

        Raises:
            ModelError: unknown model, mismatched states, malformed or non-SPD P.
        """
        model = check_model(str(data.get("model")))
        names = tuple(_STATE_NAMES[n] for n in PARAM_NAMES[model])
        x, P = _check_export(data, names)
        obj = cls(model, r_mps2, q=q, P0=P)
        obj._x[:] = x
        return obj


# ---------------------------------------------------------------------------
# Batch run over arrays (offline commands)
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class KfRun:
    """Result of running KF-EMx over a recorded series.

    Attributes:
        model: the error model.
        params: final parameter estimate (what cross-validation freezes).
        param_std: final standard deviations of θ̂, θ order.
        covariance: final P, shape (n, n).
        speed_mps: speed state after each sample, shape (N,).
        theta: parameter estimate after each sample, shape (N, p) (empty without history).
        theta_std: its standard deviation from P, shape (N, p) (the convergence sleeve).
        y: raw innovation per sample, m/s, shape (N,) (nan where no raw reading).
        S: innovation variance per sample, (m/s)², shape (N,).
        nis: NIS per sample, shape (N,) (nan where no raw reading or in outage).
        state: the exported final state (see :meth:`KfCalibrator.export_state`).
    """

    model: ModelName
    params: Params
    param_std: tuple[float, ...]
    covariance: FloatArray
    speed_mps: FloatArray
    theta: FloatArray
    theta_std: FloatArray
    y: FloatArray
    S: FloatArray
    nis: FloatArray
    state: dict[str, object]


def run_kf(
    model: str,
    t_s: npt.ArrayLike,
    raw_mps: npt.ArrayLike,
    ref_mps: npt.ArrayLike,
    config: KfConfig | None = None,
    *,
    history: bool = True,
    calibrator: KfCalibrator | None = None,
) -> KfRun:
    """Run KF-EMx over aligned arrays with the fast per-sample filter.

    Args:
        model: ``"EM1"`` … ``"EM4"``.
        t_s: sample times in s, shape (N,), non-decreasing.
        raw_mps: raw EMlog speeds in m/s, shape (N,); nan = no reading.
        ref_mps: lag-aligned reference speeds in m/s, shape (N,); nan = outage.
        config: tuning (default :class:`KfConfig`).
        history: keep per-sample speed/θ/σ histories (False: only final values
            and innovations, faster for cross-validation).
        calibrator: continue an existing filter instead of a fresh one.

    Returns:
        The final estimate and the per-sample series.

    Raises:
        DataError: arrays of different lengths or decreasing times.
        ModelError: unknown model.
    """
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    if not t.shape == raw.shape == ref.shape:
        raise DataError(f"t, raw, ref differ in length: {t.size}, {raw.size}, {ref.size}")
    dts = np.diff(t, prepend=t[0] if t.size else 0.0)
    if not np.all(dts >= 0.0):
        raise DataError("times must be non-decreasing")
    kf = calibrator if calibrator is not None else KfCalibrator(model, config)
    p = len(PARAM_NAMES[kf.spec.model])
    n = t.size
    nd = kf.spec.n_dynamic
    ys = [math.nan] * n
    ss = [math.nan] * n
    nis = [math.nan] * n
    hist: list[float] = []
    hist_std: list[float] = []
    speeds: list[float] = []
    x = kf._x
    P = kf._P
    pdiag = kf._param_diag
    upd = kf.update
    for k, (dt, zr, zv) in enumerate(zip(dts.tolist(), raw.tolist(), ref.tolist(), strict=True)):
        has_ref = zv == zv  # not nan
        inn = upd(zr if zr == zr else None, zv if has_ref else None, dt)
        if inn is not None:
            ys[k] = inn.y
            ss[k] = inn.S
            if has_ref:
                nis[k] = inn.nis
        if history:
            speeds.append(x[0])
            hist.extend(x[nd:])
            hist_std.extend([P[i] for i in pdiag])
    if history:
        theta = np.array(hist, dtype=np.float64).reshape(n, p)
        theta_std = np.sqrt(np.array(hist_std, dtype=np.float64).reshape(n, p))
        speed = np.array(speeds, dtype=np.float64)
    else:
        theta = theta_std = np.empty((0, p))
        speed = np.empty(0)
    return KfRun(
        model=kf.spec.model,
        params=kf.params,
        param_std=kf.param_std,
        covariance=np.array(kf.covariance()),
        speed_mps=speed,
        theta=theta,
        theta_std=theta_std,
        y=np.array(ys),
        S=np.array(ss),
        nis=np.array(nis),
        state=kf.export_state(),
    )
