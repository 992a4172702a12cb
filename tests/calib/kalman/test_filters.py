"""KF-EMx online: against the numpy reference, on simulated data, in the water frame."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from calib.errors import DataError, ModelError
from calib.kalman import KalmanModel, KfCalibrator, KfConfig, make_state, predict, run_kf, update
from calib.lsq import block_average
from calib.metrics import nis_stats
from calib.models import Params, design_row, forward_array
from tests.synth import water_frame_segment


def _sim(
    n: int, seed: int, truth: Params, cfg: KfConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Data drawn from the filter's own model: random-walk speed, exact R's."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64)
    steps = rng.normal(0.0, math.sqrt(cfg.accel_psd_m2ps3), n)
    v = 2.0 + 0.8 * np.sin(2 * np.pi * t / 240.0) + np.cumsum(steps) * 0.2
    raw = forward_array(truth, v) + rng.normal(0.0, math.sqrt(cfg.r_raw_mps2), n)
    ref = v + rng.normal(0.0, math.sqrt(cfg.r_ref_mps2), n)
    return t, v, raw, ref


TRUTH = {
    "EM1": Params("EM1", b_mps=0.1),
    "EM2": Params("EM2", m=0.05),
    "EM3": Params("EM3", m=0.05, b_mps=0.1),
    "EM4": Params("EM4", a_spm=0.01, m=0.05, b_mps=0.1),
}


class TestAgainstTheReference:
    """The per-sample filter is the numpy textbook filter, step by step."""

    @pytest.mark.parametrize("current", [False, True])
    @pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
    def test_matches_numpy_with_outages_and_current(self, model: str, current: bool) -> None:
        """State, covariance and NIS equal predict/update in numpy to 1e-9, outages included."""
        cfg = KfConfig(adaptive=False, fused_operating_point=False)
        t, _, raw, ref = _sim(300, 11, TRUTH[model], cfg)
        heading = np.radians(np.arange(300) * 3.0)
        kf = KfCalibrator(model, cfg, current=current, v0_mps=1.0)
        p = len(TRUTH[model].theta)
        n = 1 + p + (2 if current else 0)
        x0 = np.zeros(n)
        x0[0] = 1.0
        p0 = np.full(n, cfg.p0)
        if current:
            p0[-2:] = cfg.current_p0_m2ps2
        state = make_state(x0, np.diag(p0))
        for k in range(t.size):
            outage = 100 <= k < 160
            q = np.full(n, cfg.q_params)
            q[0] = cfg.accel_psd_m2ps3 * 1.0
            if current:
                q[-2:] = cfg.current_psd_m2ps3 * 1.0
            state = predict(state, KalmanModel.of(np.eye(n), np.eye(n)[:1], np.diag(q), [[1.0]]))
            c, s = math.cos(heading[k]), math.sin(heading[k])
            if not outage:
                h_ref = np.zeros(n)
                h_ref[0] = 1.0
                if current:
                    h_ref[-2:] = (c, s)
                ref_model = KalmanModel.of(
                    np.eye(n), h_ref[None, :], np.zeros((n, n)), [[cfg.r_ref_mps2]]
                )
                state, _ = update(state, ref[k], ref_model)
                v_op = ref[k] - (state.x[-2] * c + state.x[-1] * s if current else 0.0)
                free = None
            else:
                v_op = Params.from_theta(model, state.x[1 : 1 + p]).correct(raw[k])
                free = [True] + [False] * (n - 1)
            h = np.zeros(n)
            h[0] = 1.0
            h[1 : 1 + p] = design_row(TRUTH[model].model, v_op)
            z = raw[k]
            if free is not None:  # held unknowns are known: their terms move to z
                z -= float(np.dot(h[1:], state.x[1:]))
                h[1:] = 0.0
            raw_model = KalmanModel.of(np.eye(n), h[None, :], np.zeros((n, n)), [[cfg.r_raw_mps2]])
            state, inn = update(state, z, raw_model, free=free)
            res = kf.update(raw[k], None if outage else ref[k], 1.0, heading_cs=(c, s))
            assert res.raw is not None and inn is not None
            assert res.raw.nis == pytest.approx(inn.nis, rel=1e-9, abs=1e-12)
            assert res.learnt is not outage
        np.testing.assert_allclose(kf.x, state.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(kf.covariance(), state.P, rtol=1e-7, atol=1e-14)


class TestPaperFilters:
    """KF-EMx without current, as the paper runs them."""

    def test_kf_em3_converges_within_2_sigma(self) -> None:
        """KF-EM3 ends within 2σ of the truth by its own P."""
        cfg = KfConfig()
        truth = TRUTH["EM3"]
        t, _, raw, ref = _sim(3600, 12, truth, cfg)
        run = run_kf("EM3", t, raw, ref, cfg)
        for name, true in truth.as_dict().items():
            std = run.param_std[name]
            assert std is not None and abs(run.params.as_dict()[name] - true) <= 2.0 * std
        std_m = run.param_std["m"]
        assert std_m is not None and std_m < 0.01

    def test_kf_em4_tracks_curvature(self) -> None:
        """KF-EM4 recovers a quadratic coefficient within 3σ."""
        cfg = KfConfig()
        truth = Params("EM4", a_spm=0.03, m=0.02, b_mps=0.05)
        t, _, raw, ref = _sim(3600, 13, truth, cfg)
        run = run_kf("EM4", t, raw, ref, cfg)
        for name, true in truth.as_dict().items():
            std = run.param_std[name]
            assert std is not None and abs(run.params.as_dict()[name] - true) <= 3.0 * std

    def test_constant_speed_sigma_stays_large(self) -> None:
        """At constant speed m and b stay uncertain (σ > 0.1) though m·v + b is learnt."""
        rng = np.random.default_rng(14)
        kf = KfCalibrator("EM3", v0_mps=2.0)
        for _ in range(3600):
            kf.update(2.0 * 1.05 + 0.1 + rng.normal(0, 0.05), 2.0, 1.0)
        assert kf.param_std["m"] > 0.1 and kf.param_std["b"] > 0.1
        assert kf.corrected(2.0 * 1.05 + 0.1) == pytest.approx(2.0, abs=0.01)

    def test_consistent_filter_nis(self) -> None:
        """A correctly tuned filter has NIS mean in [0.8, 1.2] and about 95 % inside the bounds."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(4000, 15, TRUTH["EM3"], cfg)
        stats = nis_stats(run_kf("EM3", t, raw, ref, cfg).nis, skip=50)
        assert 0.8 <= stats.mean <= 1.2
        assert 0.93 <= stats.frac_inside <= 0.97

    def test_badly_tuned_filter_detected(self) -> None:
        """With R 100× too small the NIS test flags the filter as inconsistent."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(4000, 15, TRUTH["EM3"], cfg)
        bad = KfConfig(r_raw_mps2=cfg.r_raw_mps2 / 100.0, adaptive=False)
        stats = nis_stats(run_kf("EM3", t, raw, ref, bad).nis, skip=50)
        assert not stats.consistent
        assert stats.mean > 5.0 and stats.frac_inside < 0.8

    @pytest.mark.parametrize("factor", [100.0, 0.01])
    def test_adaptive_noise_scale_restores_nis(self, factor: float) -> None:
        """Block updates (speed re-acquired each time) with R 100× too small or too large:
        the adaptive filter scales it back, NIS mean 0.8–1.2."""
        cfg = KfConfig()
        _t, _, raw, ref = _sim(4000, 15, TRUTH["EM3"], cfg)
        bad = KfConfig(r_raw_mps2=cfg.r_raw_mps2 / factor, r_ref_mps2=cfg.r_ref_mps2 / factor)
        kf = KfCalibrator("EM3", bad)
        nis = _blocks(kf, raw, ref)
        stats = nis_stats(np.array(nis), skip=1000)
        assert 0.8 <= stats.mean <= 1.2
        assert kf.noise_scale == pytest.approx(factor, rel=0.3)

    def test_the_noise_scale_comes_down_within_its_memory(self) -> None:
        """Noises promised 100 times larger than the blocks hold (a GNSS speed's 20-s
        means): λ is within 40 % of 0.01 after three memories of block updates (180),
        and the NIS of the next 1000 has mean 0.8–1.2."""
        kf, raw, ref = _overstated_noises(1200)
        _blocks(kf, raw[:180], ref[:180])
        assert kf.noise_scale == pytest.approx(0.01, rel=0.4)
        nis = _blocks(kf, raw[180:], ref[180:])
        assert 0.8 <= float(np.mean(nis)) <= 1.2

    def test_covariance_matching_sets_the_noise_scale_at_once(self) -> None:
        """Noises promised 100 times larger than the blocks hold: after 30 block updates
        λ is within 40 % of 0.01 (the NIS honest), while the slow scale λ_slow is still
        above 0.03 and an offer's σ is P's times √(λ_slow/λ) (more than 1.5 times it)."""
        kf, raw, ref = _overstated_noises(300)
        _blocks(kf, raw[:30], ref[:30])
        assert kf.noise_scale == pytest.approx(0.01, rel=0.4)
        assert kf.noise_scale_slow > 0.03
        k = math.sqrt(kf.noise_scale_slow / kf.noise_scale)
        assert k > 1.5
        for name, sd in kf.param_std.items():
            assert kf.param_std_offer[name] == pytest.approx(k * sd)

    def test_an_offer_sigma_is_never_below_the_filters(self) -> None:
        """λ_slow below λ: an offer's σ is the filter's own (the floor only raises it)."""
        kf = KfCalibrator("EM3", KfConfig())
        kf.noise_scale, kf.noise_scale_slow = 1.0, 0.1
        assert kf.param_std_offer == kf.param_std

    def test_an_update_told_not_to_adapt_keeps_the_noise_scale(self) -> None:
        """``adapt=False`` (learning sample by sample): λ and the correlation stay."""
        cfg = KfConfig()
        kf = KfCalibrator("EM3", KfConfig(r_raw_mps2=cfg.r_raw_mps2 * 30.0))
        for k in range(20):
            kf.predict(1.0)
            kf.reacquire_speed()
            kf.update(2.0 + 0.01 * k, 2.0, 0.0, adapt=False)
        assert kf.noise_scale == 1.0 and kf.correlation == 1.0

    def test_a_copy_follows_the_state_and_keeps_its_own_covariance(self) -> None:
        """``copy`` is independent; ``follow`` takes the other's mean and noise scale and
        keeps its own P: a copy re-opened to the prior stays wider after the same update."""
        kf = KfCalibrator("EM3", KfConfig(), v0_mps=2.0)
        for k in range(200):
            kf.update(2.0 + 0.5 * math.sin(k / 10.0), 2.0 + 0.5 * math.sin(k / 10.0), 1.0)
        shadow = kf.copy()
        shadow.reopen(["m", "b"])
        assert kf.param_std["m"] < 0.1 and shadow.param_std["m"] == pytest.approx(0.5)
        kf.noise_scale = 0.5
        kf.update(2.4, 2.3, 1.0)
        kf.noise_scale_slow = 2.0
        shadow.follow(kf)
        assert shadow.x == kf.x and shadow.noise_scale == 0.5
        assert shadow.noise_scale_slow == 2.0
        shadow.update(2.4, 2.3, 1.0)
        assert shadow.param_std["m"] > kf.param_std["m"]

    def test_a_sample_between_blocks_has_the_configured_noises(self) -> None:
        """λ adapted to block means (0.01) does not shrink a single sample's noise: with
        ``scaled=False`` the innovation variance holds the configured R, so a reading
        0.3 m/s off a GNSS sample (its own noise) is not gated at NIS 25."""
        cfg = KfConfig(r_ref_mps2=0.3**2)
        for scaled, gated in ((True, True), (False, False)):
            kf = KfCalibrator("EM3", cfg, v0_mps=2.0)
            kf.noise_scale = 0.01
            kf.update(2.0, 2.0, 1.0, learn=False, scaled=scaled)
            res = kf.update(2.3, 2.0, 1.0, learn=False, max_nis=25.0, scaled=scaled)
            assert res.raw is not None and res.raw_gated == gated
            assert (cfg.r_raw_mps2 < res.raw.S) == (not scaled)

    def test_sample_by_sample_keeps_the_configured_noises(self) -> None:
        """Learning sample by sample (a DVL), the filter is the configured one: λ stays 1."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(2000, 15, TRUTH["EM3"], cfg)
        kf = KfCalibrator("EM3", KfConfig(r_raw_mps2=cfg.r_raw_mps2 / 100.0))
        run_kf("EM3", t, raw, ref, calibrator=kf, history=False)
        assert kf.noise_scale == 1.0 and kf.correlation == 1.0

    def test_correlated_readings_count_as_fewer_samples(self) -> None:
        """AR(1) reading errors (ρ 0.9): σ(m) grows toward the truth's spread, white: unchanged."""
        rng = np.random.default_rng(3)
        n = 3000
        t = np.arange(n, dtype=np.float64)
        v = 2.0 + np.sin(t / 60.0)
        truth = TRUTH["EM3"]
        e = np.zeros(n)
        for k in range(1, n):
            e[k] = 0.9 * e[k - 1] + math.sqrt(1 - 0.81) * 0.05 * rng.standard_normal()
        raw = forward_array(truth, v) + e
        ref = v + 0.01 * rng.standard_normal(n)
        stds = {}
        for adaptive in (False, True):
            kf = KfCalibrator("EM3", KfConfig(adaptive=adaptive))
            _blocks(kf, raw, ref)
            stds[adaptive] = kf.param_std["m"]
            if adaptive:
                assert kf.correlation > 5.0
        assert stds[True] > 1.3 * stds[False]
        white = KfCalibrator("EM3", KfConfig())
        _blocks(white, forward_array(truth, v) + 0.05 * rng.standard_normal(n), ref)
        assert white.correlation < 1.3


