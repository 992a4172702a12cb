"""Batch least squares LS-EM1..LS-EM4."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import DataError, ModelError
from calib.lsq import Averaged, block_average, current_blocks, fit_current, fit_ls
from calib.models import Params, forward_array
from tests.synth import TrajectoryKind, WaterFrameSeries, water_frame_segment


def _varying(n: int = 600, seed: int = 1) -> tuple[np.ndarray, np.random.Generator]:
    """Ten minutes at 1 Hz of a vessel sweeping 0.5–4.5 m/s (period 2 min)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64)
    return 2.5 + 2.0 * np.sin(2.0 * np.pi * t / 120.0), rng


class TestRecovery:
    """The fits recover the simulated parameters."""

    def test_ls_em3_recovers_m_and_b(self) -> None:
        """10 min of 1 Hz varying-speed data with σ = 0.05 m/s: m within 0.005, b within 0.01 m/s."""
        v, rng = _varying()
        raw = forward_array(Params("EM3", m=0.05, b_mps=0.1), v) + rng.normal(0.0, 0.05, v.size)
        fit = fit_ls("EM3", v, raw)
        assert abs(fit.params.m - 0.05) < 0.005
        assert abs(fit.params.b_mps - 0.1) < 0.01
        assert fit.identifiable and fit.unidentifiable == ()
        assert fit.rmse_mps == pytest.approx(0.05, rel=0.1)

    def test_ls_em4_recovers_curvature(self) -> None:
        """On data with curvature LS-EM4 recovers a, m and b within 3 standard errors."""
        v, rng = _varying(seed=2)
        truth = Params("EM4", a_spm=0.03, m=0.02, b_mps=0.05)
        raw = forward_array(truth, v) + rng.normal(0.0, 0.05, v.size)
        fit = fit_ls("EM4", v, raw)
        for name, true in truth.as_dict().items():
            se = fit.param_std[name]
            assert se is not None and abs(fit.params.as_dict()[name] - true) < 3.0 * se
        assert abs(fit.params.a_spm - 0.03) < 0.005

    @pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
    def test_noise_free_exact(self, model: str) -> None:
        """Without noise every model recovers its own parameters to 1e-9."""
        v, _ = _varying()
        theta = {"EM1": (0.1,), "EM2": (0.04,), "EM3": (0.04, 0.1), "EM4": (0.01, 0.04, 0.1)}
        truth = Params.from_theta(model, theta[model])
        fit = fit_ls(model, v, forward_array(truth, v))
        np.testing.assert_allclose(fit.params.theta, truth.theta, atol=1e-9)

    def test_matches_normal_equations(self) -> None:
        """θ̂ equals the paper's eq. (2) solution on well-conditioned data."""
        v, rng = _varying()
        raw = 1.03 * v - 0.05 + rng.normal(0.0, 0.05, v.size)
        H = np.column_stack([v, np.ones_like(v)])
        theta = np.linalg.solve(H.T @ H, H.T @ (raw - v))
        np.testing.assert_allclose(fit_ls("EM3", v, raw).params.theta, theta, rtol=1e-10)

    def test_standard_errors(self) -> None:
        """Standard errors equal √diag(σ̂²(HᵀH)⁻¹) with σ̂² = RSS/(N − p)."""
        v, rng = _varying()
        raw = 1.03 * v - 0.05 + rng.normal(0.0, 0.05, v.size)
        fit = fit_ls("EM3", v, raw)
        H = np.column_stack([v, np.ones_like(v)])
        r = raw - v - H @ np.array(fit.params.theta)
        cov = (r @ r) / (v.size - 2) * np.linalg.inv(H.T @ H)
        m_std, b_std = fit.param_std["m"], fit.param_std["b"]
        assert m_std is not None and b_std is not None
        np.testing.assert_allclose([m_std, b_std], np.sqrt(np.diag(cov)), rtol=1e-8)
        assert fit.cond_info == pytest.approx(np.linalg.cond(H.T @ H), rel=1e-6)


