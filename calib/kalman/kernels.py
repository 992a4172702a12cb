"""The per-sample scalar measurement update over plain Python floats.

The online filters process one scalar measurement at a time (a vector measurement
with uncorrelated noise is a sequence of scalar updates, which is exact). On the
daemon's path a numpy step costs tens of microseconds for a 3×3 system; the same
update over lists of floats costs a few. One generic kernel serves every state
size the filters use (2 to 6 states).

Contract of :func:`scalar_update`: ``x`` (n floats, the mean) and ``P`` (n lists of n
floats, the symmetric covariance) are updated in place; ``h`` is the measurement
row, ``z`` the measurement and ``r`` its variance. ``gains`` (n floats, 1.0 or 0.0)
says which states may move. A state with gain 0 is *held*: taken as known at its
current value for this measurement — its term ``hᵢ·xᵢ`` is moved to the measurement
side and its column dropped from the row, so the others learn fully from what the
measurement says given that value (a scale held at its prior while circling at
constant speed: the bias and the current still learn at full rate). The
covariance update is the Joseph form for that row ``h' = h·gains``, exact for
the optimal gain and, for a rank-one H, expanded as::

    (I − KH')P(I − KH')ᵀ + K r Kᵀ = P − K uᵀ − u Kᵀ + S K Kᵀ,   u = P h'ᵀ, S = h' u + r.

Diagonal entries are floored at :data:`P_FLOOR` to keep P positive under rounding.
A measurement whose normalised innovation squared ``y²/S`` exceeds ``max_nis`` is
not applied (the caller counts it as gated). A measurement correlated with its
neighbours holds less than one sample's information: with ``deweight`` f ≥ 1 it is
applied with the innovation variance ``f·S`` (the gain is K/f and P shrinks by 1/f of
what an independent sample would take off), while the returned S and the gate are the
sample's own.

:func:`condition` makes one state known (the Gaussian conditional of the others on it);
:func:`check_covariance` checks a covariance given from outside (a saved calibration's).

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from calib.errors import ModelError

P_FLOOR = 1e-30
"""Smallest variance a diagonal element of P may take."""


def scalar_update(
    x: list[float],
    P: list[list[float]],
    h: Sequence[float],
    z: float,
    r: float,
    gains: Sequence[float],
    max_nis: float,
    deweight: float = 1.0,
) -> tuple[float, float, bool]:
    """One scalar measurement update in place (see the module docstring).

    Args:
        x: state mean, n floats, updated in place.
        P: covariance, n rows of n floats, symmetric, updated in place.
        h: measurement row, n floats (zeros are skipped).
        z: the measurement.
        r: its noise variance (> 0).
        gains: 1.0 for a state that may move, 0.0 for a held (known) state.
        max_nis: gate: the update is skipped when ``y²/S`` exceeds it (``inf``: never).
        deweight: samples per independent sample (≥ 1): the update is made with the
            innovation variance ``deweight·S``.

    Returns:
        ``(y, S, applied)``: the innovation, its variance, and whether it was applied.
    """
    n = len(x)
    y = z
    hz = []
    for j, hj in enumerate(h):
        if hj:
            y -= hj * x[j]
            if gains[j]:
                hz.append((j, hj))
    u = []
    for row in P:
        acc = 0.0
        for j, hj in hz:
            acc += row[j] * hj
        u.append(acc)
    s = r
    for j, hj in hz:
        s += hj * u[j]
    if y * y > max_nis * s:
        return y, s, False
    s_use = s * deweight if deweight > 1.0 else s
    inv_s = 1.0 / s_use
    k = [ui * inv_s * g for ui, g in zip(u, gains, strict=True)]
    for i in range(n):
        ki = k[i]
        x[i] += ki * y
        row = P[i]
        ui_s = u[i] - s_use * ki
        for j in range(i, n):
            v = row[j] - ki * u[j] - k[j] * ui_s
            row[j] = v
            P[j][i] = v
        if row[i] < P_FLOOR:
            row[i] = P_FLOOR
    return y, s, True


def to_lists(M: npt.ArrayLike) -> list[list[float]]:
    """A square matrix as n lists of n Python floats (a copy)."""
    return [[float(v) for v in row] for row in np.asarray(M, dtype=np.float64)]


def condition(x: list[float], P: list[list[float]], i: int, value: float) -> None:
    """State ``i`` known to be ``value``: the Gaussian conditional, in place.

    Every state moves by ``P[·][i]/P[i][i]·(value − x[i])`` and the covariance loses
    ``P[·][i]·P[i][·]/P[i][i]``; state ``i`` is then ``value`` with no variance and no
    correlation. A state whose variance is already 0 is set to ``value`` alone.
    """
    n = len(x)
    var = P[i][i]
    if var > 0.0:
        col = [row[i] for row in P]
        d = (value - x[i]) / var
        for r in range(n):
            x[r] += col[r] * d
            k = col[r] / var
            row = P[r]
            for c in range(n):
                row[c] -= k * col[c]
    x[i] = value
    for j in range(n):
        P[i][j] = P[j][i] = 0.0


def check_covariance(M: npt.ArrayLike, n: int) -> None:
    """Raise ModelError unless M is an n×n finite, symmetric, positive-definite matrix.

    Args:
        M: the matrix.
        n: the expected size.

    Raises:
        ModelError: wrong shape, non-finite, not symmetric or not positive definite.
    """
    A = np.asarray(M, dtype=np.float64)
    if A.shape != (n, n):
        raise ModelError(f"covariance must have shape ({n}, {n}), got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ModelError("covariance has non-finite entries")
    scale = max(float(np.max(np.abs(A))), 1e-300)
    if not np.allclose(A, A.T, rtol=0.0, atol=1e-9 * scale):
        raise ModelError("covariance is not symmetric")
    eig = np.linalg.eigvalsh(0.5 * (A + A.T))
    if not float(eig[0]) > 0.0:
        raise ModelError(f"covariance is not positive definite (smallest eigenvalue {eig[0]:.3g})")
