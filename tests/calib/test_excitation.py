"""Excitation and the identifiability rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import DataError
from calib.excitation import ExcitationRule, ExcitationWindow, excitation


class TestExcitation:
    """Batch window excitation."""

    def test_em3_determinant_is_n_squared_variance(self) -> None:
        """det(HᵀH) = N²·var(v) for EM3 (paper eqs. (14)–(17))."""
        v = np.random.default_rng(1).uniform(1.0, 3.0, 500)
        ex = excitation("EM3", v)
        assert ex.det_info == pytest.approx(v.size**2 * np.var(v), rel=1e-9)
        expected = np.array([[np.sum(v * v), np.sum(v)], [np.sum(v), 500.0]])
        np.testing.assert_allclose(np.array(ex.info), expected, rtol=1e-12)
        assert ex.identifiable and ex.reason == ""

    def test_constant_speed_singular(self) -> None:
        """At constant speed EM3 and EM4 are rank 1 and not identifiable; EM1 is identifiable."""
        v = np.full(300, 1.8)
        for model in ("EM3", "EM4"):
            ex = excitation(model, v)
            assert ex.rank == 1 and not ex.identifiable and math.isinf(ex.cond_info)
        assert excitation("EM1", v).identifiable
        assert excitation("EM2", v).identifiable

    def test_em2_at_rest_not_identifiable(self) -> None:
        """A vessel at rest says nothing about the scale factor."""
        ex = excitation("EM2", np.random.default_rng(2).normal(0.0, 0.02, 300))
        assert not ex.identifiable and "scale factor" in ex.reason

    def test_too_few_samples(self) -> None:
        """Fewer than min_samples_per_param·p samples are not identifiable."""
        ex = excitation("EM3", np.linspace(1.0, 3.0, 15))
        assert not ex.identifiable and "few samples" in ex.reason

    def test_rule_thresholds_apply(self) -> None:
        """A stricter speed-std threshold turns an identifiable window into a rejected one."""
        v = np.linspace(1.0, 1.6, 200)  # std ≈ 0.17 m/s
        assert excitation("EM3", v).identifiable
        strict = ExcitationRule(min_speed_std_mps=0.5)
        assert not excitation("EM3", v, rule=strict).identifiable

    def test_em4_ill_conditioned(self) -> None:
        """EM4 over a very narrow speed band exceeds the condition-number limit."""
        v = np.random.default_rng(3).uniform(1.5, 1.85, 600)
        ex = excitation("EM4", v, rule=ExcitationRule(min_speed_std_mps=0.0, max_cond=1e6))
        assert not ex.identifiable and "ill-conditioned" in ex.reason

    def test_weights_scale_information(self) -> None:
        """Weights of 2 double the information matrix."""
        v = np.linspace(1.0, 3.0, 100)
        a = np.array(excitation("EM3", v).info)
        b = np.array(excitation("EM3", v, np.full(100, 2.0)).info)
        np.testing.assert_allclose(b, 2.0 * a)

    def test_rejects_empty(self) -> None:
        """An empty series raises DataError."""
        with pytest.raises(DataError):
            excitation("EM3", [])

    def test_rule_validation(self) -> None:
        """Nonsensical thresholds raise ValueError."""
        with pytest.raises(ValueError):
            ExcitationRule(max_cond=0.5)


class TestExcitationWindow:
    """The O(1) online tracker."""

    @pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
    def test_matches_batch_without_forgetting(self, model: str) -> None:
        """Without forgetting the window equals the batch excitation."""
        v = np.random.default_rng(4).uniform(0.5, 3.0, 400)
        win = ExcitationWindow()
        for vk in v.tolist():
            win.add(vk)
        online, batch = win.evaluate(model), excitation(model, v)
        np.testing.assert_allclose(online.info, batch.info, rtol=1e-12)
        assert online.cond_info == pytest.approx(batch.cond_info, rel=1e-5)
        assert online.identifiable == batch.identifiable
        assert online.speed_std_mps == pytest.approx(batch.speed_std_mps, rel=1e-9)

    def test_forgetting_tracks_recent_speed(self) -> None:
        """With a half-life the window forgets an old manoeuvre and flags a steady run."""
        win = ExcitationWindow(half_life_samples=60.0)
        for k in range(600):
            win.add(1.0 + 1.0 * math.sin(k / 10.0))
        assert win.evaluate("EM3").identifiable
        for _ in range(1200):
            win.add(2.0)
        ex = win.evaluate("EM3")
        assert not ex.identifiable
        assert win.n_effective == pytest.approx(60.0 / math.log(2.0), rel=0.02)

    def test_empty_window(self) -> None:
        """An empty window is not identifiable and does not raise."""
        assert not ExcitationWindow().evaluate("EM1").identifiable

    def test_reset(self) -> None:
        """reset() forgets everything."""
        win = ExcitationWindow()
        win.add(1.0)
        win.reset()
        assert win.n_effective == 0.0

    def test_bad_half_life(self) -> None:
        """A non-positive half-life raises ValueError."""
        with pytest.raises(ValueError):
            ExcitationWindow(half_life_samples=0.0)
