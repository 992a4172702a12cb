"""The heading sources compared (:mod:`emlogd.pipeline.headingsources`)."""

from __future__ import annotations

import math

import pytest

from emlogd.pipeline.headingcheck import WINDOW_S
from emlogd.pipeline.headingsources import (
    AGREE_DEG,
    COURSE,
    FROZEN_S,
    HeadingSources,
    angle_diff,
)
from emlogd.pipeline.routing import Headings, NavHeading


def _track(t: float) -> float:
    """A vessel's true heading: straight legs and slow turns (3°/s at most, 0.5°/s mean)."""
    return (40.0 + 30.0 * math.sin(2.0 * math.pi * t / 600.0)) % 360.0


def _run(
    hs: HeadingSources,
    seconds: float,
    *,
    dvl: float | None = 0.0,
    compass: float | None = None,
    course: bool = False,
    t0: float = 0.0,
    frozen_dvl: float | None = None,
) -> None:
    """``seconds`` of a 2-Hz DVL heading (``dvl`` degrees off the truth, or None: not
    sent; ``frozen_dvl``: that value instead), a 10-Hz compass ``compass`` off, and a
    1-Hz GNSS course (the truth, 2° off: a current) at 2 m/s when ``course``."""
    for k in range(int(seconds * 10)):
        t = t0 + k / 10.0
        h = _track(t)
        if compass is not None:
            hs.heading(t + 0.01, "compass", (h + compass) % 360.0)
        if k % 5 == 0 and (dvl is not None or frozen_dvl is not None):
            v = frozen_dvl if frozen_dvl is not None else (h + (dvl or 0.0)) % 360.0
            hs.heading(t, "dvl", v)
        if course and k % 10 == 0:
            hs.course(t + 0.02, "gnss", 2.0, (h + 2.0) % 360.0)


@pytest.mark.parametrize(
    ("a", "b", "d"), [(10.0, 350.0, 20.0), (350.0, 10.0, -20.0), (0, 180, 180)]
)
def test_the_difference_is_circular(a: float, b: float, d: float) -> None:
    assert angle_diff(a, b) == pytest.approx(d)


def test_a_constant_deviation_below_the_tolerance_is_no_fault() -> None:
    """A compass 8° off the DVL (its deviation) for ten minutes: no pair disagrees."""
    hs = HeadingSources()
    _run(hs, 600.0, compass=8.0)
    assert not hs.wrong and not hs.unresolved
    w = hs.pairs[("compass", "dvl")]
    assert w.judged and not w.disagree and w.diff_deg == pytest.approx(8.0, abs=0.5)
    assert hs.suspect(["dvl", "compass"]) == ""


def test_two_sources_180_apart_without_a_third_make_the_heading_suspect() -> None:
    """The compass 180° off, no course: unresolved within the window, both named,
    every UUT reading either suspect; one reading a third port is not."""
    hs = HeadingSources()
    _run(hs, 0.45 * WINDOW_S, compass=180.0)
    assert not hs.unresolved  # a verdict needs half a window first ...
    _run(hs, 0.1 * WINDOW_S, compass=180.0, t0=0.45 * WINDOW_S)
    assert list(hs.unresolved) == [("compass", "dvl")]  # ... and comes then
    why = hs.suspect(["dvl", "compass"])
    assert "compass and dvl 180° apart" in why and "nothing tells" in why
    assert hs.suspect(["compass"]) and hs.suspect(["other"]) == ""
    assert not hs.wrong
    assert [e[2] for e in hs.events] == ["heading_sources_disagree"]


def test_the_course_on_straight_legs_names_the_wrong_source() -> None:
    """With the GNSS course (2° off the heading: a current) the compass 180° off is
    wrong, the DVL used; nothing suspect."""
    hs = HeadingSources()
    _run(hs, 3 * WINDOW_S, compass=180.0, course=True)
    assert set(hs.wrong) == {"compass"}
    assert "gnss.course agrees with dvl" in hs.wrong["compass"]
    assert hs.usable("dvl") and not hs.usable("compass")
    assert hs.suspect(["dvl", "compass"]) == ""
    assert "heading_source_wrong" in [e[2] for e in hs.events]


