"""One estimate value: least squares and the filter hold it and read it as their own."""

from __future__ import annotations

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.kalman.batch import run_kf
from calib.lsq import fit_ls
from calib.models import Params, forward_array


def _series(n: int = 600) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A reference speed that varies and an EM3 log reading it (m = 0.1, b = 0.05)."""
    t = np.arange(n, dtype=np.float64)
    ref = 2.0 + np.sin(2.0 * np.pi * t / 120.0)
    raw = forward_array(Params("EM3", m=0.1, b_mps=0.05), ref)
    rng = np.random.default_rng(4)
    return t, ref, raw + rng.normal(0.0, 0.01, n)


def test_an_estimate_names_its_model() -> None:
    """Estimate.model is its parameters' model; the current is absent unless given."""
    e = Estimate(Params("EM4", a_spm=0.01), {"a": 0.001, "m": None, "b": None})
    assert e.model == "EM4" and e.current_mps is None and e.current_std_mps is None


@pytest.mark.parametrize("method", ["ls", "kf"])
def test_least_squares_and_the_filter_read_their_estimate(method: str) -> None:
    """LsFit and KfRun carry one Estimate: params, param_std, current and model read
    through it, and it holds the fit (m and b near the truth, each with a σ)."""
    t, ref, raw = _series()
    fit = fit_ls("EM3", ref, raw) if method == "ls" else run_kf("EM3", t, raw, ref, history=False)
    e = fit.estimate
    assert isinstance(e, Estimate)
    assert fit.params is e.params and fit.param_std is e.param_std
    assert fit.current_mps is e.current_mps is None and fit.model == e.model == "EM3"
    assert e.params.m == pytest.approx(0.1, abs=0.02)
    assert e.params.b_mps == pytest.approx(0.05, abs=0.05)
    assert set(e.param_std) == {"m", "b"} and all(v is not None for v in e.param_std.values())
