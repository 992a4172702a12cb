"""The learner: alignment, and what it offers the supervisor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.models import Layout, Params, check_model
from emlogd.pipeline.counters import Counters
from emlogd.pipeline.learner import Learner
from emlogd.pipeline.settings import UutSettings


def _learner() -> tuple[Learner, list[str]]:
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0)
    kinds: list[str] = []
    lr = Learner(
        s,
        Layout(check_model(s.model), s.current),
        None,
        lambda t, k, d: kinds.append(k),
        Counters(),
    )
    return lr, kinds


def test_nothing_is_offered_before_anything_is_learnt() -> None:
    """A fresh learner has no candidate for the supervisor."""
    lr, _ = _learner()
    assert lr.offer() is None


def test_an_offer_once_the_scale_and_bias_are_learnt() -> None:
    """Readings of a log 15 % high on a varying reference: an offer near the truth."""
    lr, kinds = _learner()
    true = Params("EM3", m=0.15, b_mps=0.1)
    offers = []
    for i in range(3000):
        t = i * 0.1
        v = 1.6 + 0.5 * math.sin(2 * math.pi * t / 60.0)
        lr.add_reference(t, v, True, lambda _t: None)
        if i % 10 == 0 and i:
            a = lr.align(t, true.forward(v), lambda _t: None)
            assert a.ref_state == "valid" and a.ref is not None
            lr.step(a, "", None)
            offer = lr.offer()
            if offer is not None:
                offers.append(offer)
    assert offers and offers[-1].params.m == pytest.approx(0.15, abs=0.02)
    assert "reference" in kinds


def _learnt() -> Learner:
    """A learner that has learnt a log 15 % high (σ of m and b well below the prior)."""
    lr, _ = _learner()
    true = Params("EM3", m=0.15, b_mps=0.1)
    for i in range(3000):
        t = i * 0.1
        v = 1.6 + 0.5 * math.sin(2 * math.pi * t / 60.0)
        lr.add_reference(t, v, True, lambda _t: None)
        if i % 10 == 0 and i:
            lr.step(lr.align(t, true.forward(v), lambda _t: None), "", None)
    return lr


def test_a_change_reopens_the_parameters_by_its_own_size() -> None:
    """The supervisor saw the readings change: a shift of 0.6 m/s at 2 m/s in the
    learner's own innovations widens m by about 0.3 and b by 0.6; a shift of 0.01 m/s
    (the reference's noise raised the alarm) leaves them nearly as they were."""
    big, small = _learnt(), _learnt()
    before = dict(big.param_std)
    assert before["m"] < 0.05 and before["b"] < 0.08
    for lr, shift in ((big, 0.6), (small, 0.01)):
        lr.change.recent.clear()
        for k in range(10):
            lr.change.recent.append((300.0 + k, shift + (0.05 if k % 2 else -0.05), 2.0))
        lr.reopen_for_change()
    assert big.param_std["m"] == pytest.approx(0.3, abs=0.02)
    assert big.param_std["b"] == pytest.approx(0.5, abs=0.01)  # at most its prior
    assert small.param_std["m"] < before["m"] + 0.01
    assert small.param_std["b"] < before["b"] + 0.02
    assert not small.change.recent


def test_without_recent_innovations_a_change_reopens_to_the_prior() -> None:
    """No innovations to measure the change on: the parameters' σ go back to the prior."""
    lr = _learnt()
    lr.change.recent.clear()
    lr.reopen_for_change()
    assert lr.param_std["m"] == pytest.approx(0.5) and lr.param_std["b"] == pytest.approx(0.5)


def test_readings_the_logs_health_refuses_never_relearn() -> None:
    """A stalled log's readings are gated, but a run of them is no changed sensor: the
    parameters are not re-opened (a healthy log's run of gated readings is)."""
    for gate, relearns in (("uut_stalled", 0), ("", 1)):
        lr = _learnt()
        std, relearnt = lr.param_std["m"], lr.counters.relearn
        for i in range(40):
            t = 300.0 + i
            lr.add_reference(t, 2.0, True, lambda _t: None)
            lr.step(lr.align(t, 0.2 if gate else 6.0, lambda _t: None), gate, None)
        assert lr.counters.relearn - relearnt == relearns
        assert (lr.param_std["m"] > 0.4) == bool(relearns) and lr.param_std["m"] >= std


def _gnss_learner() -> Learner:
    s = UutSettings(port="log", reference_port="gps", reference_field="gnss", lag_s=0.0)
    return Learner(s, Layout(check_model(s.model), s.current), None, lambda t, k, d: None,
                   Counters())  # fmt: skip


def _feed_blocks(lr: Learner, t0: int, t1: int, gain: float) -> None:
    true = Params("EM3", m=0.05, b_mps=0.0)
    for i in range(t0, t1):
        t = float(i)
        v = 2.5 + 1.0 * math.sin(2 * math.pi * t / 300.0)
        lr.add_reference(t, v, True, lambda _t: None)
        lr.step(lr.align(t, true.forward(v) * gain, lambda _t: None), "", None)


def test_learning_from_blocks_an_alarm_without_a_change_keeps_what_was_learnt() -> None:
    """Against GNSS (20-s block means) the supervisor's alarm re-opens the parameters by the
    largest mean block innovation of the last blocks: readings that did not change leave
    the filter's σ near what it was (hours of learning kept, its NIS honest), while the
    offer waits for a shadow re-opened to the prior (σ² = ``p0``) to be determined again
    by readings after the alarm."""
    lr = _gnss_learner()
    _feed_blocks(lr, 0, 2370, 1.0)
    std0 = lr.param_std["m"]
    assert std0 < 0.02 and lr.offer() is not None
    lr.reopen_for_change()
    shadow = lr.shadow
    assert shadow is not None
    assert shadow.param_std["m"] == pytest.approx(math.sqrt(lr.s.p0))
    assert shadow.param_std["b"] == pytest.approx(math.sqrt(lr.s.p0))
    assert std0 <= lr.param_std["m"] < 0.03
    assert lr.offer() is None
    _feed_blocks(lr, 2370, 2410, 1.0)
    assert lr.offer() is None  # two blocks do not determine scale and bias again
    _feed_blocks(lr, 2410, 3000, 1.0)
    offer = lr.offer()
    assert offer is not None
    assert lr.shadow is None  # the readings since the alarm determine the parameters
    assert offer.params.m == pytest.approx(0.05, abs=0.005)


def test_learning_from_blocks_a_real_change_reopens_by_its_size() -> None:
    """A 30 % gain step the blocks since it show re-opens the scale by about its size
    ((δ/v)², δ the mean innovation of those blocks), and the filter learns the new scale."""
    lr = _gnss_learner()
    _feed_blocks(lr, 0, 2300, 1.0)
    _feed_blocks(lr, 2300, 2370, 1.3)
    lr.reopen_for_change()
    assert lr.param_std["m"] > 0.15
    _feed_blocks(lr, 2370, 3600, 1.3)
    assert lr.kf.params.m == pytest.approx(1.3 * 1.05 - 1.0, abs=0.02)
    assert lr.offer() is not None


def test_the_daemon_scales_the_noises_slowly_and_calibrate_by_the_innovations() -> None:
    """The daemon's filter (the default) scales its noises by the slowly adapted λ_slow,
    on which its estimates, gates and offers rest; ``matched_noise`` (``calibrate
    --method kf``) by λ matched to the innovations, which blocks of clean readings bring
    far below λ_slow within ten minutes, and an offer is then judged on σ floored at λ_slow."""
    daemon, offline = _gnss_learner(), _gnss_learner()
    offline = Learner(offline.s, offline.layout, None, lambda t, k, d: None, Counters(),
                      matched_noise=True)  # fmt: skip
    true = Params("EM3", m=0.05, b_mps=0.0)
    for lr in (daemon, offline):
        rng = np.random.default_rng(5)
        for i in range(600):
            t = float(i)
            v = 2.5 + 1.0 * math.sin(2 * math.pi * t / 300.0)
            lr.add_reference(t, v, True, lambda _t: None)
            raw = true.forward(v) + rng.normal(0.0, 0.05)
            lr.step(lr.align(t, raw, lambda _t: None), "", None)
    assert daemon.kf.noise_scale == daemon.kf.noise_scale_slow
    assert offline.kf.noise_scale == offline.kf.noise_scale_matched
    assert offline.kf.noise_scale_slow > 2.0 * offline.kf.noise_scale
    std, floored = offline.kf.param_std, offline.kf.param_std_offer
    assert floored["m"] > 1.4 * std["m"]


def test_a_log_that_reads_right_is_offered_no_correction() -> None:
    """A log with no error, learnt as well as the 15 %-high one above: the correction at
    the speed through the water is within OFFER_SIGMAS of its σ from zero, so nothing
    is offered (the raw reading stays); the same run with the log 15 % high offers."""
    rng = np.random.default_rng(5)
    offers = {"right": 0, "high": 0}
    for case, true in (("right", Params("EM3")), ("high", Params("EM3", m=0.15, b_mps=0.1))):
        lr, _ = _learner()
        for i in range(3000):
            t = i * 0.1
            v = 1.6 + 0.5 * math.sin(2 * math.pi * t / 60.0)
            lr.add_reference(t, v + float(rng.normal(0.0, 0.02)), True, lambda _t: None)
            if i % 10 == 0 and i:
                lr.step(lr.align(t, true.forward(v), lambda _t: None), "", None)
                offers[case] += lr.offer() is not None
    assert offers["right"] == 0
    assert offers["high"] > 100
