"""The per-sample scalar update over plain floats, against the numpy reference."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from calib.kalman import KalmanModel, make_state, scalar_update, update
from calib.kalman.kernels import P_FLOOR, to_lists


def _random_spd(n: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def _masks(n: int) -> list[tuple[bool, ...]]:
    """Every gain mask with the first state free (the speed always moves)."""
    return [(True, *rest) for rest in itertools.product((True, False), repeat=n - 1)]


class TestScalarUpdate:
    """The kernel is the Joseph-form update of the numpy reference."""

    @pytest.mark.parametrize(
        ("n", "mask"), [(n, m) for n in range(1, 7) for m in _masks(n)], ids=str
    )
    def test_matches_the_numpy_reference_for_every_mask(
        self, n: int, mask: tuple[bool, ...]
    ) -> None:
        """x and P equal numpy's update with the held states' terms moved to z, to 1e-10."""
        rng = np.random.default_rng(n * 100 + sum(1 << i for i, f in enumerate(mask) if f))
        P = _random_spd(n, rng)
        x = rng.normal(size=n)
        h = rng.normal(size=n)
        h[rng.random(n) < 0.3] = 0.0
        h[0] = 1.0
        free = np.array(mask)
        h_free = np.where(free, h, 0.0)
        z_free = 0.7 - float(np.dot(np.where(free, 0.0, h), x))
        model = KalmanModel.of(np.eye(n), h_free[None, :], np.zeros((n, n)), [[0.2]])
        want, inn = update(make_state(x, P), z_free, model, free=list(mask))
        assert inn is not None
        xs, Ps = x.tolist(), to_lists(P)
        y, s, applied = scalar_update(
            xs, Ps, h.tolist(), 0.7, 0.2, [float(f) for f in mask], math.inf
        )
        assert applied
        assert (y, s) == pytest.approx((inn.y, inn.S), rel=1e-12)
        np.testing.assert_allclose(xs, want.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Ps, want.P, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(np.array(Ps), np.array(Ps).T)

    def test_gate_refuses_an_outlier_and_leaves_the_state(self) -> None:
        """An innovation beyond the NIS gate is not applied; x and P stay as they were."""
        x = [1.0, 0.1]
        P = [[0.01, 0.0], [0.0, 0.01]]
        y, s, applied = scalar_update(x, P, [1.0, 1.0], 30.0, 1e-4, [1.0, 1.0], 25.0)
        assert not applied
        assert y == pytest.approx(28.9) and s == pytest.approx(0.0201)
        assert x == [1.0, 0.1] and P == [[0.01, 0.0], [0.0, 0.01]]

    def test_gate_admits_an_innovation_inside_it(self) -> None:
        """An innovation with NIS under the gate is applied."""
        x = [1.0]
        P = [[1.0]]
        _, _, applied = scalar_update(x, P, [1.0], 2.0, 1.0, [1.0], 25.0)
        assert applied and x[0] == pytest.approx(1.5)

    def test_variances_never_fall_below_the_floor(self) -> None:
        """A perfect measurement cannot drive a variance to zero or below."""
        x = [0.0]
        P = [[1e-40]]
        scalar_update(x, P, [1.0], 1.0, 1e-300, [1.0], math.inf)
        assert P[0][0] >= P_FLOOR