def test_the_compass_filling_the_dvls_gaps_is_judged_on_the_common_times() -> None:
    """The DVL's heading missing 10 s in every 20, the compass 180° off: compared
    while both are heard, the course names the compass."""
    hs = HeadingSources()
    for k in range(36):
        _run(hs, 10.0, compass=180.0, course=True, t0=20.0 * k)
        _run(hs, 10.0, dvl=None, compass=180.0, course=True, t0=20.0 * k + 10.0)
    assert set(hs.wrong) == {"compass"}


def test_a_verdict_stands_through_turns_where_the_course_is_not_compared() -> None:
    """The compass named wrong on straight legs stays wrong through ten minutes of a
    10°/s turn (no course compared, its window emptied), not suspect again."""
    hs = HeadingSources()
    _run(hs, 3 * WINDOW_S, compass=180.0, course=True)
    t0 = 3 * WINDOW_S
    for k in range(6000):
        t = t0 + k / 10.0
        h = (10.0 * t) % 360.0
        hs.heading(t + 0.01, "compass", (h + 180.0) % 360.0)
        if k % 5 == 0:
            hs.heading(t, "dvl", h)
        if k % 10 == 0:
            hs.course(t + 0.02, "gnss", 2.0, h)
    assert set(hs.wrong) == {"compass"} and not hs.unresolved


@pytest.mark.parametrize("liar", ["compass", "sbg"])
def test_a_third_compass_arbitrates(liar: str) -> None:
    """A second compass agreeing with the DVL names the first one wrong, no course
    (the liar named before the DVL and after it)."""
    hs = HeadingSources()
    for k in range(int(3 * WINDOW_S)):
        h = _track(float(k))
        hs.heading(k + 0.0, "dvl", h)
        hs.heading(k + 0.1, liar, (h + 180.0) % 360.0)
        hs.heading(k + 0.2, "ths", (h + 3.0) % 360.0)
    assert set(hs.wrong) == {liar} and "ths agrees with dvl" in hs.wrong[liar]


def test_the_course_is_not_compared_in_turns() -> None:
    """Circling at 6°/s for ten minutes, the course 8 s behind the heading (48°: the
    vessel's inertia): never compared, no verdict."""
    hs = HeadingSources()
    for k in range(600):
        hs.heading(float(k), "dvl", (6.0 * k) % 360.0)
        hs.course(k + 0.5, "gnss", 2.0, (6.0 * (k - 8.0)) % 360.0)
    w = hs.pairs.get(("dvl", "gnss" + COURSE))
    assert w is None or not w.judged


def test_agreement_again_clears_the_verdict() -> None:
    """A compass 180° off, then right again: suspect, then trusted (an event each)."""
    hs = HeadingSources()
    _run(hs, 2 * WINDOW_S, compass=180.0)
    assert hs.unresolved
    _run(hs, 2 * WINDOW_S, compass=0.0, t0=2 * WINDOW_S)
    assert not hs.unresolved
    assert [e[2] for e in hs.events] == ["heading_sources_disagree", "heading_sources_resolved"]


def test_a_turn_widens_the_tolerance_by_the_lag_allowance() -> None:
    """A compass 3 s late in a 10°/s turn (30° behind, over the bare tolerance) agrees."""
    hs = HeadingSources()
    for k in range(int(4 * WINDOW_S * 2)):
        t = k / 2.0
        hs.heading(t, "dvl", (10.0 * t) % 360.0)
        hs.heading(t + 0.05, "compass", (10.0 * (t - 3.2)) % 360.0)
    w = hs.pairs[("compass", "dvl")]
    assert abs(w.diff_deg) > AGREE_DEG and not w.disagree and not hs.unresolved


