"""The two-axis model learnt by the extended Kalman filter."""

from __future__ import annotations

import pytest

from calib.twoaxis import ALPHA
from calib.twoaxis_kf import kf_two_axis
from tests.synth import TWO_AXIS_CURRENT_NE, TWO_AXIS_TRUTH, two_axis_trial


class TestKalman:
    def test_kf_recovers_three_degrees_on_figure8(self) -> None:
        """The filter, sample by sample: α within 0.3°, the current shared."""
        d = two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=10)
        fit = kf_two_axis("EM3", d["t"], d["gf"], d["gs"], d["rl"], d["rt"], d["hd"])
        assert fit.method == "KF"
        assert fit.misalign_deg == pytest.approx(3.0, abs=0.3)
        assert fit.misalign_std_deg is not None and fit.misalign_std_deg < 0.3
        assert fit.current_mps == pytest.approx(TWO_AXIS_CURRENT_NE, abs=0.02)

    def test_kf_holds_misalignment_on_straight_run(self) -> None:
        d = {k: v[::5] for k, v in two_axis_trial("straight", TWO_AXIS_TRUTH, seed=11).items()}
        fit = kf_two_axis("EM3", d["t"], d["gf"], d["gs"], d["rl"], d["rt"], d["hd"])
        assert ALPHA in fit.ident.unidentifiable
        assert fit.misalign_deg == 0.0
