"""Error models EM1–EM4: forward model, design rows and inverse correction."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from calib.errors import ModelError
from calib.models import (
    MODEL_NAMES,
    Layout,
    Params,
    check_model,
    correct_array,
    design_matrix,
    design_row,
    forward_array,
    n_params,
    zero_params,
)

ENVELOPE_MPS = np.linspace(-1.0, 10.0, 2001)
"""Speeds through water covered by the round-trip tests (astern to ~20 kn)."""

CASES = [
    Params("EM1", b_mps=0.12),
    Params("EM2", m=-0.07),
    Params("EM3", m=0.05, b_mps=-0.1),
    Params("EM4", a_spm=0.02, m=0.05, b_mps=0.1),
    Params("EM4", a_spm=-0.015, m=-0.03, b_mps=0.2),
    Params("EM4", a_spm=1e-12, m=0.01, b_mps=0.0),
]


class TestParams:
    """The frozen parameter dataclass."""

    def test_frozen_and_slotted(self) -> None:
        """Params cannot be modified and have no __dict__."""
        p = Params("EM3", m=0.1)
        with pytest.raises(dataclasses.FrozenInstanceError):
            p.m = 0.2  # type: ignore[misc]
        assert not hasattr(p, "__dict__")

    def test_unused_parameter_rejected(self) -> None:
        """A non-zero parameter the model does not have raises ModelError."""
        with pytest.raises(ModelError, match="no parameter a"):
            Params("EM3", a_spm=0.1)

    def test_non_finite_rejected(self) -> None:
        """A nan parameter raises ModelError."""
        with pytest.raises(ModelError, match="not finite"):
            Params("EM1", b_mps=math.nan)

    def test_unknown_model(self) -> None:
        """An unknown model name raises ModelError listing the valid names."""
        with pytest.raises(ModelError, match="EM1, EM2, EM3, EM4"):
            check_model("EM5")

    @pytest.mark.parametrize("params", CASES)
    def test_theta_round_trip(self, params: Params) -> None:
        """from_theta(theta) rebuilds the same parameters."""
        assert Params.from_theta(params.model, params.theta) == params

    def test_theta_order_and_dict(self) -> None:
        """θ follows the paper's order [a, m, b] and as_dict uses the short names."""
        p = Params("EM4", a_spm=1.0, m=2.0, b_mps=3.0)
        assert p.theta == (1.0, 2.0, 3.0)
        assert p.as_dict() == {"a": 1.0, "m": 2.0, "b": 3.0}
        assert [n_params(m) for m in MODEL_NAMES] == [1, 1, 2, 3]

    def test_from_theta_wrong_length(self) -> None:
        """A θ of the wrong length raises ModelError."""
        with pytest.raises(ModelError, match="takes 2"):
            Params.from_theta("EM3", (1.0,))

    def test_zero_params_is_identity(self) -> None:
        """The ideal sensor reads the true speed."""
        assert zero_params("EM4").forward(1.7) == 1.7


class TestForwardAndDesign:
    """measured = f(true) and the linear-in-θ error."""

    @pytest.mark.parametrize("params", CASES)
    def test_error_is_design_row_times_theta(self, params: Params) -> None:
        """raw − v equals h(v)·θ for every model (eqs. (18)–(21))."""
        v = ENVELOPE_MPS
        H = design_matrix(params.model, v)
        np.testing.assert_allclose(forward_array(params, v) - v, H @ params.theta, atol=1e-12)
        for vk in (0.3, 2.0, 7.5):
            row = design_row(params.model, vk)
            assert params.forward(vk) - vk == pytest.approx(np.dot(row, params.theta), abs=1e-12)

    def test_paper_formulas(self) -> None:
        """EM3 is (1+m)v + b and EM4 adds a·v²."""
        assert Params("EM3", m=0.1, b_mps=0.2).forward(2.0) == pytest.approx(2.4)
        assert Params("EM4", a_spm=0.5, m=0.1, b_mps=0.2).forward(2.0) == pytest.approx(4.4)


class TestInverse:
    """correct() is the inverse of forward() over the speed envelope."""

    @pytest.mark.parametrize("params", CASES)
    def test_round_trip_array(self, params: Params) -> None:
        """correct(f(v)) == v to 1e-9 (vectorised)."""
        back = correct_array(params, forward_array(params, ENVELOPE_MPS))
        np.testing.assert_allclose(back, ENVELOPE_MPS, rtol=0.0, atol=1e-9)

    @pytest.mark.parametrize("params", CASES)
    def test_round_trip_scalar(self, params: Params) -> None:
        """correct(f(v)) == v to 1e-9 (scalar fast path)."""
        err = max(abs(params.correct(params.forward(v)) - v) for v in ENVELOPE_MPS.tolist())
        assert err < 1e-9

    def test_em4_no_real_root_gives_vertex(self) -> None:
        """Beyond the parabola's extremum the correction is the vertex −(1+m)/(2a)."""
        p = Params("EM4", a_spm=-0.05, m=0.0, b_mps=0.0)
        vertex = -1.0 / (2.0 * -0.05)  # 10 m/s, where f peaks at 5 m/s
        assert p.correct(6.0) == pytest.approx(vertex)
        assert correct_array(p, np.array([6.0]))[0] == pytest.approx(vertex)

    def test_zero_gain_gives_nan(self) -> None:
        """A model with 1+m ≤ 0 cannot be inverted: the correction is nan."""
        for m in (-1.0, -1.5):
            p = Params("EM4", a_spm=0.01, m=m)
            assert math.isnan(p.correct(1.0))
            assert np.isnan(correct_array(p, np.array([1.0]))[0])

    def test_em4_takes_the_increasing_branch(self) -> None:
        """EM4's correction is the root where f increases: 1.9 m/s is never corrected to 1.11."""
        p = Params("EM4", a_spm=0.3, m=-0.2, b_mps=0.1)
        v = p.correct(1.9)
        assert p.forward(v) == pytest.approx(1.9) and 2 * 0.3 * v + 0.8 > 0
        assert correct_array(p, np.array([1.9]))[0] == pytest.approx(v)

    def test_scalar_and_array_agree(self) -> None:
        """The scalar and vectorised inverses pick the same root everywhere."""
        rng = np.random.default_rng(7)
        raw = rng.uniform(-5.0, 40.0, 500)
        for p in CASES:
            np.testing.assert_allclose(
                correct_array(p, raw), [p.correct(r) for r in raw.tolist()], atol=1e-12
            )


class TestLayout:
    """The unknowns of a calibration and the filter's states."""

    def test_names_and_indices(self) -> None:
        """EM3 with current: states v, m, b, c_N, c_E; the current has two indices."""
        lay = Layout("EM3", current=True)
        assert lay.unknowns == ("m", "b", "current")
        assert lay.states == ("v_mps", "m", "b", "c_north_mps", "c_east_mps")
        assert lay.n == 5 and lay.indices("current") == (3, 4) and lay.indices("b") == (2,)

    def test_an_unknown_the_layout_lacks_raises(self) -> None:
        """Asking EM2 for b, or a layout without current for the current, raises ModelError."""
        with pytest.raises(ModelError):
            Layout("EM2").indices("b")
        with pytest.raises(ModelError):
            Layout("EM3").indices("current")