def _overstated_noises(n_blocks: int) -> tuple[KfCalibrator, np.ndarray, np.ndarray]:
    """A filter whose noises are promised 100 times larger than the blocks of a
    simulated EM3 run hold (a GNSS speed's 20-s means), and the run's readings."""
    cfg = KfConfig()
    _t, _, raw, ref = _sim(n_blocks, 15, TRUTH["EM3"], cfg)
    bad = KfConfig(r_raw_mps2=cfg.r_raw_mps2 * 100.0, r_ref_mps2=cfg.r_ref_mps2 * 100.0)
    return KfCalibrator("EM3", bad), raw, ref


def _blocks(kf: KfCalibrator, raw: np.ndarray, ref: np.ndarray) -> list[float]:
    """Feed each (raw, ref) pair as a block mean does: the speed re-acquired first.

    Returns:
        The NIS of each learnt raw update.
    """
    nis = []
    for zr, zv in zip(raw.tolist(), ref.tolist(), strict=True):
        kf.predict(1.0)
        kf.reacquire_speed()
        res = kf.update(zr, zv, 0.0)
        if res.raw is not None and res.learnt:
            nis.append(res.raw.nis)
    return nis


class TestWaterFrame:
    """The current states: what a ground reference needs."""

    def test_figure8_in_a_current_recovers_sensor_and_current(self) -> None:
        """KF-EM3 with current finds m, b within 0.02/0.03 and the current within 0.03 m/s."""
        truth = Params("EM3", m=0.09, b_mps=0.08)
        seg = water_frame_segment(
            "figure-8", 1800.0, 1.0, truth, np.random.default_rng(3), current_mps=(-0.09, -0.066)
        )
        run = run_kf(
            "EM3", seg.t_s, seg.raw_mps, seg.ref_mps, heading_deg=seg.heading_deg, current=True
        )
        assert run.params.m == pytest.approx(0.09, abs=0.02)
        assert run.params.b_mps == pytest.approx(0.08, abs=0.03)
        assert run.current_mps is not None
        assert run.current_mps == pytest.approx((-0.09, -0.066), abs=0.03)

    def test_without_the_current_states_the_parameters_are_the_currents(self) -> None:
        """The same data without current states leave b or m visibly off the sensor's truth."""
        truth = Params("EM3", m=0.09, b_mps=0.08)
        seg = water_frame_segment(
            "figure-8", 1800.0, 1.0, truth, np.random.default_rng(3), current_mps=(-0.09, -0.066)
        )
        run = run_kf("EM3", seg.t_s, seg.raw_mps, seg.ref_mps)
        err_m = abs(run.params.m - 0.09)
        err_b = abs(run.params.b_mps - 0.08)
        assert err_m > 0.02 or err_b > 0.03

    def test_nis_is_consistent_with_the_current(self) -> None:
        """KF-EM3 with current on a figure-8 in a current has NIS mean in [0.8, 1.2]."""
        cfg = KfConfig(r_raw_mps2=0.05**2)
        truth = Params("EM3", m=0.05, b_mps=0.1)
        seg = water_frame_segment(
            "figure-8", 3600.0, 1.0, truth, np.random.default_rng(4), current_mps=(0.2, -0.1)
        )
        run = run_kf(
            "EM3", seg.t_s, seg.raw_mps, seg.ref_mps, cfg, heading_deg=seg.heading_deg, current=True
        )
        stats = nis_stats(run.nis, skip=100)
        assert 0.8 <= stats.mean <= 1.2

    def test_learning_only_bias_and_current_holds_the_scale(self) -> None:
        """learn={b, current} leaves m exactly at its prior while b and the current move."""
        prior = Params("EM3", m=0.03, b_mps=0.0)
        kf = KfCalibrator("EM3", current=True, params0=prior)
        seg = water_frame_segment(
            "circles",
            600.0,
            1.0,
            Params("EM3", m=0.03, b_mps=0.1),
            np.random.default_rng(5),
            constant_speed=True,
        )
        for raw, ref, hd in zip(seg.raw_mps, seg.ref_mps, seg.heading_deg, strict=True):
            rad = math.radians(hd)
            kf.update(
                raw, ref, 1.0, heading_cs=(math.cos(rad), math.sin(rad)), learn={"b", "current"}
            )
        assert kf.params.m == 0.03
        assert kf.params.b_mps == pytest.approx(0.1, abs=0.02)
        assert kf.current_mps == pytest.approx((0.1, -0.15), abs=0.03)

    def test_a_reference_without_heading_is_an_outage(self) -> None:
        """With current states and no heading the reference is not used and nothing is learnt."""
        kf = KfCalibrator("EM3", current=True)
        res = kf.update(2.2, 2.0, 1.0, heading_cs=None)
        assert res.ref is None and not res.learnt
        assert kf.params == Params("EM3") and kf.current_mps == (0.0, 0.0)


