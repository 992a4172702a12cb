"""Kalman filters: numpy reference, fast kernels, KF-EMx online, RLS, batch runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from calib.errors import DataError, ModelError
from calib.kalman import (
    KERNELS,
    SPECS,
    FilterSpec,
    KalmanModel,
    KfCalibrator,
    KfConfig,
    RlsCalibrator,
    _update_any,
    make_state,
    pack,
    predict,
    run_kf,
    unpack,
    update,
)
from calib.lsq import fit_ls
from calib.metrics import nis_stats
from calib.models import Params, design_matrix, forward_array


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


class TestKernels:
    """The unrolled fast kernels against the numpy reference."""

    @pytest.mark.parametrize(
        ("n", "free_count"), [(n, f) for n in range(1, 6) for f in range(1, n + 1)]
    )
    def test_kernel_matches_reference(self, n: int, free_count: int) -> None:
        """Each kernel (and the generic loop) equals the numpy Joseph update to 1e-12."""
        rng = np.random.default_rng(10 * n + free_count)
        P = _random_spd(n, rng)
        x = rng.normal(size=n)
        h = rng.normal(size=n)
        model = KalmanModel.of(np.eye(n), h[None, :], np.zeros((n, n)), [[0.2]])
        free = [i < free_count for i in range(n)]
        ref_state, inn = update(make_state(x, P), 0.7, model, free=free)
        assert inn is not None
        for kernel in {KERNELS.get(n, _update_any), _update_any}:
            xs, Ps = x.tolist(), pack(P)
            y, s = kernel(xs, Ps, tuple(h), 0.7, 0.2, free_count)
            assert (y, s) == pytest.approx((inn.y, inn.S), rel=1e-12)
            np.testing.assert_allclose(xs, ref_state.x, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(unpack(Ps, n), ref_state.P, rtol=1e-10, atol=1e-12)

    def test_pack_unpack_round_trip(self) -> None:
        """pack and unpack are inverse on symmetric matrices."""
        P = _random_spd(4, np.random.default_rng(1))
        np.testing.assert_allclose(unpack(pack(P), 4), P)


class TestKfCalibrator:
    """KF-EMx online, against the reference and on simulated data."""

    @pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
    def test_matches_numpy_reference_with_outages(self, model: str) -> None:
        """The fast filter equals predict/update in numpy, including outage steps, to 1e-10."""
        cfg = KfConfig()
        truth = Params.from_theta(
            model,
            {"EM1": (0.1,), "EM2": (0.05,), "EM3": (0.05, 0.1), "EM4": (0.01, 0.05, 0.1)}[model],
        )
        t, _, raw, ref = _sim(300, 11, truth, cfg)
        spec = SPECS[model]  # type: ignore[index]
        n = spec.n
        kf = KfCalibrator(model, cfg, v0_mps=1.0)
        x0 = np.zeros(n)
        x0[0] = 1.0
        state = make_state(x0, np.eye(n) * cfg.p0)
        for k in range(t.size):
            outage = 100 <= k < 160
            q = np.full(n, cfg.q_params)
            q[0] = cfg.accel_psd_m2ps3 * 1.0
            state = predict(state, KalmanModel.of(np.eye(n), np.eye(n)[:1], np.diag(q), [[1.0]]))
            if not outage:
                state, _ = update(
                    state,
                    ref[k],
                    KalmanModel.of(np.eye(n), np.eye(n)[:1], np.zeros((n, n)), [[cfg.r_ref_mps2]]),
                )
                h, free = spec.h_raw(ref[k]), None
            else:
                theta = state.x[1:]
                v_op = Params.from_theta(model, theta).correct(raw[k])
                h, free = spec.h_raw(v_op), [True] + [False] * (n - 1)
            raw_model = KalmanModel.of(
                np.eye(n), np.eye(n)[:1], np.zeros((n, n)), [[cfg.r_raw_mps2]]
            )
            state, inn = update(state, raw[k], raw_model, H=h, free=free)
            fast = kf.update(raw[k], None if outage else ref[k], 1.0)
            assert fast is not None and inn is not None
            assert fast.nis == pytest.approx(inn.nis, rel=1e-9, abs=1e-12)
        np.testing.assert_allclose(kf.x, state.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.covariance(), state.P, rtol=1e-8, atol=1e-14)

    def test_kf_em3_converges_within_2_sigma(self) -> None:
        """KF-EM3 ends within 2σ of the truth by its own P."""
        cfg = KfConfig()
        truth = Params("EM3", m=0.05, b_mps=0.1)
        t, _, raw, ref = _sim(3600, 12, truth, cfg)
        run = run_kf("EM3", t, raw, ref, cfg)
        for est, true, sd in zip(run.params.theta, truth.theta, run.param_std, strict=True):
            assert abs(est - true) <= 2.0 * sd
        assert run.param_std[0] < 0.01

    def test_kf_em4_tracks_curvature(self) -> None:
        """KF-EM4 recovers a quadratic coefficient within 3σ."""
        cfg = KfConfig()
        truth = Params("EM4", a_spm=0.03, m=0.02, b_mps=0.05)
        t, _, raw, ref = _sim(3600, 13, truth, cfg)
        run = run_kf("EM4", t, raw, ref, cfg)
        for est, true, sd in zip(run.params.theta, truth.theta, run.param_std, strict=True):
            assert abs(est - true) <= 3.0 * sd

    def test_constant_speed_sigma_stays_large(self) -> None:
        """At constant speed m and b stay uncertain (σ > 0.1) though m·v + b is learnt."""
        cfg = KfConfig()
        rng = np.random.default_rng(14)
        kf = KfCalibrator("EM3", cfg, v0_mps=2.0)
        for _ in range(3600):
            kf.update(2.0 * 1.05 + 0.1 + rng.normal(0, 0.05), 2.0, 1.0)
        sd_m, sd_b = kf.param_std
        assert sd_m > 0.1 and sd_b > 0.1
        assert kf.corrected(2.0 * 1.05 + 0.1) == pytest.approx(2.0, abs=0.01)

    def test_consistent_filter_nis(self) -> None:
        """A correctly tuned filter has NIS mean in [0.8, 1.2] and about 95 % inside the bounds."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(4000, 15, Params("EM3", m=0.05, b_mps=0.1), cfg)
        stats = nis_stats(run_kf("EM3", t, raw, ref, cfg).nis, skip=50)
        assert 0.8 <= stats.mean <= 1.2
        assert 0.93 <= stats.frac_inside <= 0.97
        assert stats.consistent

    def test_badly_tuned_filter_detected(self) -> None:
        """With R 100× too small the NIS test flags the filter as inconsistent."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(4000, 15, Params("EM3", m=0.05, b_mps=0.1), cfg)
        bad = KfConfig(r_raw_mps2=cfg.r_raw_mps2 / 100.0)
        stats = nis_stats(run_kf("EM3", t, raw, ref, bad).nis, skip=50)
        assert not stats.consistent
        assert stats.mean > 5.0 and stats.frac_inside < 0.8

    def test_outage_freezes_parameters_and_carries_speed(self) -> None:
        """Without reference the parameters stay fixed and v follows the corrected raw reading."""
        cfg = KfConfig()
        truth = Params("EM3", m=0.05, b_mps=0.1)
        _t, v, raw, ref = _sim(1200, 16, truth, cfg)
        kf = KfCalibrator("EM3", cfg)
        for k in range(900):
            kf.update(raw[k], ref[k], 1.0)
        frozen = kf.params
        errors = []
        for k in range(900, 1200):
            inn = kf.update(raw[k], None, 1.0)
            assert inn is not None
            errors.append(kf.speed_mps - v[k])
        assert kf.params == frozen
        assert math.sqrt(np.mean(np.square(errors))) < 0.06

    def test_outage_innovation_is_corrected_minus_state(self) -> None:
        """In an outage the raw innovation is exactly corrected(raw) − v̂ (prior)."""
        kf = KfCalibrator("EM4", params0=Params("EM4", a_spm=0.02, m=0.05, b_mps=0.1), v0_mps=1.5)
        v_prior = kf.speed_mps
        inn = kf.update(2.0, None, 0.0)
        assert inn is not None
        assert inn.y == pytest.approx(kf.params.correct(2.0) - v_prior, abs=1e-12)

    def test_learn_false_holds_parameters(self) -> None:
        """learn=False updates the speed but not the parameters, even with a reference."""
        kf = KfCalibrator("EM3")
        kf.update(2.3, 2.0, 1.0, learn=False)
        assert kf.params == Params("EM3")
        assert kf.speed_mps == pytest.approx(2.0, abs=0.01)

    def test_no_raw_returns_none(self) -> None:
        """Without a raw reading update returns None (reference and predict still applied)."""
        kf = KfCalibrator("EM1")
        assert kf.update(None, 1.5, 1.0) is None
        assert kf.speed_mps == pytest.approx(1.5, abs=0.01)

    def test_negative_dt_raises(self) -> None:
        """A negative time step raises DataError."""
        with pytest.raises(DataError):
            KfCalibrator("EM3").update(1.0, 1.0, -1.0)

    def test_p_symmetric_positive_after_long_run(self) -> None:
        """After 20 000 steps P is positive definite and the state storage has not grown."""
        cfg = KfConfig(q_params=0.0)
        _t, _, raw, ref = _sim(20000, 17, Params("EM4", a_spm=0.01, m=0.05, b_mps=0.1), cfg)
        kf = KfCalibrator("EM4", cfg)
        size = (len(kf.x), len(kf.export_state()["P"]))  # type: ignore[arg-type]
        for r, z in zip(raw.tolist(), ref.tolist(), strict=True):
            kf.update(r, z, 1.0)
        P = np.array(kf.covariance())
        np.testing.assert_array_equal(P, P.T)
        assert np.all(np.linalg.eigvalsh(P) > 0.0)
        assert (len(kf.x), len(kf.export_state()["P"])) == size  # type: ignore[arg-type]
        assert not hasattr(kf, "__dict__")

    def test_export_import_resumes_identically(self) -> None:
        """A filter rebuilt from its JSON export continues exactly like the original."""
        cfg = KfConfig()
        _t, _, raw, ref = _sim(400, 18, Params("EM3", m=0.05, b_mps=0.1), cfg)
        a = KfCalibrator("EM3", cfg)
        for k in range(200):
            a.update(raw[k], ref[k], 1.0)
        b = KfCalibrator.from_state(json.loads(json.dumps(a.export_state())), cfg)
        for k in range(200, 400):
            assert a.update(raw[k], ref[k], 1.0) == b.update(raw[k], ref[k], 1.0)
        assert a.x == b.x and a.covariance() == b.covariance()

    def test_import_rejects_mismatched_states(self) -> None:
        """An export of another model or with a non-SPD P raises ModelError."""
        data = KfCalibrator("EM3").export_state()
        with pytest.raises(ModelError):
            KfCalibrator.from_state({**data, "model": "EM2"})
        with pytest.raises(ModelError):
            KfCalibrator.from_state({**data, "P": [[1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]]})

    def test_params_of_wrong_model_rejected(self) -> None:
        """Initial parameters of another model raise ModelError."""
        with pytest.raises(ModelError):
            KfCalibrator("EM3", params0=Params("EM1"))

    def test_custom_spec_with_extra_dynamic_state(self) -> None:
        """A new model is a new spec: a 4-state [v, c, m, b] filter runs on the generic path."""
        spec = FilterSpec("EM3", ("v_mps", "c_mps", "m", "b_mps"), 2, lambda v: (1.0, 1.0, v, 1.0))
        kf = KfCalibrator(spec=spec)
        inn = kf.update(2.1, 2.0, 1.0)
        assert inn is not None and math.isfinite(inn.nis)
        assert len(kf.param_std) == 2

    def test_bad_spec_rejected(self) -> None:
        """A spec whose state count does not match its model raises ModelError."""
        with pytest.raises(ModelError):
            FilterSpec("EM3", ("v_mps", "m"), 1, lambda v: (1.0, v))

    def test_config_validation(self) -> None:
        """Non-positive variances raise ValueError."""
        with pytest.raises(ValueError, match="r_raw_mps2"):
            KfConfig(r_raw_mps2=0.0)
        with pytest.raises(ValueError, match="q_params"):
            KfConfig(q_params=-1.0)


class TestRls:
    """The parameter-only form (recursive least squares)."""

    def _data(self) -> tuple[np.ndarray, np.ndarray]:
        rng = np.random.default_rng(20)
        t = np.arange(600, dtype=np.float64)
        v = 2.5 + 2.0 * np.sin(2 * np.pi * t / 120.0)
        raw = forward_array(Params("EM4", a_spm=0.02, m=0.05, b_mps=0.1), v)
        return v, raw + rng.normal(0.0, 0.05, v.size)

    @pytest.mark.parametrize("model", ["EM1", "EM2", "EM3", "EM4"])
    def test_equals_batch_ls_from_initial_fit(self, model: str) -> None:
        """With Q = 0, RLS started from LS of the first samples equals batch LS of all (1e-9)."""
        v, raw = self._data()
        n0, r = 20, 0.05**2
        first = fit_ls(model, v[:n0], raw[:n0])
        H0 = design_matrix(model, v[:n0])
        rls = RlsCalibrator(model, r, params0=first.params, P0=r * np.linalg.inv(H0.T @ H0))
        for vk, zk in zip(v[n0:].tolist(), raw[n0:].tolist(), strict=True):
            rls.update(zk, vk)
        np.testing.assert_allclose(
            rls.params.theta, fit_ls(model, v, raw).params.theta, rtol=1e-9, atol=1e-9
        )

    def test_equals_ls_with_prior(self) -> None:
        """With Q = 0 and prior (0, 0.25·I), RLS equals LS augmented with the prior rows (1e-9)."""
        v, raw = self._data()
        r = 0.05**2
        rls = RlsCalibrator("EM3", r)
        for vk, zk in zip(v.tolist(), raw.tolist(), strict=True):
            rls.update(zk, vk)
        H = np.vstack([design_matrix("EM3", v), math.sqrt(r / 0.25) * np.eye(2)])
        z = np.concatenate([raw - v, np.zeros(2)])
        theta = np.linalg.lstsq(H, z, rcond=None)[0]
        np.testing.assert_allclose(rls.params.theta, theta, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(
            rls.covariance(), r * np.linalg.inv(H.T @ H), rtol=1e-8, atol=1e-15
        )

    def test_weights_match_weighted_ls(self) -> None:
        """Sample weights act as r/weight and reproduce weighted LS."""
        v, raw = self._data()
        w = np.random.default_rng(21).uniform(0.5, 2.0, v.size)
        n0, r = 20, 0.05**2
        first = fit_ls("EM3", v[:n0], raw[:n0], w[:n0])
        H0 = design_matrix("EM3", v[:n0]) * np.sqrt(w[:n0])[:, None]
        rls = RlsCalibrator("EM3", r, params0=first.params, P0=r * np.linalg.inv(H0.T @ H0))
        for vk, zk, wk in zip(v[n0:].tolist(), raw[n0:].tolist(), w[n0:].tolist(), strict=True):
            rls.update(zk, vk, wk)
        np.testing.assert_allclose(
            rls.params.theta, fit_ls("EM3", v, raw, w).params.theta, rtol=1e-9
        )

    def test_random_walk_keeps_learning(self) -> None:
        """With Q > 0 the parameter variance does not collapse to zero."""
        v, raw = self._data()
        a, b = RlsCalibrator("EM3", 0.0025), RlsCalibrator("EM3", 0.0025, q=1e-6)
        for vk, zk in zip(v.tolist(), raw.tolist(), strict=True):
            a.update(zk, vk)
            b.update(zk, vk)
        assert b.param_std[0] > 1.5 * a.param_std[0]

    def test_export_import(self) -> None:
        """The RLS state round-trips through plain lists."""
        rls = RlsCalibrator("EM2", 0.01)
        rls.update(2.1, 2.0)
        again = RlsCalibrator.from_state(rls.export_state(), 0.01)
        assert again.x == rls.x and again.covariance() == rls.covariance()


class TestRunKf:
    """Batch runs over arrays."""

    def test_histories_have_shapes(self) -> None:
        """The run returns per-sample θ, σ and NIS series of the right shapes."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(200, 30, Params("EM3", m=0.05, b_mps=0.1), cfg)
        ref[50:60] = np.nan
        run = run_kf("EM3", t, raw, ref, cfg)
        assert run.theta.shape == (200, 2) and run.theta_std.shape == (200, 2)
        assert run.speed_mps.shape == (200,)
        assert np.all(np.isnan(run.nis[50:60])) and np.all(np.isfinite(run.y))
        assert run.theta_std[-1, 0] < run.theta_std[0, 0]

    def test_history_off_gives_same_result(self) -> None:
        """history=False changes only the stored series, not the estimate."""
        cfg = KfConfig()
        t, _, raw, ref = _sim(200, 31, Params("EM2", m=0.05), cfg)
        a = run_kf("EM2", t, raw, ref, cfg)
        b = run_kf("EM2", t, raw, ref, cfg, history=False)
        assert a.params == b.params and b.theta.size == 0

    def test_decreasing_time_raises(self) -> None:
        """Times that go backwards raise DataError."""
        with pytest.raises(DataError):
            run_kf("EM3", [0.0, 2.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0])


def test_em3_specialised_step_matches_the_generic_three_state_step() -> None:
    """KF-EM3's inline-row fused step gives the same filter as the generic 3-state step."""
    from calib.kalman import SPECS, FilterSpec

    generic = FilterSpec("EM3", SPECS["EM3"].states, 1, lambda v: (1.0, v, 1.0))
    fast = KfCalibrator("EM3")
    slow = KfCalibrator("EM3", spec=generic)
    assert fast._fused is not slow._fused
    rng = np.random.default_rng(7)
    for k in range(2000):
        v = 1.5 + 0.5 * math.sin(k / 40.0)
        raw = 1.05 * v + 0.1 + rng.normal(0.0, 0.05)
        ref = v + rng.normal(0.0, 0.01)
        a = fast.update(raw, ref, 0.1)
        b = slow.update(raw, ref, 0.1)
        assert a is not None and b is not None
        assert a.y == pytest.approx(b.y, abs=1e-12)
        s_fast, s_slow = a.S, b.S
        assert s_fast == pytest.approx(s_slow, rel=1e-12)
    assert fast.x == pytest.approx(slow.x, abs=1e-12)
    assert np.allclose(fast.covariance(), slow.covariance(), rtol=1e-10, atol=1e-15)
