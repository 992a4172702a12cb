"""The two-axis model learnt by the extended Kalman filter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.models import Params
from calib.twoaxis import ALPHA, TwoAxisParams
from calib.twoaxis_kf import kf_two_axis

# The same trials as tests/calib/test_twoaxis.py, for the filter.
CURRENT_NE = (0.15, -0.1)
TRUTH = TwoAxisParams(Params("EM3", m=-0.11, b_mps=-0.05), math.radians(3.0), -0.09, 0.04)
"""A sensor turned 3° to starboard, the transverse scale 2 % off the longitudinal one."""


def _trial(
    kind: str, truth: TwoAxisParams, seed: int, n: int = 16200, dt: float = 0.1
) -> dict[str, np.ndarray]:
    """27 min at 10 Hz of one manoeuvre, as the simulator flies it: heading, surge,
    sway (−0.6·rate·surge in turns), a constant current, a DVL and a two-axis log
    with 0.05 m/s of noise on each axis."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    ph = rng.uniform(0.0, 2.0 * math.pi)
    if kind == "figure-8":
        om = 2.0 * math.pi / 90.0
        rate = 2.405 * om * np.cos(om * t + ph)
        u = 1.83 - 0.7 * np.cos(om * t + ph) ** 2
    elif kind == "circles":
        rate = np.full(n, 2.0 * math.pi / 120.0)
        u = 1.85 + 0.3 * np.sign(np.sin(2.0 * math.pi * t / 240.0 + ph))
    else:
        rate = 0.002 * np.sin(2.0 * math.pi * t / 60.0 + ph)
        u = 1.59 + 0.02 * np.sin(2.0 * math.pi * t / 120.0)
    psi = rng.uniform(0.0, 2.0 * math.pi) + np.cumsum(rate) * dt
    w = -0.6 * rate * u
    cn, ce = CURRENT_NE
    gf = u + cn * np.cos(psi) + ce * np.sin(psi)
    gs = w - cn * np.sin(psi) + ce * np.cos(psi)
    rl, rt = truth.forward(u, w)
    return {
        "t": t,
        "u": u,
        "w": w,
        "hd": np.degrees(psi) % 360.0,
        "gf": gf + rng.normal(0.0, 0.01, n),
        "gs": gs + rng.normal(0.0, 0.01, n),
        "rl": rl + rng.normal(0.0, 0.05, n),
        "rt": rt + rng.normal(0.0, 0.05, n),
    }


class TestKalman:
    def test_kf_recovers_three_degrees_on_figure8(self) -> None:
        """The filter, sample by sample: α within 0.3°, the current shared."""
        d = _trial("figure-8", TRUTH, seed=10)
        fit = kf_two_axis("EM3", d["t"], d["gf"], d["gs"], d["rl"], d["rt"], d["hd"])
        assert fit.method == "KF"
        assert fit.misalign_deg == pytest.approx(3.0, abs=0.3)
        assert fit.misalign_std_deg is not None and fit.misalign_std_deg < 0.3
        assert fit.current_mps == pytest.approx(CURRENT_NE, abs=0.02)

    def test_kf_holds_misalignment_on_straight_run(self) -> None:
        d = {k: v[::5] for k, v in _trial("straight", TRUTH, seed=11).items()}
        fit = kf_two_axis("EM3", d["t"], d["gf"], d["gs"], d["rl"], d["rt"], d["hd"])
        assert ALPHA in fit.ident.unidentifiable
        assert fit.misalign_deg == 0.0
