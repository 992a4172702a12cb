"""KF-EMx over recorded arrays."""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import DataError
from calib.kalman import run_kf
from calib.models import Params, forward_array


def _data(n: int, seed: int, truth: Params) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64)
    v = 2.0 + 0.8 * np.sin(2 * np.pi * t / 240.0)
    return t, forward_array(truth, v) + rng.normal(0, 0.05, n), v + rng.normal(0, 0.01, n)


class TestRunKf:
    """Batch runs over arrays."""

    def test_histories_have_shapes(self) -> None:
        """The run returns per-sample θ, σ and NIS series of the right shapes."""
        t, raw, ref = _data(200, 30, Params("EM3", m=0.05, b_mps=0.1))
        ref[50:60] = np.nan
        run = run_kf("EM3", t, raw, ref)
        assert run.theta.shape == (200, 2) and run.theta_std.shape == (200, 2)
        assert run.speed_mps.shape == (200,) and run.current.size == 0
        assert np.all(np.isnan(run.nis[50:60])) and np.all(np.isfinite(run.y))
        assert run.theta_std[-1, 0] < run.theta_std[0, 0]

    def test_current_histories(self) -> None:
        """With current states the run also returns the current and its σ per sample."""
        t, raw, ref = _data(200, 32, Params("EM3", m=0.05, b_mps=0.1))
        heading = (t * 3.0) % 360.0
        run = run_kf("EM3", t, raw, ref, heading_deg=heading, current=True)
        assert run.current.shape == (200, 2) and run.current_std.shape == (200, 2)
        assert run.current_mps is not None and run.current_std_mps is not None
        assert run.current_std[-1, 0] < run.current_std[0, 0]

    def test_history_off_gives_same_result(self) -> None:
        """history=False changes only the stored series, not the estimate."""
        t, raw, ref = _data(200, 31, Params("EM2", m=0.05))
        a = run_kf("EM2", t, raw, ref)
        b = run_kf("EM2", t, raw, ref, history=False)
        assert a.params == b.params and b.theta.size == 0

    def test_bad_input_raises(self) -> None:
        """Times that go backwards, or a current without headings, raise DataError."""
        with pytest.raises(DataError):
            run_kf("EM3", [0.0, 2.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0])
        with pytest.raises(DataError, match="heading"):
            run_kf("EM3", [0.0, 1.0], [1.0, 1.0], [1.0, 1.0], current=True)
