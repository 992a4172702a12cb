"""The filter's noise scales one innovation at a time (calib.kalman.adapt)."""

from __future__ import annotations

import math

import numpy as np

from calib.kalman.adapt import (
    ADAPT_NIS_CAP,
    NOISE_SCALE_MAX,
    NOISE_SCALE_MIN,
    matched_scale,
    slow_scale,
)

R_SUM = 0.01
"""The noises the scales multiply, (m/s)²."""


def test_matched_scale_follows_the_innovations_noise() -> None:
    """Innovations whose noise is four times the given one (σ twice) bring λ to about
    4 within a few memories, whatever it started at."""
    rng = np.random.default_rng(1)
    for start in (0.1, 1.0, 30.0):
        lam, w = start, 0.0
        for y in rng.normal(0.0, math.sqrt(4.0 * R_SUM), 4000):
            s = lam * R_SUM  # no state uncertainty: S is the noises alone
            lam, w = matched_scale(lam, w, float(y), (s, 0.0, R_SUM), 200)
        assert 3.2 < lam < 4.8, (start, lam)


def test_one_outlier_moves_the_matched_scale_by_its_cap_at_most() -> None:
    """A 100σ innovation counts as a NIS of ADAPT_NIS_CAP: λ moves by at most
    (cap − 1)/W of itself, W the weights in memory."""
    lam, w = 1.0, 100.0
    new, w2 = matched_scale(lam, w, 100.0 * math.sqrt(R_SUM), (R_SUM, 0.0, R_SUM), 200)
    assert w2 == 100.0 * (1.0 - 1.0 / 200) + 1.0
    assert math.isclose(new, 1.0 + (ADAPT_NIS_CAP - 1.0) / w2)


def test_the_state_share_of_s_is_not_noise() -> None:
    """An innovation as large as the state's share of S says nothing of the noises: λ
    does not grow from it, where the same innovation against noise alone would."""
    y = math.sqrt(10.0 * R_SUM)
    with_state, _ = matched_scale(1.0, 50.0, y, (11.0 * R_SUM, 10.0 * R_SUM, R_SUM), 200)
    noise_only, _ = matched_scale(1.0, 50.0, y, (R_SUM, 0.0, R_SUM), 200)
    assert with_state < 1.0 < noise_only


def test_slow_scale_is_unmoved_by_a_consistent_filter_and_bounded() -> None:
    """λ_slow stays near 1 on innovations whose noise the filter was given, and stays
    within its bounds whatever it is fed."""
    rng = np.random.default_rng(2)
    slow = 1.0
    for k, y in enumerate(rng.normal(0.0, math.sqrt(R_SUM), 5000)):
        slow = slow_scale(slow, float(y), (slow * R_SUM, 0.0, R_SUM), 1.0 / min(k + 10, 500))
    assert 0.8 < slow < 1.25
    assert slow_scale(NOISE_SCALE_MIN, 0.0, (R_SUM, 0.0, R_SUM), 1.0) == NOISE_SCALE_MIN
    huge = slow_scale(NOISE_SCALE_MAX, 1e6, (R_SUM, 0.0, R_SUM), 1.0)
    assert huge == NOISE_SCALE_MAX
