"""Identifiability of every unknown, judged in the water frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import DataError
from calib.excitation import (
    ExcitationRule,
    ExcitationWindow,
    heading_sectors,
    identifiability,
    judge,
    structural,
    window_stats,
)
from calib.models import Layout, Params
from tests.synth import TrajectoryKind, WaterFrameSeries, water_frame_segment

SIGMA2 = 0.05**2
EM3C = Layout("EM3", current=True)


def _seg(
    kind: TrajectoryKind, *, constant: bool = False, seconds: float = 1200.0, seed: int = 1
) -> WaterFrameSeries:
    return water_frame_segment(
        kind,
        seconds,
        1.0,
        Params("EM3", m=0.05, b_mps=0.1),
        np.random.default_rng(seed),
        current_mps=(0.25, -0.2),
        constant_speed=constant,
    )


class TestWindowStats:
    """The five-column information matrix and the speed figures."""

    def test_em3_block_is_the_papers_matrix(self) -> None:
        """The (u, 1) block is the paper's HᵀH, whose determinant is N²·var(u)."""
        u = np.random.default_rng(1).uniform(1.0, 3.0, 500)
        st = window_stats(u, u, np.zeros(500))
        block = st.info[1:3, 1:3]
        np.testing.assert_allclose(
            block, np.array([[np.sum(u * u), np.sum(u)], [np.sum(u), 500.0]])
        )
        assert np.linalg.det(block) == pytest.approx(500**2 * np.var(u), rel=1e-9)

    def test_speed_figures_come_from_the_readings(self) -> None:
        """The speed statistics are those of the UUT's readings, not of the reference."""
        st = window_stats(np.linspace(1.0, 3.0, 100), np.full(100, 2.0))
        assert st.speed_std_mps == 0.0 and st.speed_mean_mps == 2.0

    def test_bad_input_raises(self) -> None:
        """Empty or non-finite windows raise DataError."""
        with pytest.raises(DataError):
            window_stats([], [])
        with pytest.raises(DataError):
            window_stats([1.0, math.nan], [1.0, 1.0])


