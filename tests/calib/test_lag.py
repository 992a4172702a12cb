"""Lag estimation by normalised cross-correlation."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import calib.lag
from calib.errors import DataError
from calib.lag import LagEstimate, accept, combine, estimate_lag
from calib.models import Params
from tests.synth import WaterFrameSeries, water_frame_segment


def _speed(t: np.ndarray) -> np.ndarray:
    """A manoeuvring speed profile (m/s) rich enough to correlate."""
    return 1.5 + 0.6 * np.sin(2 * np.pi * t / 95.0) + 0.3 * np.sin(2 * np.pi * t / 37.0 + 1.0)


def _segment(
    kind: str, seconds: float, seed: int, current: tuple[float, float]
) -> WaterFrameSeries:
    """A 10 Hz water-frame segment of a log with m = 0.09, b = 0.08 m/s and 0.03 m/s of noise."""
    return water_frame_segment(
        kind,  # type: ignore[arg-type]
        seconds,
        10.0,
        Params("EM3", m=0.09, b_mps=0.08),
        np.random.default_rng(seed),
        current_mps=current,
        sigma_raw_mps=0.03,
    )


def _water_lag(
    seg: WaterFrameSeries,
    late_s: float,
    max_lag_s: float,
    *,
    ref: np.ndarray | None = None,
    keep: np.ndarray | None = None,
) -> LagEstimate:
    """The water-frame lag of the segment's log read at 1 Hz ``late_s`` behind its 10 Hz
    reference (``ref`` instead of the segment's), the reference and heading only where
    ``keep``."""
    ref_mps = seg.ref_mps if ref is None else ref
    k = np.ones(seg.t_s.size, dtype=bool) if keep is None else keep
    return estimate_lag(
        seg.t_s[::10] + late_s,
        seg.raw_mps[::10],
        seg.t_s[k],
        ref_mps[k],
        max_lag_s,
        step_s=0.1,
        heading=(seg.t_s[k], seg.heading_deg[k]),
    )


class TestEstimateLag:
    """estimate_lag finds the delay across rates."""

    def test_3_2_s_between_1_hz_and_10_hz(self) -> None:
        """A 3.2 s delay of a 1 Hz series behind a 10 Hz reference is found within 0.1 s."""
        rng = np.random.default_rng(3)
        t_ref = np.arange(0.0, 1200.0, 0.1)
        v_ref = _speed(t_ref) + rng.normal(0.0, 0.01, t_ref.size)
        t_meas = np.arange(5.0, 1195.0, 1.0) + 0.37
        v_meas = 1.05 * _speed(t_meas - 3.2) + 0.1 + rng.normal(0.0, 0.05, t_meas.size)
        est = estimate_lag(t_meas, v_meas, t_ref, v_ref, 10.0)
        assert est.lag_s == pytest.approx(3.2, abs=0.1)
        assert est.peak_corr > 0.95
        assert not est.at_bound

    def test_reference_outage_is_not_interpolated_across(self) -> None:
        """Samples that could meet a reference outage at any candidate lag are left out."""
        t_ref = np.arange(0.0, 1200.0, 0.1)
        lost = (t_ref > 500.0) & (t_ref < 560.0)  # a minute without bottom lock
        t_ref, v_ref = t_ref[~lost], _speed(t_ref[~lost])
        t_meas = np.arange(0.0, 1200.0, 1.0) + 0.37
        v_meas = _speed(t_meas - 3.2)
        est = estimate_lag(t_meas, v_meas, t_ref, v_ref, 10.0, step_s=0.1)
        assert est.lag_s == pytest.approx(3.2, abs=0.05)
        assert est.peak_corr > 0.999
        margin = 10.0 + 2.0  # the lag reach and the smoothing width
        inside = (t_meas - 10.0 >= 0.0) & (t_meas + 10.0 <= t_ref[-1])
        near = (t_meas + margin > 500.0 - 0.05) & (t_meas - margin < 560.0)
        assert est.n_samples == int(np.count_nonzero(inside & ~near))

    def test_sub_sample_refinement(self) -> None:
        """A lag between grid points is refined beyond the grid step (0.45 s on a 1 s grid)."""
        t = np.arange(0.0, 1200.0, 1.0)
        est = estimate_lag(t, _speed(t - 0.45), t, _speed(t), 5.0)
        assert est.step_s == pytest.approx(1.0)
        assert est.lag_s == pytest.approx(0.45, abs=0.08)

    def test_negative_lag(self) -> None:
        """A measurement ahead of the reference gives a negative lag."""
        t_ref = np.arange(0.0, 900.0, 0.1)
        t_meas = np.arange(0.0, 900.0, 0.2)
        est = estimate_lag(t_meas, _speed(t_meas + 1.5), t_ref, _speed(t_ref), 5.0)
        assert est.lag_s == pytest.approx(-1.5, abs=0.05)

    def test_peak_at_bound_flagged(self) -> None:
        """A true lag outside the searched range is reported at the bound."""
        t = np.arange(0.0, 900.0, 0.5)
        est = estimate_lag(t, _speed(t - 8.0), t, _speed(t), 3.0)
        assert est.at_bound and est.lag_s == pytest.approx(3.0)

    def test_uncorrelated_noise_has_low_quality(self) -> None:
        """Independent noise series give a low peak correlation."""
        rng = np.random.default_rng(4)
        t = np.arange(0.0, 600.0, 1.0)
        est = estimate_lag(t, rng.normal(size=t.size), t, rng.normal(size=t.size), 5.0)
        assert est.peak_corr < 0.3

    def test_rejects_bad_input(self) -> None:
        """Unsorted times, too little overlap or a non-positive range raise DataError."""
        t = np.arange(0.0, 100.0, 1.0)
        with pytest.raises(DataError, match="increasing"):
            estimate_lag(t[::-1], t, t, t, 5.0)
        with pytest.raises(DataError, match="overlap"):
            estimate_lag(t, t, t + 90.0, t, 5.0)
        with pytest.raises(DataError, match="max_lag_s"):
            estimate_lag(t, t, t, t, 0.0)


class TestWaterFrameLag:
    """A current seen through the heading cannot shift the lag."""

    @pytest.mark.parametrize("kind", ["figure-8", "circles"])
    def test_current_does_not_bias_the_lag(self, kind: str) -> None:
        """In 0.3 m/s of current the water-frame lag is within 0.1 s; the plain one misses or is refused."""
        seg = _segment(kind, 900.0, 2, (-0.3, 0.1))
        t_meas, v_meas = seg.t_s[::10] + 3.2, seg.raw_mps[::10]
        plain = estimate_lag(t_meas, v_meas, seg.t_s, seg.ref_mps, 10.0, step_s=0.1)
        water = _water_lag(seg, 3.2, 10.0)
        assert water.lag_s == pytest.approx(3.2, abs=0.1)
        assert abs(plain.lag_s - 3.2) > 0.1 or accept(plain) != ""
        assert accept(water) == ""

    def test_a_drifting_current_does_not_bias_the_lag(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """A current turning within the window is fitted per block: the lag stays within 0.1 s.

        Fitted as one constant over the window, the same current pulls the peak off or
        leaves it refused.
        """
        seg = _segment("figure-8", 1500.0, 5, (0.0, 0.0))
        # The tide turns during the run: (−0.25, +0.15) m/s to (+0.15, −0.20) m/s.
        f = (seg.t_s - seg.t_s[0]) / (seg.t_s[-1] - seg.t_s[0])
        c_n, c_e = -0.25 + 0.40 * f, 0.15 - 0.35 * f
        psi = np.radians(seg.heading_deg)
        ref = seg.ref_mps + c_n * np.cos(psi) + c_e * np.sin(psi)
        blocks = _water_lag(seg, 3.2, 10.0, ref=ref)
        assert blocks.lag_s == pytest.approx(3.2, abs=0.1)
        assert accept(blocks) == ""
        monkeypatch.setattr(calib.lag, "CURRENT_BLOCK_S", 1e9)
        constant = _water_lag(seg, 3.2, 10.0, ref=ref)
        assert abs(constant.lag_s - 3.2) > 0.1 or accept(constant) != ""

    def test_the_coarse_search_finds_what_every_lag_finds(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """Scoring coarse lags first, then the steps around the best, gives the estimate of
        scoring every step (the water-frame score is smooth at the coarse step)."""
        seg = _segment("figure-8", 900.0, 3, (-0.2, 0.15))
        coarse = _water_lag(seg, 1.7, 8.0)
        monkeypatch.setattr(calib.lag, "COARSE_STEP_S", 0.1)
        assert _water_lag(seg, 1.7, 8.0) == coarse
        assert coarse.lag_s == pytest.approx(1.7, abs=0.1)

    def test_a_gap_longer_than_a_current_block(self) -> None:
        """A reference outage longer than a current block leaves that block empty: it is
        dropped (no division by an empty block), and the lag is still found."""
        seg = _segment("figure-8", 1800.0, 3, (-0.2, 0.15))
        out = (seg.t_s > 600.0) & (seg.t_s < 1300.0)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            est = _water_lag(seg, 2.0, 8.0, keep=~out)
        assert est.lag_s == pytest.approx(2.0, abs=0.3)

    def test_standard_error_and_acceptance(self) -> None:
        """A broad peak has a large standard error and is refused; a bound peak is refused."""
        t = np.arange(0.0, 300.0, 1.0)
        slow = 1.5 + 0.2 * np.sin(2 * np.pi * t / 600.0)
        rng = np.random.default_rng(5)
        est = estimate_lag(t, slow + rng.normal(0, 0.05, t.size), t, slow, 10.0, step_s=0.1)
        assert est.std_s > 0.15
        assert "broad" in accept(est)
        bound = estimate_lag(t, _speed(t - 8.0), t, _speed(t), 3.0)
        assert "bound" in accept(bound)

    def test_a_negative_or_too_long_lag_is_never_accepted(self) -> None:
        """A sharp peak at a negative lag, or beyond max_lag_s, is refused with the reason."""
        sharp = LagEstimate(-0.5, 0.99, 0.1, 1000, False, 0.01)
        assert "negative" in accept(sharp)
        assert accept(LagEstimate(0.0, 0.99, 0.1, 1000, False, 0.01)) == ""
        late = LagEstimate(4.0, 0.99, 0.1, 1000, False, 0.01)
        assert accept(late, max_lag_s=5.0) == ""
        assert "max_lag_s" in accept(late, max_lag_s=3.0)

    def test_combine_is_a_weighted_median(self) -> None:
        """combine() leans on the sharp estimates and ignores one outlier."""
        e = [
            LagEstimate(3.2, 0.9, 0.1, 100, False, 0.03),
            LagEstimate(3.25, 0.9, 0.1, 100, False, 0.05),
            LagEstimate(4.5, 0.9, 0.1, 100, False, 0.5),
        ]
        assert combine(e) == pytest.approx(3.2)
        with pytest.raises(DataError):
            combine([])