class TestWeights:
    """Weighted least squares."""

    def test_weights_match_row_scaling(self) -> None:
        """Weights w give the same θ̂ as ordinary LS on rows scaled by √w."""
        v, rng = _varying()
        raw = 1.03 * v - 0.05 + rng.normal(0.0, 0.05, v.size)
        w = rng.uniform(0.2, 3.0, v.size)
        H = np.column_stack([v, np.ones_like(v)]) * np.sqrt(w)[:, None]
        theta = np.linalg.lstsq(H, (raw - v) * np.sqrt(w), rcond=None)[0]
        np.testing.assert_allclose(fit_ls("EM3", v, raw, w).params.theta, theta, rtol=1e-9)

    def test_uniform_weights_change_nothing(self) -> None:
        """Scaling all weights by a constant leaves θ̂ and its standard errors unchanged."""
        v, rng = _varying()
        raw = 1.03 * v - 0.05 + rng.normal(0.0, 0.05, v.size)
        a, b = fit_ls("EM3", v, raw), fit_ls("EM3", v, raw, np.full(v.size, 7.0))
        np.testing.assert_allclose(a.params.theta, b.params.theta, rtol=1e-10)
        for k in ("m", "b"):
            assert a.param_std[k] == pytest.approx(b.param_std[k], rel=1e-9)

    def test_bad_weights(self) -> None:
        """Negative or wrongly shaped weights raise DataError."""
        v, _ = _varying(10)
        with pytest.raises(DataError):
            fit_ls("EM3", v, v, -np.ones(10))
        with pytest.raises(DataError):
            fit_ls("EM3", v, v, np.ones(9))


class TestIdentifiability:
    """Only what the data determine is estimated; the rest stays at its prior."""

    def test_constant_speed_holds_the_scale_at_its_prior(self) -> None:
        """LS-EM3 at constant speed: m not determined and held at 0, b takes the mean error."""
        rng = np.random.default_rng(3)
        v = np.full(600, 2.0)
        raw = 1.05 * v + 0.1 + rng.normal(0.0, 0.05, v.size)
        fit = fit_ls("EM3", v, raw)
        assert fit.unidentifiable == ("m",) and not fit.identifiable
        assert "speed through water nearly constant" in fit.reason
        assert fit.params.m == 0.0 and fit.param_std["m"] is None
        assert fit.params.forward(2.0) == pytest.approx(float(np.mean(raw)), abs=1e-9)

    def test_a_given_prior_is_where_an_undetermined_unknown_stays(self) -> None:
        """With a prior the undetermined scale stays at the prior's value."""
        v = np.full(600, 2.0)
        fit = fit_ls("EM3", v, 1.05 * v + 0.1, prior=Params("EM3", m=0.05))
        assert fit.params.m == 0.05
        assert fit.params.b_mps == pytest.approx(0.1, abs=1e-9)

    def test_excitation_is_judged_on_the_readings(self) -> None:
        """A reference that wobbles while the reading is flat excites no scale."""
        rng = np.random.default_rng(4)
        v = 2.0 + rng.normal(0.0, 0.3, 600)
        fit = fit_ls("EM3", v, np.full(600, 2.2))
        assert not fit.identifiable and "constant" in fit.reason

    def test_em1_identifiable_at_constant_speed(self) -> None:
        """The bias alone is identifiable without any speed variation."""
        v = np.full(100, 2.0)
        fit = fit_ls("EM1", v, v + 0.2)
        assert fit.identifiable
        assert fit.params.b_mps == pytest.approx(0.2)


