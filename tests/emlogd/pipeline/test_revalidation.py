"""The verdicts on a calibration validated before (restored or withdrawn), on
validation windows built to pass or fail each rule; the supervisor's use of them is
pinned in test_supervisor and test_uut."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.kalman import KfConfig
from calib.models import Params
from emlogd.pipeline.evidence import SeaMemory
from emlogd.pipeline.revalidation import (
    COMMON_SEA_DEGREE,
    RESTORE_SEA_SIGMAS,
    WORSE_FACTOR,
    WORSE_MARGIN_MPS,
    Candidate,
    CommonSea,
    beats_raw,
    common_current,
    judge_early,
    judge_own_currents,
    judge_restored,
    judge_saved_sea,
    worse,
)

N = 200
CURRENT = (0.3, -0.2)


def _candidate(headings_deg: np.ndarray, offset_cand: float, offset_raw: float) -> Candidate:
    """A restored candidate whose errors are a current (north, east) seen through the
    heading, plus an offset of its own and of raw's, with a little noise."""
    rng = np.random.default_rng(3)
    c, s = np.cos(np.radians(headings_deg)), np.sin(np.radians(headings_deg))
    sea = -(CURRENT[0] * c + CURRENT[1] * s)
    d_raw = sea + offset_raw + rng.normal(0.0, 0.01, c.size)
    d_c = sea + offset_cand + rng.normal(0.0, 0.01, c.size)
    cand = Candidate(Params("EM3"), 0.0, "restored")
    cand.samples = [
        (float(a), float(b), float(x), float(y))
        for a, b, x, y in zip(d_raw, d_c, c, s, strict=True)
    ]
    cand.n = c.size
    return cand


def test_worse_is_the_factor_and_the_margin() -> None:
    edge = 0.1 * WORSE_FACTOR + WORSE_MARGIN_MPS
    assert not worse(edge, 0.1)
    assert worse(edge + 1e-9, 0.1)


def test_in_a_turn_each_is_judged_after_its_own_current() -> None:
    """Headings over 180°: the current is taken out of both, and the offsets decide."""
    hd = np.linspace(0.0, 180.0, N)
    detail: dict[str, object] = {}
    assert judge_own_currents(_candidate(hd, 0.0, 0.2), detail) is True
    assert float(detail["rmse_candidate_own_current"]) < 0.02  # type: ignore[arg-type]
    assert judge_own_currents(_candidate(hd, 0.2, 0.0), {}) is False


def test_on_a_straight_leg_own_currents_cannot_tell() -> None:
    detail: dict[str, object] = {}
    assert judge_own_currents(_candidate(np.full(N, 30.0), 0.0, 0.2), detail) is None
    assert detail["heading_spread"] == pytest.approx(0.0, abs=1e-9)


def test_saved_sea_compares_the_squared_errors() -> None:
    cand = _candidate(np.full(N, 30.0), 0.0, 0.0)
    cand.n, cand.sea_raw, cand.sea_cand = 4, 4 * 0.1**2, 4 * 0.1**2
    assert judge_saved_sea(cand, {})
    cand.sea_cand = 4 * 0.2**2
    assert not judge_saved_sea(cand, {})


def test_a_straight_leg_implying_an_impossible_current_is_refused() -> None:
    """Straight leg, no saved sea scores: the current its mean error implies (less the
    saved current) must lie within RESTORE_SEA_SIGMAS of the saved one's σ."""
    hd = np.full(N, 0.0)
    kf = KfConfig()
    saved = (CURRENT[0], CURRENT[1], 0.0)
    std = (0.02, 0.02)
    allowance = RESTORE_SEA_SIGMAS * 0.02
    assert judge_restored(_candidate(hd, 0.5 * allowance, 0.0), {}, kf, saved, std, 0.0)
    detail: dict[str, object] = {}
    assert not judge_restored(_candidate(hd, 2.0 * allowance, 0.0), detail, kf, saved, std, 0.0)
    assert detail["current_allowance_mps"] == pytest.approx(round(allowance, 4))
    # no saved sea: the whole prior allowance of a current component (raw right in no
    # current, so that raw's current is the likely one)
    prior = math.sqrt(kf.current_p0_m2ps2)
    for share, ok in ((0.9, True), (1.1, False)):
        cand = _candidate(hd, share * prior + CURRENT[0], CURRENT[0])
        assert judge_restored(cand, {}, kf, None, None, None) is ok


def test_early_on_a_straight_leg_as_the_whole_window_but_not_in_a_turn() -> None:
    """Its first samples (no saved-sea scores): on a straight leg the whole window's
    verdict applies it early when the current it implies is one the sea can have; in a
    turn it waits for the currents of their own over the whole window."""
    kf, saved, std = KfConfig(), (CURRENT[0], CURRENT[1], 0.0), (0.02, 0.02)
    allowance = RESTORE_SEA_SIGMAS * 0.02
    straight = _candidate(np.full(N, 0.0), 0.5 * allowance, 0.0)
    assert judge_early(straight, {}, kf, saved, std)
    assert not judge_early(_candidate(np.full(N, 0.0), 2.0 * allowance, 0.0), {}, kf, saved, std)
    turn = _candidate(np.linspace(0.0, 180.0, N), 0.0, 0.2)
    assert judge_own_currents(turn, {}) is True
    assert not judge_early(turn, {}, kf, saved, std)