class TestParameterWalk:
    @staticmethod
    def _grown(kf: KfCalibrator, before: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.diag(np.array(kf.covariance()))[1:3] - before

    def test_parameters_walk_per_second_whatever_the_rate(self) -> None:
        """In the water frame ``q_params`` is the parameters' random walk per second (the
        paper's per step of a 1-Hz log): 100 s at 10 Hz widen them as much as 100 s at
        1 Hz, and a gap of an hour adds one step's worth."""
        q = 1e-6
        cfg = KfConfig(q_params=q)
        fast, slow, gap = (KfCalibrator("EM3", cfg, current=True) for _ in range(3))
        before = np.diag(np.array(fast.covariance()))[1:3].copy()
        for _ in range(1000):
            fast.predict(0.1)
        for _ in range(100):
            slow.predict(1.0)
        gap.predict(3600.0)
        for kf, added in ((fast, 100 * q), (slow, 100 * q), (gap, q)):
            np.testing.assert_allclose(self._grown(kf, before), added, rtol=1e-6)

    def test_against_the_ground_the_parameters_walk_per_step(self) -> None:
        """Without the current's states (the paper's filter against the ground) the
        parameters walk ``q_params`` per step, as the paper's: they stand in for the
        sea's changes too, which its tuning follows."""
        q = 1e-6
        kf = KfCalibrator("EM3", KfConfig(q_params=q))
        before = np.diag(np.array(kf.covariance()))[1:3].copy()
        for _ in range(1000):
            kf.predict(0.1)
        np.testing.assert_allclose(self._grown(kf, before), 1000 * q, rtol=1e-6)


class TestIntegrityHooks:
    """Gating, consider states and covariance management."""

    def test_a_gated_reference_glitch_teaches_nothing(self) -> None:
        """A +30 m/s reference is refused by the gate; parameters and speed stay put."""
        cfg = KfConfig()
        _t, _, raw, ref = _sim(600, 20, TRUTH["EM3"], cfg)
        kf = KfCalibrator("EM3", cfg)
        for k in range(500):
            kf.update(raw[k], ref[k], 1.0, max_nis=25.0)
        before = kf.params
        res = kf.update(raw[500], ref[500] + 30.0, 1.0, max_nis=25.0)
        assert res.ref_gated and not res.learnt
        assert kf.params == before
        assert abs(kf.speed_mps - ref[500]) < 0.3

    def test_learn_false_holds_parameters(self) -> None:
        """learn=False updates the speed but not the parameters, even with a reference."""
        kf = KfCalibrator("EM3")
        kf.update(2.3, 2.0, 1.0, learn=False)
        assert kf.params == Params("EM3")
        assert kf.speed_mps == pytest.approx(2.0, abs=0.02)

    def test_the_estimate_read_between_steps_is_the_state_of_each(self) -> None:
        """params read after each step is the state's (θ of x), also when read twice
        in one step and after a restart."""
        cfg = KfConfig()
        _t, _, raw, ref = _sim(50, 3, TRUTH["EM3"], cfg)
        kf = KfCalibrator("EM3", cfg)
        seen = []
        for k in range(50):
            kf.update(raw[k], ref[k], 1.0)
            assert kf.params is kf.params
            assert kf.params == Params.from_theta("EM3", kf.x[1:3])
            seen.append(kf.params)
        assert len(set(seen)) == 50
        kf.restart(Params("EM3", m=0.01))
        assert kf.params == Params("EM3", m=0.01)

    def test_reopen_restores_the_prior_variance(self) -> None:
        """reopen() sets an unknown's variance back to p0 and drops its correlations."""
        cfg = KfConfig()
        _t, _, raw, ref = _sim(600, 21, TRUTH["EM3"], cfg)
        kf = KfCalibrator("EM3", cfg)
        for k in range(600):
            kf.update(raw[k], ref[k], 1.0)
        assert kf.param_std["m"] < 0.05
        kf.reopen(["m"])
        P = kf.covariance()
        assert P[1][1] == cfg.p0 and P[1][0] == P[1][2] == 0.0
        assert kf.params.m != 0.0

    def test_condition_moves_the_others_along_what_the_data_left(self) -> None:
        """At one speed the data fix (1 + m)·v + b only: conditioning b at its true value
        puts m at the truth along that valley, exactly the Gaussian conditional of the
        state (b's variance 0, the others' covariance reduced)."""
        cfg = KfConfig()
        kf = KfCalibrator("EM3", cfg, current=True)
        rng = np.random.default_rng(5)
        truth = TRUTH["EM3"]
        for k in range(900):
            psi = math.radians(90.0 * (k // 60))
            v = 2.0 + rng.normal(0.0, 0.01)
            ref = v + 0.2 * math.cos(psi) + rng.normal(0.0, cfg.r_ref_mps2**0.5)
            raw = float(forward_array(truth, np.array([v]))[0]) + rng.normal(0.0, 0.02)
            kf.update(raw, ref, 1.0, heading_cs=(math.cos(psi), math.sin(psi)))
        assert abs(kf.params.m - truth.m) > 0.02  # the valley: b and m traded
        x, P = np.array(kf.x), np.array(kf.covariance())
        kf.condition({"b": truth.b_mps})
        g = P[:, 2] / P[2, 2]
        assert np.allclose(kf.x, x - g * (x[2] - truth.b_mps), atol=1e-12)
        assert np.allclose(kf.covariance(), P - np.outer(g, P[2, :]), atol=1e-12)
        assert kf.params.b_mps == truth.b_mps and kf.param_std["b"] == 0.0
        assert kf.params.m == pytest.approx(truth.m, abs=0.01)
        with pytest.raises(ModelError, match="not a finite value of a parameter"):
            kf.condition({"a": 0.0})
        with pytest.raises(ModelError, match="finite"):
            kf.condition({"m": math.nan})

    def test_age_current_grows_the_current_variance_up_to_its_prior(self) -> None:
        """age_current(s) adds the random walk over s to each current component, capped at
        the prior; the parameters' variances are untouched."""
        cfg = KfConfig()
        P0 = np.diag([1.0, 1e-4, 1e-4, 1e-6, 1e-6])
        kf = KfCalibrator("EM3", cfg, current=True, current0_mps=(0.2, -0.1), P0=P0)
        kf.age_current(600.0)
        P = kf.covariance()
        assert P[3][3] == pytest.approx(1e-6 + cfg.current_psd_m2ps3 * 600.0)
        assert P[4][4] == pytest.approx(1e-6 + cfg.current_psd_m2ps3 * 600.0)
        assert P[1][1] == P[2][2] == 1e-4
        kf.age_current(1e9)
        assert kf.covariance()[3][3] == cfg.current_p0_m2ps2
        assert kf.current_mps == (0.2, -0.1)

    @pytest.mark.parametrize("elapsed_s", [-3600.0, math.nan])
    def test_a_current_saved_in_the_future_is_of_unknown_age(self, elapsed_s: float) -> None:
        """A state saved by a clock ahead of the data's (a negative age) or of no age: the
        current is kept but its variance is its prior, not the tight one it was saved with."""
        cfg = KfConfig()
        P0 = np.diag([1.0, 1e-4, 1e-4, 1e-6, 1e-6])
        kf = KfCalibrator("EM3", cfg, current=True, current0_mps=(0.2, -0.1), P0=P0)
        kf.age_current(elapsed_s)
        P = kf.covariance()
        assert P[3][3] == P[4][4] == cfg.current_p0_m2ps2
        assert P[1][1] == 1e-4 and kf.current_mps == (0.2, -0.1)

    def test_outage_freezes_parameters_and_carries_speed(self) -> None:
        """Without reference the parameters stay fixed and v follows the corrected raw reading."""
        cfg = KfConfig()
        _t, v, raw, ref = _sim(1200, 16, TRUTH["EM3"], cfg)
        kf = KfCalibrator("EM3", cfg)
        for k in range(900):
            kf.update(raw[k], ref[k], 1.0)
        frozen = kf.params
        errors = []
        for k in range(900, 1200):
            assert kf.update(raw[k], None, 1.0).raw is not None
            errors.append(kf.speed_mps - v[k])
        assert kf.params == frozen
        assert math.sqrt(np.mean(np.square(errors))) < 0.06

    def test_outage_innovation_is_corrected_minus_state(self) -> None:
        """In an outage the raw innovation is exactly corrected(raw) − v̂ (prior)."""
        kf = KfCalibrator("EM4", params0=Params("EM4", a_spm=0.02, m=0.05, b_mps=0.1), v0_mps=1.5)
        v_prior = kf.speed_mps
        res = kf.update(2.0, None, 0.0)
        assert res.raw is not None
        assert res.raw.y == pytest.approx(kf.params.correct(2.0) - v_prior, abs=1e-12)

    def test_no_raw_reading_gives_no_raw_innovation(self) -> None:
        """Without a raw reading only the reference is applied."""
        kf = KfCalibrator("EM1")
        res = kf.update(None, 1.5, 1.0)
        assert res.raw is None and res.ref is not None
        assert kf.speed_mps == pytest.approx(1.5, abs=0.01)

    def test_negative_dt_raises(self) -> None:
        """A negative time step raises DataError."""
        with pytest.raises(DataError):
            KfCalibrator("EM3").update(1.0, 1.0, -1.0)

    def test_p_symmetric_positive_after_long_run(self) -> None:
        """After 20 000 steps P is positive definite and the object has no __dict__."""
        cfg = KfConfig(q_params=0.0)
        _t, _, raw, ref = _sim(20000, 17, TRUTH["EM4"], cfg)
        kf = KfCalibrator("EM4", cfg)
        for r, z in zip(raw.tolist(), ref.tolist(), strict=True):
            kf.update(r, z, 1.0)
        P = np.array(kf.covariance())
        np.testing.assert_array_equal(P, P.T)
        assert np.all(np.linalg.eigvalsh(P) > 0.0)
        assert not hasattr(kf, "__dict__")

    def test_bad_construction_is_rejected(self) -> None:
        """Params of another model, a non-SPD P0 and bad tuning raise."""
        with pytest.raises(ModelError):
            KfCalibrator("EM3", params0=Params("EM1"))
        with pytest.raises(ModelError):
            KfCalibrator("EM3", P0=[[1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])
        with pytest.raises(ValueError, match="r_raw_mps2"):
            KfConfig(r_raw_mps2=0.0)
        with pytest.raises(ValueError, match="current_psd_m2ps3"):
            KfConfig(current_psd_m2ps3=-1.0)


class TestOperatingPoint:
    """Errors in variables: a noisy reference must not pull the scale down."""

    @staticmethod
    def _blocks(fused: bool) -> KfCalibrator:
        truth = Params("EM3", m=0.02, b_mps=0.1)
        rng = np.random.default_rng(4)
        s = water_frame_segment(
            "transit", 6 * 3600, 1.0, truth, rng, current_mps=(0.2, 0.1), sigma_ref_mps=0.3
        )
        a = block_average(s.t_s, s.raw_mps, s.ref_mps, s.heading_deg, 20.0)
        cfg = KfConfig(r_ref_mps2=0.3**2, fused_operating_point=fused)
        kf = KfCalibrator("EM3", cfg, current=True)
        for k in range(a.t.size):
            kf.predict(20.0)
            kf.reacquire_speed()
            psi = math.radians(float(a.heading_deg[k]))
            kf.update(
                float(a.raw[k]), float(a.ref[k]), 0.0, heading_cs=(math.cos(psi), math.sin(psi))
            )
        return kf

    def test_block_means_of_a_noisy_reference_learn_the_true_scale(self) -> None:
        """GNSS-like 0.3 m/s reference, a transit at nearly constant speed, 20-s block means:
        the noise-weighted operating point finds m and b within 2σ of the truth; the
        reference's own (the paper's) pulls m down by more than 0.07 and b up."""
        fused = self._blocks(True)
        std = fused.param_std
        assert abs(fused.params.m - 0.02) < 2.0 * std["m"] + 0.005
        assert abs(fused.params.b_mps - 0.1) < 2.0 * std["b"] + 0.01
        paper = self._blocks(False)
        assert paper.params.m < 0.02 - 0.07 and paper.params.b_mps > 0.25


@pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
def test_amb_reads_the_parameters_of_the_state(model: str) -> None:
    """``amb()`` is (a, m, b) of :attr:`KfCalibrator.params` (0 for one the model has
    not), after updates and in a copy."""
    kf = KfCalibrator(model, current=True)
    for k in range(50):
        psi = math.radians(7.0 * k)
        kf.update(2.0 + 0.01 * k, 1.8 + 0.012 * k, 0.1, heading_cs=(math.cos(psi), math.sin(psi)))
    for f in (kf, kf.copy()):
        p = f.params
        assert f.amb() == (p.a_spm, p.m, p.b_mps)
    assert any(kf.amb())