class TestWaterFrame:
    """Fits with the current: the sensor's parameters, not the sea's."""

    TRUTH = Params("EM3", m=0.09, b_mps=0.08)
    CURRENT = (-0.091, -0.066)

    def _segment(
        self, kind: TrajectoryKind, *, constant: bool = False, seed: int = 7
    ) -> WaterFrameSeries:
        return water_frame_segment(
            kind,
            1620.0,
            1.0,
            self.TRUTH,
            np.random.default_rng(seed),
            current_mps=self.CURRENT,
            constant_speed=constant,
        )

    def test_figure8_recovers_the_sensor_and_the_current(self) -> None:
        """On a figure-8: m within 0.02, b within 0.03 m/s, the current within 0.03 m/s."""
        s = self._segment("figure-8")
        fit = fit_ls("EM3", s.ref_mps, s.raw_mps, heading_deg=s.heading_deg, current=True)
        assert fit.identifiable
        assert fit.params.m == pytest.approx(0.09, abs=0.02)
        assert fit.params.b_mps == pytest.approx(0.08, abs=0.03)
        assert fit.current_mps == pytest.approx(self.CURRENT, abs=0.03)
        assert fit.current_std_mps is not None and max(fit.current_std_mps) < 0.01

    def test_without_the_current_the_fit_is_the_currents(self) -> None:
        """The paper's fit of the same figure-8 puts the current into b (off by > 0.03 m/s)."""
        s = self._segment("figure-8")
        fit = fit_ls("EM3", s.ref_mps, s.raw_mps)
        assert abs(fit.params.b_mps - 0.08) > 0.03 or abs(fit.params.m - 0.09) > 0.02

    def test_circles_at_constant_speed_give_the_current_but_no_scale(self) -> None:
        """Constant-speed circles: the current is right and the scale is declared undetermined."""
        s = self._segment("circles", constant=True)
        fit = fit_ls("EM3", s.ref_mps, s.raw_mps, heading_deg=s.heading_deg, current=True)
        assert fit.unidentifiable == ("m",)
        assert fit.current_mps == pytest.approx(self.CURRENT, abs=0.03)

    def test_a_straight_line_reports_neither_bias_nor_current(self) -> None:
        """A straight line: bias and current unidentifiable; b stays at its prior, no current."""
        s = self._segment("straight")
        fit = fit_ls(
            "EM3",
            s.ref_mps,
            s.raw_mps,
            heading_deg=s.heading_deg,
            current=True,
            prior=Params("EM3", b_mps=0.05),
        )
        assert {"b", "current"} <= set(fit.unidentifiable)
        assert fit.params.b_mps == 0.05 and fit.current_mps is None
        assert "heading covered 1 of 8 sectors" in fit.reason

    def test_the_current_needs_a_heading(self) -> None:
        """A current fit without headings raises DataError."""
        with pytest.raises(DataError, match="heading"):
            fit_ls("EM3", np.ones(50), np.ones(50), current=True)

    def test_fit_current_with_frozen_parameters(self) -> None:
        """fit_current finds the segment's current with the sensor's parameters frozen."""
        s = self._segment("circles", constant=True)
        cur = fit_current(self.TRUTH, s.ref_mps, s.raw_mps, s.heading_deg)
        assert cur == pytest.approx(self.CURRENT, abs=0.02)
        s = self._segment("straight")
        assert fit_current(self.TRUTH, s.ref_mps, s.raw_mps, s.heading_deg) is None


class TestInterface:
    """Validation and serialisation."""

    def test_mismatched_lengths(self) -> None:
        """ref and raw of different lengths raise DataError."""
        with pytest.raises(DataError, match="equal length"):
            fit_ls("EM3", np.ones(5), np.ones(6))

    def test_nan_rejected(self) -> None:
        """Non-finite samples raise DataError."""
        with pytest.raises(DataError, match="finite"):
            fit_ls("EM3", np.array([1.0, np.nan, 2.0]), np.ones(3))

    def test_unknown_model(self) -> None:
        """An unknown model raises ModelError."""
        with pytest.raises(ModelError):
            fit_ls("EM9", np.ones(5), np.ones(5))


