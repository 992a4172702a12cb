"""The two-axis error model: misalignment, transverse scale and bias, a shared current."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import DataError, ModelError
from calib.models import CURRENT, Params
from calib.twoaxis import (
    ALPHA,
    B_T,
    M_T,
    TwoAxisFit,
    TwoAxisParams,
    TwoAxisSeries,
    current_basis,
    fit_current_two_axis,
    fit_two_axis,
    water_velocity,
)
from calib.twoaxis_kf import kf_two_axis
from tests.synth import TWO_AXIS_CURRENT_NE, TWO_AXIS_TRUTH, two_axis_series, two_axis_trial


def _fit(d: dict[str, np.ndarray], model: str = "EM3") -> TwoAxisFit:
    return fit_two_axis(model, two_axis_series(d))


class TestLeastSquares:
    @pytest.mark.parametrize("seed", [3, 15, 16])
    def test_three_degrees_recovered_on_figure8(self, seed: int) -> None:
        """α = 3° within 0.3° on the figure-8; the current shared by both axes."""
        fit = _fit(two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=seed))
        assert ALPHA in fit.ident.determined, fit.ident.reason
        assert fit.misalign_deg == pytest.approx(3.0, abs=0.3)
        assert fit.misalign_std_deg is not None and fit.misalign_std_deg < 0.15
        assert fit.current_mps == pytest.approx(TWO_AXIS_CURRENT_NE, abs=0.01)
        assert fit.params.b_t_mps == pytest.approx(0.04, abs=0.01)

    def test_half_a_figure8_determines_alpha(self) -> None:
        """13 minutes of figure-8 (α's σ about 0.18°, above the 27 minutes' 0.12°)
        still determine α within 0.3°: the rule's bound leaves room for a trial whose
        noise draws a larger σ, and for the daemon's window before the whole
        figure-8 is in."""
        fit = _fit(two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=4, n=8000))
        assert ALPHA in fit.ident.determined, fit.ident.reason
        assert fit.misalign_std_deg is not None and 0.15 < fit.misalign_std_deg < 0.25
        assert fit.misalign_deg == pytest.approx(3.0, abs=0.3)

    def test_figure8_determines_transverse_scale(self) -> None:
        """The figure-8's alternating turns swing the sway: the transverse scale is learnt."""
        fit = _fit(two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=4))
        assert M_T in fit.ident.determined
        assert fit.params.m_t == pytest.approx(-0.09, abs=0.05)

    def test_circles_refuse_misalignment_with_transverse_scale(self) -> None:
        """In steady circles the sway follows the surge: the transverse scale is not
        determined and α is refused with it (its signature is (1 + m_t)·sin α·u);
        the transverse scale and bias are held at the prior's 0, the bias with the
        reason (without α it would take the phantom leeway at these speeds)."""
        fit = _fit(two_axis_trial("circles", TWO_AXIS_TRUTH, seed=5))
        assert M_T in fit.ident.unidentifiable and ALPHA in fit.ident.unidentifiable
        why = fit.ident.verdict(ALPHA).reason
        assert why.startswith("misalignment not determinable: a misalignment and a transverse")
        assert (
            "at every speed: one steady turn (one turn rate throughout" in why
            and "(a figure-8)" in why
        )
        assert fit.params.m_t == 0.0 and fit.params.b_t_mps == 0.0
        assert fit.misalign_deg == 0.0
        assert fit.stderr[M_T] is None and fit.stderr[B_T] is None
        assert fit.ident.verdict(B_T).reason.startswith(
            "transverse bias held at +0 m/s: without the misalignment"
        )
        assert "sway follows the surge" in fit.ident.verdict(M_T).reason

    @pytest.mark.parametrize("method", ["ls", "kf"])
    def test_nothing_learnt_without_alpha_makes_the_athwart_speed_worse_than_raw(
        self, method: str
    ) -> None:
        """Trained on one-way circles (α refused), the figures applied to a figure-8
        leave its athwart reading as read: never worse than raw, by least squares and
        by the filter. Before, the transverse scale held at the forward one (−0.11)
        and the bias fitted with α held made it worse than raw there."""
        d = two_axis_trial("circles", TWO_AXIS_TRUTH, seed=5, n=6000)
        fit = _fit(d) if method == "ls" else kf_two_axis("EM3", d["t"], two_axis_series(d))
        assert ALPHA in fit.ident.unidentifiable
        e8 = two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=6, n=6000)
        _, w = fit.params.correct(e8["rl"], e8["rt"])
        assert np.array_equal(w, e8["rt"])
        fitted = fit_two_axis("EM3", two_axis_series(d), hold=False)  # as it was reported
        assert fitted.params.m_t == fitted.params.longitudinal.m
        _, w_fitted = fitted.params.correct(e8["rl"], e8["rt"])

        def rms(x: np.ndarray) -> float:
            return float(np.sqrt(np.mean((x - e8["w"]) ** 2)))

        assert rms(w_fitted) > rms(e8["rt"])

    def test_a_held_transverse_figure_is_the_priors(self) -> None:
        """With a prior, α refused holds the transverse scale and bias at the prior's."""
        prior = TwoAxisParams(Params("EM3"), 0.0, -0.05, 0.02)
        d = two_axis_trial("circles", TWO_AXIS_TRUTH, seed=5, n=6000)
        fit = fit_two_axis("EM3", two_axis_series(d), prior=prior)
        assert (fit.params.m_t, fit.params.b_t_mps) == (-0.05, 0.02)
        assert "held at +0.02 m/s" in fit.ident.verdict(B_T).reason

    @pytest.mark.parametrize("seed", [6, 17, 18])
    def test_zero_misalignment_within_sigma(self, seed: int) -> None:
        """An aligned sensor on the figure-8: α estimated as 0 within 2σ."""
        aligned = TwoAxisParams(
            TWO_AXIS_TRUTH.longitudinal, 0.0, TWO_AXIS_TRUTH.m_t, TWO_AXIS_TRUTH.b_t_mps
        )
        fit = _fit(two_axis_trial("figure-8", aligned, seed=seed))
        assert fit.misalign_std_deg is not None
        assert abs(fit.misalign_deg) < 2.0 * fit.misalign_std_deg

    def test_straight_run_refuses_misalignment(self) -> None:
        """A straight run: α, the transverse bias and the current refused, with reasons."""
        fit = _fit(two_axis_trial("straight", TWO_AXIS_TRUTH, seed=7))
        for k in (ALPHA, B_T, CURRENT):
            assert k in fit.ident.unidentifiable
        assert fit.misalign_std_deg is None
        assert fit.misalign_deg == 0.0
        assert "misalignment not separable from the transverse bias" in fit.ident.reason
        assert "heading covered" in fit.ident.reason

    def test_prior_held_on_straight_run(self) -> None:
        """A refused α is held at the prior's."""
        prior = TwoAxisParams(Params("EM3", m=-0.1), math.radians(2.0))
        d = two_axis_trial("straight", TWO_AXIS_TRUTH, seed=8)
        fit = fit_two_axis("EM3", two_axis_series(d), prior=prior)
        assert fit.misalign_deg == pytest.approx(2.0)

    def test_bad_series_refused(self) -> None:
        with pytest.raises(DataError, match="same length"):
            TwoAxisSeries.of([1.0, 2.0], [0.0], [1.0, 2.0], [0.0, 0.0], [0.0, 0.0])
        with pytest.raises(DataError, match="finite"):
            TwoAxisSeries.of([math.nan], [0.0], [1.0], [0.0], [0.0])
        with pytest.raises(DataError, match="no samples"):
            TwoAxisSeries.of([], [], [], [], [])
        with pytest.raises(ModelError):
            fit_two_axis("EM9", TwoAxisSeries.of([1.0], [0.0], [1.0], [0.0], [0.0]))

    def test_to_dict_carries_misalignment(self) -> None:
        fit = _fit(two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=9))
        d = fit.to_dict()
        assert d["misalign_deg"] == fit.misalign_deg
        assert d["misalign_std_deg"] == fit.misalign_std_deg
        params = d["params"]
        assert isinstance(params, dict)
        assert set(params) == {"m", "b", "misalign_deg", "m_t", "b_t"}


