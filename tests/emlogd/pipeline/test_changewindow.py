"""What a change of the readings is measured on, and how far it re-opens the parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.kalman import KfCalibrator, KfConfig
from emlogd.pipeline.changewindow import (
    CHANGE_BLOCKS,
    CHANGE_BLOCKS_S,
    CHANGE_MIN_SAMPLES,
    CHANGE_WINDOW_S,
    ChangeWindow,
    widen,
)


def test_a_change_is_the_mean_innovation_of_the_last_window() -> None:
    """Sample by sample: the mean raw innovation of the last CHANGE_WINDOW_S and the mean
    speed; older innovations are forgotten, and the measurement uses them up."""
    w = ChangeWindow()
    w.add_sample(0.0, 5.0, 9.0)  # older than the window at the end
    for k in range(10):
        w.add_sample(CHANGE_WINDOW_S + 1.0 + k, 0.3 if k % 2 else 0.1, 2.0)
    change = w.sample_change()
    assert change is not None
    assert change[0] == pytest.approx(0.2) and change[1] == pytest.approx(2.0)
    assert not w.recent


def test_too_few_innovations_measure_no_change() -> None:
    """Fewer than CHANGE_MIN_SAMPLES: no measure (the parameters re-open to their
    prior), and the few are kept."""
    w = ChangeWindow()
    for k in range(CHANGE_MIN_SAMPLES - 1):
        w.add_sample(float(k), 0.5, 2.0)
    assert w.sample_change() is None
    assert len(w.recent) == CHANGE_MIN_SAMPLES - 1


def test_a_step_inside_the_blocks_shows_in_the_blocks_since_it() -> None:
    """From block means: the largest mean over the last k blocks with its variance
    added, k up to CHANGE_BLOCKS; a step two blocks ago is measured on those two."""
    w = ChangeWindow()
    for k, y in enumerate([0.0, 0.0, 0.0, 0.0, 0.45, 0.35]):
        w.add_block(20.0 * k, y, 0.01, 2.0 + k)
    change = w.block_change()
    assert change is not None
    assert change[0] == pytest.approx(math.sqrt(0.4**2 + 0.01 / 2))  # not the last alone
    assert change[1] == pytest.approx((6.0 + 7.0) / 2)
    assert w.block_change() is None  # used up


def test_old_blocks_measure_nothing() -> None:
    """Blocks older than CHANGE_BLOCKS_S before the last are dropped, and at most
    CHANGE_BLOCKS are kept."""
    w = ChangeWindow()
    w.add_block(0.0, 3.0, 0.0, 2.0)
    w.add_block(CHANGE_BLOCKS_S + 1.0, 0.1, 0.0, 2.0)
    assert len(w.blocks) == 1
    for k in range(2 * CHANGE_BLOCKS):
        w.add_block(400.0 + k, 0.1, 0.0, 2.0)
    assert len(w.blocks) == CHANGE_BLOCKS


def test_a_change_widens_each_parameter_by_what_it_alone_would_take() -> None:
    """δ = 0.6 m/s at 2 m/s: the scale's variance grows by (δ/v)², the bias's by δ²
    (each at most its prior)."""
    kf = KfCalibrator("EM3", KfConfig(p0=1.0), P0=np.diag([1.0, 0.01, 0.01]))
    widen(kf, ["m", "b"], 0.6, 2.0)
    assert kf.param_std["m"] ** 2 == pytest.approx(0.01 + 0.09)
    assert kf.param_std["b"] ** 2 == pytest.approx(0.01 + 0.36)
    widen(kf, ["m"], 3.0, 2.0)  # (δ/v)² = 2.25: up to the prior, the bias as it was
    assert kf.param_std["m"] == pytest.approx(1.0)
    assert kf.param_std["b"] ** 2 == pytest.approx(0.37)