class TestVerdicts:
    """Which unknowns a window determines, and why not."""

    def test_figure8_in_a_current_determines_everything(self) -> None:
        """A figure-8 determines scale, bias and current."""
        s = _seg("figure-8")
        ident = identifiability(EM3C, s.u_water_mps, s.raw_mps, SIGMA2, heading_deg=s.heading_deg)
        assert ident.identifiable and ident.unidentifiable == () and ident.reason == ""
        assert all(v.std is not None for v in ident.verdicts)

    def test_speed_that_follows_the_heading_leaves_the_scale_to_the_current(self) -> None:
        """A slalom whose speed dips at one heading: a scale error and a current look the
        same, so with the current the scale is refused (and accepted without it)."""
        t = np.arange(0.0, 1800.0, 0.5)
        swing = 2.405 * np.sin(2 * np.pi * t / 90.0)
        heading = np.degrees(0.7 + swing) % 360.0
        u = 1.8 - 0.7 * np.cos(2 * np.pi * t / 90.0) ** 2
        ident = identifiability(EM3C, u, 1.1 * u + 0.1, SIGMA2, heading_deg=heading)
        assert ident.unidentifiable == ("m",)
        assert "follows the heading" in ident.reason
        plain = identifiability(Layout("EM3"), u, 1.1 * u + 0.1, SIGMA2)
        assert plain.identifiable

    def test_circles_at_constant_speed_leave_the_scale_undetermined(self) -> None:
        """Circling at constant speed in a current: no scale, but bias and current."""
        s = _seg("circles", constant=True)
        ident = identifiability(EM3C, s.u_water_mps, s.raw_mps, SIGMA2, heading_deg=s.heading_deg)
        assert ident.unidentifiable == ("m",)
        assert ident.verdict("m").reason.startswith(
            "scale not determinable: speed through water nearly constant (spread 0.05 m/s)"
        )
        assert ident.verdict("b").determined and ident.verdict("current").determined

    def test_the_ground_speed_swing_of_a_circle_is_not_excitation(self) -> None:
        """Without current states too, the reference's swing in a current excites no scale."""
        s = _seg("circles", constant=True)
        assert np.std(s.ref_mps) > 0.2
        ident = identifiability(Layout("EM3"), s.ref_mps, s.raw_mps, SIGMA2)
        assert ident.unidentifiable == ("m",)

    def test_a_straight_line_does_not_separate_bias_and_current(self) -> None:
        """On a straight line bias and current are one unknown; a changing speed still gives the scale."""
        s = _seg("transit", seconds=400.0, seed=4)
        ident = identifiability(EM3C, s.u_water_mps, s.raw_mps, SIGMA2, heading_deg=s.heading_deg)
        assert set(ident.unidentifiable) == {"b", "current"}
        assert ident.verdict("current").reason == (
            "current not separable from bias: heading covered 1 of 8 sectors"
        )
        assert ident.verdict("m").determined and ident.nuisance_offset

    def test_em2_at_rest_has_no_scale(self) -> None:
        """A vessel at rest says nothing about EM2's scale factor."""
        v = np.random.default_rng(2).normal(0.0, 0.02, 300)
        ident = identifiability(Layout("EM2"), v, v, SIGMA2)
        assert ident.unidentifiable == ("m",) and "too low" in ident.reason

    def test_too_few_samples(self) -> None:
        """Fewer than min_samples_per_param per unknown determine nothing."""
        u = np.linspace(1.0, 3.0, 15)
        ident = identifiability(Layout("EM3"), u, u, SIGMA2)
        assert ident.unidentifiable == ("m", "b") and "too few samples" in ident.reason

    def test_weak_excitation_is_refused_by_the_standard_deviation(self) -> None:
        """A scale whose σ from the information matrix exceeds max_std_m is refused."""
        u = np.linspace(1.5, 1.8, 60)
        ident = identifiability(
            Layout("EM3"), u, u, 0.3**2, rule=ExcitationRule(min_speed_std_mps=0.0)
        )
        assert "m" in ident.unidentifiable and "weak excitation" in ident.verdict("m").reason

    def test_rule_validation(self) -> None:
        """Thresholds out of range raise ValueError."""
        with pytest.raises(ValueError):
            ExcitationRule(min_heading_sectors=9)
        with pytest.raises(ValueError):
            ExcitationRule(max_cond=0.5)
        with pytest.raises(ValueError):
            ExcitationRule(max_std_m=0.0)


class TestHeadingSectors:
    """Coverage of the compass."""

    def test_sectors_wrap_across_north(self) -> None:
        """350° to 10° covers two sectors, not eight."""
        assert heading_sectors(np.linspace(-10.0, 10.0, 100) % 360.0) == 2

    def test_a_full_turn_covers_eight(self) -> None:
        """A full circle covers all eight sectors; a stray sample does not count."""
        assert heading_sectors(np.arange(0.0, 360.0, 1.0)) == 8
        assert heading_sectors(np.r_[np.full(500, 90.0), 270.0]) == 1

    @pytest.mark.parametrize("span", [10.0, 100.0, 200.0, 360.0])
    def test_the_window_counts_sectors_as_the_batch_does(self, span: float) -> None:
        """ExcitationWindow without forgetting counts the sectors of its headings as
        heading_sectors does (a sector with under 3 % of the samples not counted); a
        window without a heading has no count."""
        hd = np.random.default_rng(int(span)).uniform(0.0, span, 200)
        hd = np.r_[hd, np.full(4, (span + 50.0) % 360.0)]  # a stray sector, under 3 %
        w = ExcitationWindow(EM3C)
        for h in hd:
            w.add(2.0, 2.0, float(h))
        assert w.stats().heading_sectors == heading_sectors(hd)
        assert ExcitationWindow(EM3C).stats().heading_sectors is None


