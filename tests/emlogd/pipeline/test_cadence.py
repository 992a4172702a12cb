"""The readings' cadence and the weight the change detector's baseline needs at it."""

from __future__ import annotations

import pytest

from emlogd.pipeline.cadence import (
    CUSUM_MIN_FILL_S,
    RECHECK_MIN_FILL_S,
    RECHECK_MIN_SAMPLES,
    VALIDATION_MIN_FILL_S,
    VALIDATION_MIN_SAMPLES,
    Cadence,
)
from emlogd.pipeline.evidence import CUSUM_MAX_GAP_S


def _cadence(dt: float, n: int = 30) -> Cadence:
    c = Cadence()
    for k in range(n):
        c.add(k * dt)
    return c


@pytest.mark.parametrize("dt", [0.1, 1.0, 2.0])
def test_at_a_reading_every_2_s_or_faster_the_baseline_needs_its_samples(dt: float) -> None:
    """At 0.5 Hz and faster the change detector's baseline waits for its ten samples."""
    assert _cadence(dt).detector_weight(10.0, 60.0) == 10.0


def test_at_a_reading_every_5_s_the_baseline_needs_what_30_s_of_them_weigh() -> None:
    """A window of a 60-s half-life holds at most 18 readings 5 s apart (fewer after a
    run whose samples were kept out): the baseline needs the weight 30 s of them give
    it, about 5, not ten."""
    c = _cadence(5.0)
    need = c.detector_weight(10.0, 60.0)
    full = 1.0 / (1.0 - 0.5 ** (5.0 / 60.0))
    assert need == pytest.approx((1.0 - 0.5 ** (CUSUM_MIN_FILL_S / 60.0)) * full)
    assert 5.0 < need < 5.5 and full < 18.0
    assert c.median_s == pytest.approx(5.0)


def test_a_silence_is_no_cadence() -> None:
    """Readings 1 s apart around a silence longer than CUSUM_MAX_GAP_S: still 1 s."""
    c = _cadence(1.0, 10)
    c.add(9.0 + 2.0 * CUSUM_MAX_GAP_S)
    c.add(10.0 + 2.0 * CUSUM_MAX_GAP_S)
    assert c.median_s == pytest.approx(1.0)
    assert Cadence().detector_weight(10.0, 60.0) == 10.0  # no interval yet


@pytest.mark.parametrize("dt", [0.1, 1.0, 2.0])
def test_at_a_reading_every_2_s_or_faster_the_recheck_and_validation_count_samples(
    dt: float,
) -> None:
    """At 0.5 Hz and faster the re-check waits for its 60 and a validation for its 20."""
    c = _cadence(dt)
    assert c.recheck_weight(300.0) == RECHECK_MIN_SAMPLES == 60.0
    assert c.validation_count() == VALIDATION_MIN_SAMPLES == 20.0


def test_at_a_reading_every_5_s_the_recheck_and_validation_need_a_span() -> None:
    """Readings 5 s apart: the re-check needs the weight 150 s of them give a window of a
    300-s half-life (about 25, gathered in 150 s, not 60 in 8.5 minutes), a validation
    the 8 readings of 40 s (not 20 in 100 s)."""
    c = _cadence(5.0)
    full = 1.0 / (1.0 - 0.5 ** (5.0 / 300.0))
    assert c.recheck_weight(300.0) == pytest.approx(
        (1.0 - 0.5 ** (RECHECK_MIN_FILL_S / 300.0)) * full
    )
    assert 25.0 < c.recheck_weight(300.0) < 26.0
    assert c.validation_count() == pytest.approx(VALIDATION_MIN_FILL_S / 5.0) == 8.0
    assert Cadence().validation_count() == VALIDATION_MIN_SAMPLES  # no interval yet


def test_a_reference_lost_for_half_a_minute_is_no_slow_cadence() -> None:
    """Readings 1 s apart around a 30-s loss of the reference (within CUSUM_MAX_GAP_S):
    the change detector, the re-check and a validation still count samples."""
    c = _cadence(1.0)
    c.add(29.0 + 30.0)
    c.add(60.0)
    assert c.median_s == pytest.approx(1.0)
    assert c.detector_weight(10.0, 60.0) == 10.0
    assert c.recheck_weight(300.0) == RECHECK_MIN_SAMPLES
    assert c.validation_count() == VALIDATION_MIN_SAMPLES