def test_fit_current_with_frozen_params() -> None:
    """The true parameters frozen: the current of the segment, on a straight run too
    (both axes see it); linear between knots it follows a current that turns."""
    for kind in ("circles", "straight"):
        d = two_axis_trial(kind, TWO_AXIS_TRUTH, seed=12)
        cur = fit_current_two_axis(TWO_AXIS_TRUTH, two_axis_series(d))
        assert cur.shape == (d["t"].size, 2)
        assert cur[0] == pytest.approx(TWO_AXIS_CURRENT_NE, abs=0.005)
    d = two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=12)
    turn = 0.1 * np.sin(2.0 * math.pi * d["t"] / d["t"][-1])  # north current grows, falls
    psi = np.radians(d["hd"])
    gf = d["gf"] + turn * np.cos(psi)
    gs = d["gs"] - turn * np.sin(psi)
    cur = fit_current_two_axis(
        TWO_AXIS_TRUTH,
        TwoAxisSeries.of(gf, gs, d["rl"], d["rt"], d["hd"]),
        t_s=d["t"],
        current_knot_s=120.0,
    )
    assert np.max(np.abs(cur[:, 0] - (TWO_AXIS_CURRENT_NE[0] + turn))) < 0.02
    assert current_basis(d["t"][:10], 10, 300.0) is None


def test_dead_transverse_axis_refused_by_envelope() -> None:
    """A transverse axis that reads nothing would take a gain of zero (m_t = −1): the
    transverse scale is refused as outside the envelope and held."""
    d = two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=13)
    fit = fit_two_axis(
        "EM3", TwoAxisSeries.of(d["gf"], d["gs"], d["rl"], np.zeros_like(d["rt"]), d["hd"])
    )
    assert M_T in fit.ident.unidentifiable
    assert "transverse scale outside the envelope" in fit.ident.reason
    assert fit.params.m_t == 0.0 and fit.params.b_t_mps == 0.0


def test_water_frame_reference_determines_both_biases() -> None:
    """A reference already in the water frame (no current unknown): both biases learnt."""
    d = two_axis_trial("figure-8", TWO_AXIS_TRUTH, seed=14)
    u, w = water_velocity(d["gf"], d["gs"], d["hd"], TWO_AXIS_CURRENT_NE)
    fit = fit_two_axis("EM3", TwoAxisSeries.of(u, w, d["rl"], d["rt"], d["hd"]), current=False)
    assert fit.identifiable, fit.ident.reason
    assert fit.params.b_t_mps == pytest.approx(0.04, abs=0.01)
    assert fit.params.longitudinal.b_mps == pytest.approx(-0.05, abs=0.02)


def test_current_basis_leaves_out_knots_without_samples() -> None:
    """Two captures an hour apart: the knots in between carry no sample and are left
    out, each row still sums to 1 (a fit on both captures is not singular)."""
    t = np.concatenate([np.arange(0.0, 1200.0, 1.0), np.arange(4800.0, 6000.0, 1.0)])
    basis = current_basis(t, t.size, 300.0)
    assert basis is not None
    assert basis.shape[1] == 10  # 5 knots over each capture's 1200 s, none between
    np.testing.assert_allclose(basis.sum(axis=1), 1.0)
    assert np.all(basis.sum(axis=0) > 0.05 * basis.sum(axis=0).max())
