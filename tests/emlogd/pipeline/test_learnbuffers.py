"""The learner's buffers: the lag finder's window (its growth and slide) and its
bounded series; the block means are pinned in test_uut's TestBlockMeans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from emlogd.pipeline.learnbuffers import LAG_MAX_RATE_HZ, LAG_WINDOW_GROWTH, LagFinder

LAG_S = 1.5


def _speed(t: float) -> float:
    """A speed with structure on every scale the correlation needs."""
    return 2.0 + 0.5 * math.sin(0.21 * t) + 0.3 * math.sin(0.67 * t + 1.0)


def _fill(finder: LagFinder, t0: float, t1: float, lag_s: float | None) -> None:
    """10 Hz of reference and UUT; the UUT reads the reference ``lag_s`` late (None:
    the UUT reads a flat line, nothing to correlate)."""
    for k in range(int(t0 * 10), int(t1 * 10)):
        t = k / 10.0
        finder.ref.append((t, _speed(t)))
        finder.uut.append((t, 1.0 if lag_s is None else _speed(t - lag_s)))


def test_a_delayed_log_gives_its_lag() -> None:
    """Once the window is filled, the lag the UUT trails its reference by is found."""
    finder = LagFinder(60.0, 5.0, with_heading=False)
    _fill(finder, 0.0, 30.0, LAG_S)
    assert not finder.ready()
    _fill(finder, 30.0, 61.0, LAG_S)
    assert finder.ready()
    lag, std, why = finder.estimate()
    assert lag == pytest.approx(LAG_S, abs=0.1)
    assert std < 0.5 and why.startswith("r=")


def test_a_refused_estimate_grows_the_window_then_slides_it() -> None:
    """No correlation: the window grows by half each time up to LAG_WINDOW_GROWTH
    times the first, then the older half of the series is dropped."""
    finder = LagFinder(20.0, 5.0, with_heading=False)
    _fill(finder, 0.0, 21.0, None)
    lag, std, why = finder.estimate()
    assert lag is None and math.isinf(std) and why
    assert finder.target_s == pytest.approx(30.0)
    for _ in range(10):
        finder.estimate()
    assert finder.target_s == pytest.approx(LAG_WINDOW_GROWTH * 20.0)
    n = len(finder.uut)
    finder.estimate()
    assert len(finder.uut) == n - n // 2


@pytest.mark.parametrize(
    ("delay_s", "said_who"),
    [(30.0, "the log lags its reference"), (-30.0, "the reference lags the log")],
    ids=["log-late", "reference-late"],
)
def test_searches_peaking_at_their_bound_say_the_log_lags_beyond_them(
    delay_s: float, said_who: str
) -> None:
    """A log 30 s late against a search up to 5 s (or its reference 30 s late): one
    search peaking at its upper (lower) bound is not enough (a flat curve may peak there
    by chance), two in a row say the lag lies beyond the search
    (:attr:`LagFinder.beyond`), and it stands while the data say nothing else; a log
    then found right on time (the lag accepted) clears it."""

    def slow(t: float) -> float:  # a speed changing over minutes, no period near 30 s
        return 2.0 + 0.5 * math.sin(2.0 * math.pi * t / 600.0)

    finder = LagFinder(60.0, 5.0, with_heading=False)
    for k in range(1200):
        t = k / 10.0
        finder.ref.append((t, slow(t)))
        finder.uut.append((t, slow(t - delay_s)))
    lag, _, why = finder.estimate()
    said = [finder.beyond]
    assert lag is None and "search bound" in why
    finder.estimate()
    said.append(finder.beyond)
    _fill(finder, 120.0, 600.0, None)
    finder.estimate()
    said.append(finder.beyond)  # no correlation: no word against it
    assert said[0] == "" and said[1] == said[2]
    assert f"{said_who} beyond max_lag_s: 2 lag searches in a row" in said[1]
    _fill(finder, 600.0, 900.0, LAG_S)
    while finder.uut.t[0] < 600.0:
        finder.uut.drop_older_half()
        finder.ref.drop_older_half()
    lag, _, _ = finder.estimate()
    assert lag == pytest.approx(LAG_S, abs=0.1) and not finder.beyond


def test_series_are_bounded() -> None:
    """The series keep at most what the grown window and the lag search need."""
    finder = LagFinder(10.0, 1.0, with_heading=False)
    _fill(finder, 0.0, 600.0, LAG_S)
    assert len(finder.uut) <= (LAG_WINDOW_GROWTH * 10.0 + 2 * 1.0) * LAG_MAX_RATE_HZ + 64
    assert finder.span() == pytest.approx(np.ptp(finder.uut.times()), abs=1e-9)
