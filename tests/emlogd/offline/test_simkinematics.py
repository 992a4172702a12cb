"""The simulated trial's vessel motion."""

from __future__ import annotations

import numpy as np
import pytest

from emlogd.offline.simkinematics import TRAJECTORIES, kinematics


def test_constant_speed_circles() -> None:
    """circles="constant" flies the circles at one speed and draws the same random numbers."""
    spec = TRAJECTORIES[3]
    rng_s, rng_c = np.random.default_rng(3), np.random.default_rng(3)
    steps = kinematics(spec, 1440.0, rng_s)
    const = kinematics(spec, 1440.0, rng_c, circles="constant")
    assert steps.surge.std() > 0.1
    assert const.surge.std() < 1e-9
    assert const.surge.mean() == pytest.approx(spec.mean_mps)
    assert np.array_equal(steps.heading, const.heading)
    assert rng_s.random() == rng_c.random()  # later draws (sensors, faults) do not move