def test_a_frozen_heading_is_named_while_the_course_turns() -> None:
    """The DVL's heading stuck at one value while the course turns 60°: frozen, wrong;
    its value moving again ends it."""
    hs = HeadingSources()
    for k in range(400):
        hs.heading(float(k), "dvl", 100.0)
        hs.course(k + 0.5, "gnss", 2.0, (100.0 + 0.2 * k) % 360.0)
    assert set(hs.wrong) == {"dvl"}
    assert "repeats 100.0°" in hs.wrong["dvl"] and "gnss.course turned" in hs.wrong["dvl"]
    hs.heading(400.0, "dvl", 180.5)
    hs.course(400.5, "gnss", 2.0, 180.0)
    assert not hs.wrong


def test_a_steady_heading_on_a_straight_leg_is_not_frozen() -> None:
    """One value repeated for ten minutes while the course holds within 5°: no fault;
    nor a value repeated shorter than :data:`FROZEN_S` in a turn."""
    hs = HeadingSources()
    for k in range(600):
        hs.heading(float(k), "dvl", 100.0)
        hs.course(k + 0.5, "gnss", 2.0, 100.0 + 5.0 * math.sin(k / 30.0))
    assert not hs.wrong
    hs2 = HeadingSources()
    for k in range(int(FROZEN_S) - 2):
        hs2.heading(float(k), "dvl", 100.0)
        hs2.heading(k + 0.5, "compass", (100.0 + 3.0 * k) % 360.0)
    assert not hs2.wrong


def test_the_course_is_weak_it_alone_makes_nothing_suspect() -> None:
    """One heading 180° from the course: no pair of headings, nothing suspect (the
    course check's to judge with the log's speed); slow fixes are not compared."""
    hs = HeadingSources()
    for k in range(600):
        h = _track(float(k))
        hs.heading(float(k), "dvl", (h + 180.0) % 360.0)
        hs.course(k + 0.5, "gnss", 2.0, h)
        hs.course(k + 0.6, "slow", 0.3, h)
    assert hs.pairs[("dvl", "gnss" + COURSE)].disagree
    assert ("dvl", "slow" + COURSE) not in hs.pairs
    assert not hs.wrong and not hs.unresolved and hs.suspect(["dvl"]) == ""


def test_status_names_pairs_and_verdicts() -> None:
    hs = HeadingSources()
    _run(hs, 3 * WINDOW_S, compass=180.0, course=True)
    st = hs.status()
    assert st["heard"] == ["compass", "dvl", "gnss.course"]
    pairs = st["pairs"]
    assert isinstance(pairs, dict) and pairs["compass/dvl"]["disagree"] is True
    assert abs(pairs["compass/dvl"]["diff_deg"]) == pytest.approx(180.0, abs=1.0)
    assert st["unresolved"] == [] and "compass" in st["wrong"]  # type: ignore[operator]


def test_two_sentences_on_one_port_are_two_sources() -> None:
    """HDT and VHW's heading on one multiplexed port, VHW's 180° off and filling HDT's
    gaps (10 s in every 20), the course on another port: ``nmea.VHW`` is wrong, and
    the port's heading in HDT's gaps is none, not VHW's."""
    h = Headings(["nmea", "gnss"], [])
    for k in range(int(3 * WINDOW_S)):
        t = float(k)
        true = _track(t)
        if k % 20 < 10:
            h.add(t, "nmea", NavHeading(true, None, None, "HDT"))
        h.add(t + 0.3, "nmea", NavHeading((true + 180.0) % 360.0, None, None, "VHW"))
        h.sources.course(t + 0.5, "gnss", 2.0, true)
    assert set(h.sources.wrong) == {"nmea.VHW"}
    assert h.at(["nmea"], 3 * WINDOW_S - 2.0) is None  # in HDT's gap
    found = h.at(["nmea"], 3 * WINDOW_S - 15.5)
    assert found is not None and abs(angle_diff(found[0], _track(3 * WINDOW_S - 15.5))) < 1.0
