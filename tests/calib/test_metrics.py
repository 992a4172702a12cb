"""RMSE, improvement and NIS statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import DataError
from calib.metrics import (
    IMO_MIN_ERROR_MPS,
    chi2_1_quantile,
    chi2_mean_bounds,
    correlation_factor,
    imo_bound_mps,
    imo_bound_one_mps,
    imo_verdict,
    improvement_pct,
    nis_stats,
    rmse,
    water_imo,
    water_rmse,
    water_scores,
    water_target,
    water_targets,
)
from calib.models import Params, correct_array, forward_array


class TestRmse:
    """RMSE and improvement (eq. (28))."""

    def test_known_value(self) -> None:
        """RMSE of errors 3 and 4 is √12.5."""
        assert rmse([0.0, 0.0], [3.0, 4.0]) == pytest.approx(math.sqrt(12.5))

    def test_ignores_nan(self) -> None:
        """nan pairs are skipped."""
        assert rmse([0.0, np.nan, 0.0], [1.0, 5.0, 1.0]) == pytest.approx(1.0)

    def test_errors(self) -> None:
        """Different shapes or no finite pair raise DataError."""
        with pytest.raises(DataError):
            rmse([1.0], [1.0, 2.0])
        with pytest.raises(DataError):
            rmse([np.nan], [1.0])

    def test_improvement(self) -> None:
        """0.576 → 0.167 m/s is the paper's 71 % improvement; worse is negative."""
        assert improvement_pct(0.576, 0.167) == pytest.approx(71.0, abs=0.1)
        assert improvement_pct(0.4, 0.5) == pytest.approx(-25.0)
        assert math.isnan(improvement_pct(0.0, 0.1))


class TestNis:
    """χ²(1) bounds and the consistency verdict."""

    def test_chi2_quantiles(self) -> None:
        """The 2.5 % and 97.5 % χ²(1) quantiles are 0.000982 and 5.024."""
        assert chi2_1_quantile(0.025) == pytest.approx(0.000982, rel=1e-3)
        assert chi2_1_quantile(0.975) == pytest.approx(5.0239, rel=1e-4)

    def test_mean_bounds(self) -> None:
        """χ²(1000)/1000 95 % bounds are about [0.914, 1.090] and shrink with n."""
        lo, hi = chi2_mean_bounds(1000)
        assert (lo, hi) == pytest.approx((0.9143, 1.0895), abs=2e-3)
        lo2, hi2 = chi2_mean_bounds(10000)
        assert lo < lo2 < 1.0 < hi2 < hi

    def test_true_chi2_samples_consistent(self) -> None:
        """Squared standard-normal samples are consistent with ~95 % inside."""
        nis = np.random.default_rng(1).normal(size=5000) ** 2
        st = nis_stats(nis)
        assert st.consistent
        assert st.frac_inside == pytest.approx(0.95, abs=0.01)
        assert st.mean == pytest.approx(1.0, abs=0.05)

    def test_overconfident_detected(self) -> None:
        """NIS samples 3× too large are flagged inconsistent."""
        nis = 3.0 * np.random.default_rng(2).normal(size=2000) ** 2
        assert not nis_stats(nis).consistent

    def test_skip_and_nan(self) -> None:
        """skip drops leading samples and nan samples are ignored."""
        st = nis_stats([100.0, np.nan, 1.0, 1.0], skip=1)
        assert st.n == 2 and st.mean == 1.0

    def test_errors(self) -> None:
        """No finite sample or a bad confidence raises DataError."""
        with pytest.raises(DataError):
            nis_stats([np.nan])
        with pytest.raises(DataError):
            nis_stats([1.0], confidence=1.5)


class TestWaterFrameAndCorrelation:
    """One water-frame RMSE and the residuals' correlation factor."""

    def test_water_rmse_uses_each_samples_current(self) -> None:
        """A current that turns is taken off sample by sample; its final value would not do."""
        n = 200
        hd = np.zeros(n)
        cur = np.column_stack([np.linspace(0.0, 1.0, n), np.zeros(n)])
        water = np.full(n, 3.0)
        ref = water + cur[:, 0]
        assert water_rmse(ref, water, hd, cur) == pytest.approx(0.0, abs=1e-12)
        assert water_rmse(ref, water, hd, cur[-1]) > 0.5
        assert water_rmse(ref, water) == pytest.approx(rmse(ref, water))

    def test_water_target_leaves_undetermined_samples(self) -> None:
        """A nan current (not determined then) leaves that sample's reference as it is."""
        cur = np.array([[0.5, 0.0], [np.nan, np.nan]])
        out = water_target([2.0, 2.0], [0.0, 0.0], cur)
        assert out.tolist() == [1.5, 2.0]
        with pytest.raises(DataError):
            water_target([2.0, 2.0], [0.0], cur)

    @pytest.mark.parametrize("rho", [0.0, 0.5, 0.9])
    def test_correlation_factor_of_ar1(self, rho: float) -> None:
        """AR(1) residuals: (1 + ρ)/(1 − ρ) within 25 %; white: about 1."""
        rng = np.random.default_rng(7)
        e = np.zeros(20000)
        for k in range(1, e.size):
            e[k] = rho * e[k - 1] + rng.standard_normal()
        expected = (1 + rho) / (1 - rho)
        assert correlation_factor(e) == pytest.approx(expected, rel=0.25)
        assert correlation_factor([1.0, 2.0]) == 1.0

    def test_water_scores_follow_a_turning_current(self) -> None:
        """A current turning over hours: the windows follow it (corrected error ≈ 0) while the
        raw reading's score does not depend on the calibration given."""
        n = 4 * 3600
        t = np.arange(n, dtype=np.float64)
        hd = (t * 2.0) % 360.0  # circling: every window determines its current
        water = 3.0 + 0.5 * np.sin(t / 300.0)
        c_n = np.linspace(-0.5, 0.5, n)
        psi = np.radians(hd)
        ref = water + c_n * np.cos(psi)
        truth = Params("EM3", m=0.05, b_mps=0.1)
        raw = forward_array(truth, water)
        cor = correct_array(truth, raw)
        r_raw, r_cal = water_scores(water_targets(t, ref, raw, cor, hd, truth))
        assert r_cal < 0.03
        r_raw2, _ = water_scores(water_targets(t, ref, raw, raw, hd, Params("EM3")))
        assert r_raw == pytest.approx(r_raw2)
        _, r_const = water_scores(water_targets(t, ref, raw, cor, hd, truth, window_s=1e9))
        assert r_const > 5.0 * r_cal
        assert water_scores(water_targets(t, ref, raw, cor, None, truth)) == (
            rmse(ref, raw),
            rmse(ref, cor),
        )
        # the IMO verdict scores against the same water speed: the corrected reading meets
        # it, the raw one (5 % scale) does not; against the reference (the current left
        # in) the corrected one would not either
        v_raw, v_cor = water_imo(water_targets(t, ref, raw, cor, hd, truth))
        assert v_cor.meets and v_cor.fraction > 0.99 and v_cor.n == n
        assert not v_raw.meets
        assert not imo_verdict(ref, cor).meets
        assert water_imo(water_targets(t, ref, raw, cor, None, truth)) == (
            imo_verdict(ref, raw),
            imo_verdict(ref, cor),
        )


