"""The lags scored each on the readings that overlap the reference at that lag: a
reference with outages, minutes off (calib.lagscan)."""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import DataError
from calib.lag import CURRENT_BLOCK_S, CurrentBlocks, estimate_lag
from calib.lagscan import _adjusted, scan_lags

_KNOTS = np.random.default_rng(11).uniform(1.0, 4.0, 200)
"""A speed that wanders between 1 and 4 m/s, a new value every 10 s (never periodic)."""


def _speed(t: np.ndarray) -> np.ndarray:
    return np.asarray(np.interp(t, 10.0 * np.arange(_KNOTS.size), _KNOTS), dtype=np.float64)


def _series(shift_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Readings at 1 Hz over 300 s, and a 2 Hz reference over 660 s around them stamped
    ``shift_s`` late with a 40-s outage every 200 s."""
    tm = np.arange(600.0, 900.0)
    tr = np.arange(420.0, 1080.0, 0.5)
    tr = tr[(tr - 420.0) % 200.0 < 160.0]
    vr = _speed(tr - shift_s) + 0.01 * np.sin(7.0 * tr)
    return tm, _speed(tm), tr, vr


@pytest.mark.parametrize("shift_s", [120.0, -120.0, 0.0])
def test_a_gapped_reference_minutes_off_is_found(shift_s: float) -> None:
    """Every lag over ±180 s faces an outage for some readings, so scoring them all on
    the same readings leaves none; each lag on its own overlap finds the offset."""
    tm, vm, tr, vr = _series(shift_s)
    with pytest.raises(DataError, match="overlap"):
        estimate_lag(tm, vm, tr, vr, 180.0, step_s=1.0, min_samples=150, split=False)
    est = scan_lags(tm, vm, tr, vr, 180.0, step_s=1.0, min_samples=150, at_s=0.5)
    assert est.lag_s == pytest.approx(-shift_s, abs=1.0)
    assert est.peak_corr > 0.95 and not est.at_bound
    assert 150 <= est.n_samples < tm.size  # the readings facing an outage left out
    if shift_s:
        assert est.peak_corr - est.corr_at > 0.3


def test_the_water_frame_scores_a_current_away() -> None:
    """Over the ground with a current of 0.5 m/s swinging with the heading (a turn every
    minute): the offset is still found, the current fitted at every lag."""
    tm, vm, tr, _ = _series(120.0)
    heading = (np.arange(tr[0], tr[-1] + 1.0) * 6.0) % 360.0
    th = np.arange(tr[0], tr[-1] + 1.0)
    cur = 0.5 * np.cos(np.radians(np.interp(tr, th, heading)))
    vr = _speed(tr - 120.0) + cur
    est = scan_lags(tm, vm, tr, vr, 180.0, step_s=1.0, min_samples=150, heading=(th, heading))
    assert est.lag_s == pytest.approx(-120.0, abs=1.0)


def test_too_few_readings_anywhere_is_refused() -> None:
    """No lag overlaps ``min_samples`` readings: no estimate; the lag in use overlapping
    too few scores nan."""
    tm, vm, tr, vr = _series(120.0)
    with pytest.raises(DataError, match="overlaps"):
        scan_lags(tm, vm, tr, vr, 180.0, step_s=1.0, min_samples=tm.size + 1)
    est = scan_lags(tm, vm, tr, vr, 180.0, step_s=1.0, min_samples=150, at_s=1000.0)
    assert np.isnan(est.corr_at)


def test_a_lag_is_not_favoured_by_fewer_readings() -> None:
    """Noise against noise on 30 readings with a level and a drifting current fitted in
    each of two blocks (11 unknowns): the adjusted score's median is about zero, where
    the plain fit's R² would sit near 11/30 (fewer readings at a lag would look better)."""
    rng = np.random.default_rng(3)
    t = np.arange(30.0) * 21.0
    blocks = CurrentBlocks(t, CURRENT_BLOCK_S)
    r2 = []
    for _ in range(200):
        psi = rng.uniform(0.0, 2.0 * np.pi, t.size)
        c, s = np.cos(psi), np.sin(psi)
        X = np.stack((np.ones(t.size), c, s, blocks.tau * c, blocks.tau * s), axis=1)
        score = _adjusted(rng.normal(size=t.size), X, rng.normal(size=t.size), blocks)
        r2.append(score * abs(score))
    assert len(blocks.spans) == 2
    assert abs(float(np.median(r2))) < 0.05
