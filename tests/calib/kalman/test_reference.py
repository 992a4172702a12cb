"""The numpy reference Kalman filter: model validation and the textbook steps."""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import ModelError
from calib.kalman import KalmanModel, make_state, predict, update


def _random_spd(n: int, rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


class TestKalmanModel:
    """Validation of the immutable model."""

    def test_wrong_shaped_R_raises(self) -> None:
        """An R that is not 1×1 raises ModelError."""
        with pytest.raises(ModelError, match="R must have shape"):
            KalmanModel.of(np.eye(2), [[1.0, 0.0]], np.eye(2), np.eye(2))

    def test_wrong_shaped_H_raises(self) -> None:
        """An H with the wrong number of columns raises ModelError."""
        with pytest.raises(ModelError, match="H must have shape"):
            KalmanModel.of(np.eye(2), [[1.0, 0.0, 0.0]], np.eye(2), [[1.0]])

    def test_asymmetric_Q_raises(self) -> None:
        """A non-symmetric Q raises ModelError."""
        with pytest.raises(ModelError, match="symmetric"):
            KalmanModel.of(np.eye(2), [[1.0, 0.0]], [[1.0, 0.5], [0.0, 1.0]], [[1.0]])

    def test_indefinite_Q_raises(self) -> None:
        """A Q with a negative eigenvalue raises ModelError."""
        with pytest.raises(ModelError, match="semi-definite"):
            KalmanModel.of(np.eye(2), [[1.0, 0.0]], [[1.0, 0.0], [0.0, -1.0]], [[1.0]])

    def test_non_positive_R_raises(self) -> None:
        """R = 0 raises ModelError."""
        with pytest.raises(ModelError, match="positive"):
            KalmanModel.of(np.eye(1), [[1.0]], np.eye(1), [[0.0]])

    def test_arrays_read_only(self) -> None:
        """The model's matrices cannot be modified in place."""
        model = KalmanModel.of(np.eye(1), [[1.0]], np.eye(1), [[1.0]])
        with pytest.raises(ValueError, match="read-only"):
            model.F[0, 0] = 2.0


class TestReferenceSteps:
    """The pure numpy predict/update."""

    def test_scalar_textbook_values(self) -> None:
        """A 1-state update gives the textbook gain, innovation, S and NIS."""
        model = KalmanModel.of([[1.0]], [[1.0]], [[0.5]], [[1.0]])
        state = predict(make_state([0.0], [[1.5]]), model)
        assert state.P[0, 0] == pytest.approx(2.0)
        new, inn = update(state, 3.0, model)
        assert inn is not None
        assert (inn.y, inn.S, inn.nis) == pytest.approx((3.0, 3.0, 3.0))
        assert new.x[0] == pytest.approx(2.0)
        assert new.P[0, 0] == pytest.approx(2.0 / 3.0)

    def test_none_measurement_is_predict_only(self) -> None:
        """z = None returns the state unchanged and no innovation."""
        model = KalmanModel.of([[1.0]], [[1.0]], [[0.5]], [[1.0]])
        state = make_state([1.0], [[1.0]])
        same, inn = update(state, None, model)
        assert same is state and inn is None

    def test_joseph_equals_standard_form_for_optimal_gain(self) -> None:
        """With the optimal gain the Joseph form equals (I − KH)P."""
        rng = np.random.default_rng(5)
        P = _random_spd(3, rng)
        h = rng.normal(size=3)
        model = KalmanModel.of(np.eye(3), h[None, :], np.zeros((3, 3)), [[0.3]])
        new, _ = update(make_state(np.zeros(3), P), 1.0, model)
        K = P @ h / (h @ P @ h + 0.3)
        np.testing.assert_allclose(new.P, (np.eye(3) - np.outer(K, h)) @ P, atol=1e-12)

    def test_free_mask_holds_states(self) -> None:
        """States marked not free keep their mean; P stays symmetric positive definite."""
        rng = np.random.default_rng(6)
        P = _random_spd(3, rng)
        model = KalmanModel.of(np.eye(3), [[1.0, 2.0, 1.0]], np.zeros((3, 3)), [[0.1]])
        new, _ = update(make_state([1.0, 0.1, 0.2], P), 5.0, model, free=[True, False, False])
        assert new.x[1:] == pytest.approx([0.1, 0.2])
        assert np.all(np.linalg.eigvalsh(new.P) > 0.0)
        np.testing.assert_array_equal(new.P, new.P.T)

    def test_make_state_rejects_bad_P(self) -> None:
        """A covariance of the wrong shape or not positive definite raises ModelError."""
        with pytest.raises(ModelError):
            make_state([0.0, 0.0], np.eye(3))
        with pytest.raises(ModelError):
            make_state([0.0], [[-1.0]])