def test_beyond_the_allowance_it_is_refused_only_where_raw_is_the_likelier() -> None:
    """Straight leg, the calibration implying twice the allowance: where raw implies a
    current as odd (the sea moved since it was saved), the window is no evidence against
    the calibration and it keeps its verdict; where raw's current is the likelier by
    the allowance's square, refused."""
    hd = np.full(N, 0.0)
    kf = KfConfig()
    saved = (CURRENT[0], CURRENT[1], 0.0)
    allowance = RESTORE_SEA_SIGMAS * 0.02
    for raw_share, ok in ((-1.8, True), (1.9, True), (1.5, False), (0.0, False)):
        detail: dict[str, object] = {}
        cand = _candidate(hd, 2.0 * allowance, raw_share * allowance)
        assert judge_restored(cand, detail, kf, saved, (0.02, 0.02), 0.0) is ok, raw_share
        assert detail["implied_current_raw_mps"] == pytest.approx(raw_share * allowance, abs=0.01)


def test_the_common_sea_is_one_current_whatever_the_correction() -> None:
    """A turn at varying speed, a log 5 % high plus 0.1 m/s, GNSS in a current: the
    common sea is the current (β = minus it), and the same when the memory holds any
    affine correction of the readings instead of raw."""
    cur = (0.3, -0.2)
    p = Params("EM3", m=0.05, b_mps=0.1)
    mems = (SeaMemory(), SeaMemory())
    for k in range(1200):
        t = float(k)
        hd = math.radians(0.6 * t)
        cs = (math.cos(hd), math.sin(hd))
        u = 2.0 + 0.5 * math.sin(t / 50.0)
        ref = u + cur[0] * cs[0] + cur[1] * cs[1]
        raw = p.forward(u)
        mems[0].add(t, raw, ref, cs)
        mems[1].add(t, p.correct(raw), ref, cs)
    b0 = common_current(mems[0], 1199.0, 1)
    b1 = common_current(mems[1], 1199.0, 1)
    assert b0[:2] == pytest.approx((-cur[0], -cur[1]), abs=0.01)
    assert b1[:2] == pytest.approx(b0[:2], abs=1e-6)
    assert b0.along((1.0, 0.0)) == pytest.approx(-cur[0], abs=0.01)


def _sea_on_legs(headings_deg: tuple[float, ...]) -> CommonSea:
    """The common sea of 10 minutes per leg at each heading, the speed varying, a log
    5 % high plus 0.1 m/s in a current of (0.3, −0.2) m/s."""
    p = Params("EM3", m=0.05, b_mps=0.1)
    mem = SeaMemory()
    rng = np.random.default_rng(5)
    t = 0.0
    for hd in headings_deg:
        cs = (math.cos(math.radians(hd)), math.sin(math.radians(hd)))
        for _ in range(600):
            u = 2.0 + 0.5 * math.sin(t / 50.0)
            ref = u + 0.3 * cs[0] - 0.2 * cs[1] + float(rng.normal(0.0, 0.03))
            mem.add(t, p.forward(u), ref, cs)
            t += 1.0
    return common_current(mem, t - 1.0, COMMON_SEA_DEGREE)


@pytest.mark.parametrize(
    ("legs", "at", "determined"),
    [
        ((0.0,), 0.0, False),  # one heading: the current along it is the polynomial's offset
        ((0.0, 45.0), 45.0, False),  # two sectors: only the difference of their currents
        ((0.0, 45.0), 0.0, False),
        ((0.0, 120.0, 240.0), 240.0, True),  # three headings: the current itself
        ((0.0, 120.0, 240.0), 90.0, True),
    ],
)
def test_the_common_sea_is_no_sea_where_the_headings_do_not_determine_it(
    legs: tuple[float, ...], at: float, determined: bool
) -> None:
    """Along a heading whose current the memory's headings cannot tell from the free
    polynomial's offset, the common sea gives nothing to score in
    (:data:`COMMON_SEA_MAX_STD_MPS`); where they determine it, it is the current."""
    sea = _sea_on_legs(legs)
    cs = (math.cos(math.radians(at)), math.sin(math.radians(at)))
    along = sea.along(cs)
    assert (along is not None) is determined
    if along is not None:
        assert along == pytest.approx(-(0.3 * cs[0] - 0.2 * cs[1]), abs=0.02)
    assert common_current(SeaMemory(), 0.0, COMMON_SEA_DEGREE).along(cs) is None


def test_a_candidate_is_scored_in_the_common_sea_only_where_it_is_determined() -> None:
    cand = Candidate(Params("EM3"), 0.0)
    cand.score_common(0.3, 0.05, None)
    assert cand.n_common == 0
    assert beats_raw(cand, 0.3, 0.05, {}) is True
    cand.score_common(0.3, 0.05, 0.3)  # in that sea raw is right and the candidate not
    assert (cand.n_common, cand.common_raw, cand.common_cand) == (1, 0.0, 0.0625)
    assert beats_raw(cand, 0.3, 0.05, {}) is False


@pytest.mark.parametrize(
    ("own", "common", "beats"),
    [
        ((0.2, 0.1), None, True),  # no common sea scored (no current states)
        ((0.2, 0.1), (0.2, 0.1), True),
        ((0.2, 0.1), (0.1, 0.12), False),  # raw better in the common sea
        ((0.1, 0.098), (0.2, 0.1), False),  # a tie after their own currents
    ],
)
def test_a_candidate_beats_raw_in_both_seas(
    own: tuple[float, float], common: tuple[float, float] | None, beats: bool
) -> None:
    """RMSEs (raw, candidate) after each one's own current and in the common sea: raw
    must be worse than it by the margin in both."""
    cand = Candidate(Params("EM3"), 0.0)
    if common is not None:
        cand.n_common = 10
        cand.common_raw, cand.common_cand = 10 * common[0] ** 2, 10 * common[1] ** 2
    assert beats_raw(cand, own[0], own[1], {}) is beats
