"""Where a simulated trial's misalignment misses: the log's noise draw, or the rest of the
pipeline (``pytest -m soak -s``; docs/REPRODUCTION.md quotes the figures it prints).

Seed 3's figure-8 (the log turned 3°, its transverse axis 8 % low and 0.04 m/s off)
gives α 0.30° below the truth. Its own aligned series, as ``calibrate --axes 2`` pairs
it (the DVL's references and headings, its bottom-lock gaps, the lag, the current's
knots), refitted with the log's readings replaced by the true sensor's, noise-free and
with fresh noise draws, tells the two apart: the noise-free readings carry everything
but the noise draw."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from calib.models import FloatArray
from calib.twoaxis import TwoAxisSeries, fit_two_axis
from emlogd.offline.simtruth import read_truth
from emlogd.offline.simulate import EMLOG1, EMLOG2, simulate, with_sensor
from emlogd.offline.twoaxis import record_two_axis
from emlogd.pipeline.twoaxis_learn import CURRENT_KNOT_S

KNOT_MPS = 1852.0 / 3600.0
LAG_S = 0.46
"""The trials' ``--lag``: emlog2's latency, 0.45 s, and its VBW's transmission."""
TRUE_DELAY_S = 0.45 + 0.01
"""What separates a VBW's receive time from the water it read: the latency and the
line's transmission (its 38 bytes at 38400 baud)."""
FloatPair = tuple[float, float]


def _refits(directory: Path, alpha_deg: float, draws: int) -> tuple[float, float, FloatPair]:
    """α − truth, degrees: as recorded, with noise-free readings, and over ``draws``
    fresh noise draws (0.05 m/s on each axis, VBW's 0.01 kn) their mean and scatter."""
    truth = read_truth(directory)
    sensor = truth.two_axis("emlog2")
    a = record_two_axis(directory / "2-figure8.cap", "emlog2", "dvl").aligned(LAG_S)
    at = a.t - TRUE_DELAY_S
    ok = np.isfinite(truth.stw_at(at))
    rl0, rt0 = sensor.forward(truth.stw_at(at[ok]), truth.trans_at(at[ok]))

    def error(raw_l: FloatArray, raw_t: FloatArray) -> float:
        s = TwoAxisSeries.of(a.ref_fwd[ok], a.ref_stb[ok], raw_l, raw_t, a.heading[ok])
        fit = fit_two_axis("EM3", s, t_s=a.t[ok], current_knot_s=CURRENT_KNOT_S)
        return fit.misalign_deg - alpha_deg

    rng = np.random.default_rng(7)

    def noisy(x: FloatArray) -> FloatArray:
        return np.asarray(
            np.round((x + rng.normal(0.0, 0.05, x.size)) / KNOT_MPS, 2) * KNOT_MPS, dtype=np.float64
        )

    fresh = np.array([error(noisy(rl0), noisy(rt0)) for _ in range(draws)])
    spread = (float(np.mean(fresh)), float(np.std(fresh, ddof=1)))
    return error(a.raw_l[ok], a.raw_t[ok]), error(rl0, rt0), spread


@pytest.mark.soak
def test_seed_3_misses_by_its_noise_draw(tmp_path: Path) -> None:
    """Seed 3 at 3°: as recorded α is 0.25–0.35° low; with the same series' readings
    noise-free within 0.05° of the truth, and over 20 fresh noise draws the mean error
    within 0.1° of 0 and the scatter below 0.2° (the σ the fit states, 0.14°)."""
    sensor = with_sensor(EMLOG2, {"misalign": 3.0, "mt": -0.08, "bt": 0.04})
    simulate(tmp_path, seed=3, emlogs=(EMLOG1, sensor))
    recorded, noise_free, (mean, scatter) = _refits(tmp_path, 3.0, 20)
    sys.stdout.write(
        f"seed 3, 3°: as recorded {recorded:+.3f}°, noise-free {noise_free:+.3f}°, "
        f"20 fresh draws {mean:+.3f} ± {scatter / math.sqrt(20):.3f}° (scatter {scatter:.3f}°)\n"
    )
    assert -0.35 < recorded < -0.25
    assert abs(noise_free) < 0.05
    assert abs(mean) < 0.1
    assert scatter < 0.2