class TestStructural:
    """The rules no noise level changes, on their own."""

    def test_structural_refuses_what_judge_refuses_for_any_noise(self) -> None:
        """On a straight run at one speed, structural refuses the scale (speed constant),
        and the current and bias together (one sector), as judge does at any noise."""
        s = _seg("straight", constant=True, seconds=600.0, seed=3)
        stats = window_stats(s.u_water_mps, s.raw_mps, s.heading_deg)
        refused, offset = structural(EM3C, stats)
        assert set(refused) == {"m", "b", "current"} and offset
        for sigma2 in (1e-6, SIGMA2, 1.0):
            ident = judge(EM3C, stats, sigma2)
            assert {v.unknown: v.reason for v in ident.verdicts if not v.determined} == refused


class TestExcitationWindow:
    """The online window applies the same rule."""

    @pytest.mark.parametrize("kind", ["figure-8", "circles", "transit"])
    def test_without_forgetting_it_equals_the_batch_verdict(self, kind: TrajectoryKind) -> None:
        """A window with no forgetting gives the batch verdicts and information matrix."""
        s = _seg(kind, constant=kind == "circles", seconds=600.0)
        win = ExcitationWindow(EM3C)
        for u, r, h in zip(s.u_water_mps, s.raw_mps, s.heading_deg, strict=True):
            win.add(float(u), float(r), float(h))
        online = win.evaluate(SIGMA2)
        batch = identifiability(EM3C, s.u_water_mps, s.raw_mps, SIGMA2, heading_deg=s.heading_deg)
        assert online.unidentifiable == batch.unidentifiable
        np.testing.assert_allclose(online.stats.info, batch.stats.info, rtol=1e-9, atol=1e-9)
        assert online.stats.heading_sectors == batch.stats.heading_sectors

    def test_forgetting_lets_a_constant_phase_take_over(self) -> None:
        """After a figure-8, a long constant-speed straight leaves scale and current undetermined."""
        eight, straight = _seg("figure-8", seconds=600.0), _seg("straight", seconds=1800.0)
        win = ExcitationWindow(EM3C, half_life_samples=120.0)
        for s in (eight, straight):
            for u, r, h in zip(s.u_water_mps, s.raw_mps, s.heading_deg, strict=True):
                win.add(float(u), float(r), float(h))
        assert set(win.evaluate(SIGMA2).unidentifiable) == {"m", "b", "current"}

    def test_a_strict_bound_then_a_loose_one_judge_independently(self) -> None:
        """Judging one window against two bounds, in either order, gives each bound's own
        verdict (what the strict bound refuses does not carry over to the loose one)."""
        s = _seg("figure-8", seconds=60.0)
        win = ExcitationWindow(EM3C)
        for u, r, h in zip(s.u_water_mps, s.raw_mps, s.heading_deg, strict=True):
            win.add(float(u), float(r), float(h))
        strict = judge(EM3C, win.stats(), SIGMA2).determined
        loose = judge(EM3C, win.stats(), SIGMA2, std_factor=5.0).determined
        assert strict != loose
        assert (
            win.evaluate(SIGMA2).determined,
            win.evaluate(SIGMA2, std_factor=5.0).determined,
        ) == (
            strict,
            loose,
        )
        assert win.evaluate(SIGMA2, std_factor=5.0).determined == loose
        assert win.evaluate(SIGMA2).determined == strict

    def test_a_judgement_follows_the_samples_added_since_the_last(self) -> None:
        """The window is judged afresh after each sample: a figure-8 determines the
        current, and the long straight after it takes that away."""
        eight, straight = _seg("figure-8", seconds=600.0), _seg("straight", seconds=1800.0)
        win = ExcitationWindow(EM3C, half_life_samples=120.0)
        verdicts = []
        for s in (eight, straight):
            for u, r, h in zip(s.u_water_mps, s.raw_mps, s.heading_deg, strict=True):
                win.add(float(u), float(r), float(h))
            verdicts.append(set(win.evaluate(SIGMA2).determined))
        assert "current" in verdicts[0]
        assert verdicts[1] == set()

    def test_reset_and_bad_half_life(self) -> None:
        """reset() empties the window; a non-positive half-life raises ValueError."""
        win = ExcitationWindow(Layout("EM1"))
        win.add(1.0, 1.0)
        win.reset()
        assert win.n_effective == 0.0
        with pytest.raises(ValueError):
            ExcitationWindow(Layout("EM1"), half_life_samples=0.0)