class TestImoVerdict:
    """IMO A.824(19): error ≤ max(2 % of the speed, 0.2 kn); meets with ≥ 95 % within."""

    KN = 1852.0 / 3600.0

    def test_bound_crosses_over_at_10_kn(self) -> None:
        """0.2 kn below 10 kn, 2 % above, both 0.2 kn at 10 kn."""
        kn = self.KN
        bound = imo_bound_mps(np.array([0.0, 5.0, 10.0, 20.0]) * kn) / kn
        assert bound == pytest.approx([0.2, 0.2, 0.2, 0.4])

    def test_bound_at_one_speed_is_the_arrays_exactly(self) -> None:
        """The per-sample bound (a Python float) is the array's, bit for bit, astern too."""
        speeds = np.array([0.0, 1.3, 5.0, 10.0, 20.0, -7.5]) * self.KN
        assert [imo_bound_one_mps(float(v)) for v in speeds] == imo_bound_mps(speeds).tolist()

    @pytest.mark.parametrize("speed_kn", [4.0, 10.0, 20.0])
    def test_at_inside_and_outside_the_bound(self, speed_kn: float) -> None:
        """An error of exactly the bound is within; 1 % less is within; 1 % more is not."""
        kn = self.KN
        b_kn = max(0.02 * speed_kn, 0.2)
        ref = np.full(3, speed_kn * kn)
        for factor, inside in ((1.0, True), (0.99, True), (1.01, False)):
            for sign in (1.0, -1.0):
                est = ref + sign * factor * b_kn * kn
                v = imo_verdict(ref, est)
                assert v.n == 3
                assert v.within == (3 if inside else 0), (speed_kn, factor, sign)
                assert v.meets is inside

    def test_exactly_at_the_bound_is_within(self) -> None:
        """Errors equal to the bound to the last bit: 0.2 kn at rest, 2 % of 50 m/s."""
        assert imo_verdict([0.0], [IMO_MIN_ERROR_MPS]).meets
        assert imo_verdict([50.0], [49.0]).meets
        assert not imo_verdict([50.0], [48.99]).meets

    def test_at_20_kn_0_3_kn_is_within_but_not_at_5_kn(self) -> None:
        """The bound scales with the speed above 10 kn only."""
        kn = self.KN
        assert imo_verdict([20.0 * kn], [20.3 * kn]).meets
        assert not imo_verdict([5.0 * kn], [5.3 * kn]).meets

    def test_meets_needs_95_percent(self) -> None:
        """19 of 20 within meets (95 %); 18 of 20 does not; nan pairs are left out."""
        kn = self.KN
        ref = np.full(22, 8.0 * kn)
        est = ref.copy()
        est[0] += 1.0 * kn
        est[20] = math.nan
        ref[21] = math.nan
        v = imo_verdict(ref, est)
        assert (v.n, v.within, v.meets) == (20, 19, True)
        assert v.fraction == pytest.approx(0.95)
        est[1] -= 1.0 * kn
        v = imo_verdict(ref, est)
        assert (v.within, v.meets) == (18, False)
        assert v.as_dict() == {"n": 20, "within": 18, "fraction": 0.9, "meets": False}

    def test_no_samples_does_not_meet(self) -> None:
        """Without a finite pair: n 0, fraction None in JSON, not met."""
        v = imo_verdict([math.nan], [1.0])
        assert (v.n, v.meets, v.as_dict()["fraction"]) == (0, False, None)

    def test_bad_input_raises_data_error(self) -> None:
        """Different shapes or a fraction outside [0, 1]."""
        with pytest.raises(DataError):
            imo_verdict([1.0, 2.0], [1.0])
        with pytest.raises(DataError):
            imo_verdict([1.0], [1.0], meets_fraction=1.5)
