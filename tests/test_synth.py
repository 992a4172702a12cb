"""Synthetic trial data."""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import DataError
from calib.models import Params
from tests.synth import (
    PAPER_TRIAL,
    heading_profile,
    paper_trial,
    simulate_segment,
    speed_profile,
    water_frame_segment,
)

TRUTH = Params("EM3", m=0.05, b_mps=0.1)


class TestSynth:
    """Seeded, plausible synthetic segments."""

    def test_paper_trial_sizes(self) -> None:
        """The 221-minute trial at 1 Hz has 13 260 samples in five named segments."""
        segs = paper_trial(TRUTH, np.random.default_rng(0))
        assert [s.name for s in segs] == [k for k, _ in PAPER_TRIAL]
        assert sum(np.asarray(s.t_s).size for s in segs) == 13260

    def test_deterministic(self) -> None:
        """The same seed gives the same data."""
        a = simulate_segment("x", "circles", 60.0, 10.0, TRUTH, np.random.default_rng(5))
        b = simulate_segment("x", "circles", 60.0, 10.0, TRUTH, np.random.default_rng(5))
        np.testing.assert_array_equal(a.raw_mps, b.raw_mps)

    @pytest.mark.parametrize("kind", [k for k, _ in PAPER_TRIAL])
    def test_profiles_positive_with_paper_mean(self, kind: str) -> None:
        """Each profile is positive with a mean within 0.1 m/s of the paper's."""
        t = np.arange(0.0, 1800.0)
        v = speed_profile(kind, t, np.random.default_rng(1))  # type: ignore[arg-type]
        assert np.all(v > 0.0)
        means = {"transit": 1.95, "figure-8": 1.48, "straight": 1.59, "circles": 1.85}
        assert float(np.mean(v)) == pytest.approx(means.get(kind, 1.37), abs=0.1)

    def test_straight_has_little_excitation(self) -> None:
        """The straight segment varies far less than the figure-8."""
        t = np.arange(0.0, 900.0)
        rng = np.random.default_rng(2)
        assert (
            np.std(speed_profile("straight", t, rng))
            < 0.1
            < np.std(speed_profile("figure-8", t, rng))
        )

    def test_bad_arguments(self) -> None:
        """Unknown kinds and non-positive durations raise DataError."""
        with pytest.raises(DataError):
            speed_profile("zigzag", np.arange(3.0), np.random.default_rng(0))  # type: ignore[arg-type]
        with pytest.raises(DataError):
            simulate_segment("x", "straight", 0.0, 1.0, TRUTH, np.random.default_rng(0))


class TestWaterFrameSegment:
    """Synthetic segments with a current seen through the heading."""

    def test_the_reference_is_the_ground_speed_along_the_hull(self) -> None:
        """Without noise, ref = u + c_N·cos ψ + c_E·sin ψ and raw = f(u)."""
        truth = Params("EM3", m=0.05, b_mps=0.1)
        s = water_frame_segment(
            "figure-8",
            300.0,
            2.0,
            truth,
            np.random.default_rng(1),
            sigma_raw_mps=0.0,
            sigma_ref_mps=0.0,
            current_mps=(0.2, -0.1),
        )
        psi = np.radians(s.heading_deg)
        np.testing.assert_allclose(s.ref_mps, s.u_water_mps + 0.2 * np.cos(psi) - 0.1 * np.sin(psi))
        np.testing.assert_allclose(s.raw_mps, 1.05 * s.u_water_mps + 0.1)
        assert s.t_s.size == 600 and s.current_mps.shape == (600, 2)

    def test_constant_speed_and_heading_profiles(self) -> None:
        """Constant-speed circles turn a full circle every 120 s; a straight holds its course."""
        rng = np.random.default_rng(2)
        s = water_frame_segment("circles", 240.0, 1.0, Params("EM1"), rng, constant_speed=True)
        assert np.ptp(s.u_water_mps) == 0.0
        steps = np.diff(np.unwrap(np.radians(s.heading_deg)))
        assert np.degrees(np.sum(steps)) == pytest.approx(717.0, abs=1.0)
        straight = heading_profile("straight", np.arange(0.0, 600.0), rng)
        assert np.ptp(np.unwrap(np.radians(straight))) < np.radians(2.5)