class TestBlockAverage:
    """Block means: a noisy reference no longer shrinks the scale."""

    def test_noisy_reference_scale_recovered(self) -> None:
        """σ 0.3 m/s on the reference: per-sample LS is ~8 % low, 20-s means are not."""
        rng = np.random.default_rng(7)
        t = np.arange(0.0, 6 * 3600.0, 1.0)
        u = 2.5 + np.sin(2 * np.pi * t / 400.0) * 1.2 + 0.3 * np.sin(2 * np.pi * t / 1700.0)
        raw = 1.05 * u + 0.1 + rng.normal(0.0, 0.05, t.size)
        ref = u + rng.normal(0.0, 0.3, t.size)
        per_sample = fit_ls("EM3", ref, raw)
        assert per_sample.params.m < 0.0  # the shrinkage the averaging exists for
        avg = block_average(t, raw, ref, None, 20.0)
        fit = fit_ls("EM3", avg.ref, avg.raw)
        assert fit.params.m == pytest.approx(0.05, abs=0.01)
        assert fit.params.b_mps == pytest.approx(0.1, abs=0.03)

    def test_blocks_with_a_turn_gap_or_too_few_samples_are_dropped(self) -> None:
        """A block turning through 180°, one across a gap, one nearly empty: gone."""
        t = np.concatenate([np.arange(0.0, 40.0), np.arange(50.0, 60.0), [100.0]])
        hd = np.where(t < 20.0, 90.0, 0.0)
        hd[(t >= 20.0) & (t < 40.0)] = np.linspace(0.0, 180.0, 20)  # a U-turn
        x = np.ones_like(t)
        avg = block_average(t, x, 2 * x, hd, 20.0)
        # kept: [0, 20) steady at 90° and [50, 60) (half of a block, after the gap);
        # dropped: the U-turn [20, 40) and the lone sample at 100 s
        assert avg.t.tolist() == pytest.approx([9.5, 54.5])
        assert avg.heading_deg.tolist() == pytest.approx([90.0, 0.0])
        assert avg.raw.tolist() == [1.0, 1.0] and avg.ref.tolist() == [2.0, 2.0]

    def test_bad_input(self) -> None:
        """Different lengths, a bad window or decreasing times are refused."""
        with pytest.raises(DataError):
            block_average([0.0, 1.0], [1.0], [1.0, 2.0], None, 10.0)
        with pytest.raises(DataError):
            block_average([0.0, 1.0], [1.0, 1.0], [1.0, 2.0], None, 0.0)
        with pytest.raises(DataError):
            block_average([1.0, 0.0], [1.0, 1.0], [1.0, 2.0], None, 10.0)


def test_stderr_counts_correlated_residuals_as_fewer_samples() -> None:
    """AR(1) residuals (ρ 0.9) inflate the standard errors by about √19 over white ones."""
    rng = np.random.default_rng(5)
    n = 4000
    ref = 2.0 + np.sin(np.arange(n) / 40.0)
    white = 0.05 * rng.standard_normal(n)
    ar = np.zeros(n)
    for k in range(1, n):
        ar[k] = 0.9 * ar[k - 1] + math.sqrt(1 - 0.81) * 0.05 * rng.standard_normal()
    fw = fit_ls("EM3", ref, 1.05 * ref + 0.1 + white)
    fa = fit_ls("EM3", ref, 1.05 * ref + 0.1 + ar)
    assert fw.correlation < 1.3
    assert fa.correlation > 8.0
    assert fa.param_std["m"] is not None and fw.param_std["m"] is not None
    assert fa.param_std["m"] > 3.0 * fw.param_std["m"]


class TestTidalCurrent:
    """A current that turns with the tide, seen through GNSS-like block means."""

    @staticmethod
    def _blocks(kind: TrajectoryKind, swing: float) -> tuple[Averaged, Params]:
        truth = Params("EM3", m=0.02, b_mps=0.1)
        s = water_frame_segment(
            kind,
            6 * 3600,
            1.0,
            truth,
            np.random.default_rng(4),
            current_mps=(0.2, 0.1),
            current_swing_mps=swing,
            sigma_ref_mps=0.3,
        )
        return block_average(s.t_s, s.raw_mps, s.ref_mps, s.heading_deg, 20.0), truth

    def test_blocks_and_weighted_speed_find_the_sensor(self) -> None:
        """Circles for 6 h in a current swinging 1 m/s: one current over the whole run and
        the reference's speed as regressor put m 0.9 off and b 1.6 off; a current per
        30 min and the variance-weighted speed recover m, b within 0.01 / 0.02."""
        a, truth = self._blocks("circles", 1.0)
        one = fit_ls(truth.model, a.ref, a.raw, heading_deg=a.heading_deg, current=True)
        assert one.params.m < truth.m - 0.5 and one.params.b_mps > truth.b_mps + 1.0
        fit = fit_ls(
            truth.model,
            a.ref,
            a.raw,
            heading_deg=a.heading_deg,
            current=True,
            t_s=a.t,
            current_block_s=1800.0,
            noise_ratio=0.3**2 / 0.05**2,
        )
        assert abs(fit.params.m - truth.m) < 0.01
        assert abs(fit.params.b_mps - truth.b_mps) < 0.02
        assert len(fit.current_blocks) == 12
        north = [c[1] for c in fit.current_blocks]
        assert max(north) - min(north) > 1.5  # the tide's swing, ±1 m/s north

    def test_blocks_without_headings_join_their_neighbour(self) -> None:
        """A block whose heading covers too few sectors joins the one before (the first: after)."""
        t = np.arange(0.0, 400.0)
        hd = np.where(t < 100, 10.0, (t * 7.0) % 360.0)
        hd = np.where((t >= 200) & (t < 300), 90.0, hd)
        ids = current_blocks(t, hd, 100.0, 3)
        assert ids[0] == ids[150] == ids[250] and ids[350] == ids[0] + 1
        with pytest.raises(DataError):
            current_blocks(None, hd, 100.0, 3)

    @staticmethod
    def _speed_follows_heading(
        seed: int = 5,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Params]:
        """Two half hours on three headings each, the speed through the water following
        the heading's cosine, +1 m/s in the first and −1 m/s in the second."""
        rng = np.random.default_rng(seed)
        truth = Params("EM3", m=0.05, b_mps=0.1)
        t = np.arange(0.0, 3600.0, 20.0)
        hd = np.array([0.0, 120.0, 240.0])[(t // 60.0 % 3).astype(int)]
        sign = np.where(t < 1800.0, 1.0, -1.0)
        u = 2.0 + sign * np.cos(np.radians(hd)) + rng.normal(0.0, 0.02, t.size)
        ref = u + 0.2 * np.cos(np.radians(hd)) + 0.1 * np.sin(np.radians(hd))
        raw = forward_array(truth, u) + rng.normal(0.0, 0.01, t.size)
        return t, ref, raw, hd, truth

    def test_a_scale_the_blocks_currents_take_is_held(self) -> None:
        """One current over the hour determines the scale (the speed's tie to the heading
        flips between the halves); a current per half hour takes it in each, so the fit
        with blocks holds the scale at its prior and says why."""
        t, ref, raw, hd, truth = self._speed_follows_heading()
        one = fit_ls("EM3", ref, raw, heading_deg=hd, current=True)
        assert "m" in one.ident.determined
        assert abs(one.params.m - truth.m) < 0.01
        fit = fit_ls("EM3", ref, raw, heading_deg=hd, current=True, t_s=t, current_block_s=1800.0)
        assert len(fit.current_blocks) == 2
        assert "m" not in fit.ident.determined
        assert fit.params.m == 0.0
        assert "with a current per block" in fit.reason
