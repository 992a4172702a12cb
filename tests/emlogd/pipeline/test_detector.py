"""The change detector on its own: when it alarms, and how it judges an alarm."""

from __future__ import annotations

import random

from emlogd.pipeline.detector import Alarm, ChangeDetector

GAIN = 1.1
"""The log's gain the applied calibration corrects (corrected = raw / GAIN)."""


def _feed(
    det: ChangeDetector,
    t0: int,
    t1: int,
    gain: float,
    rng: random.Random,
    ref_offset: float = 0.0,
    applied: bool = True,
) -> list[tuple[float, Alarm]]:
    """1 Hz readings at 2 m/s through the water on a steady heading; the alarms."""
    alarms = []
    for i in range(t0, t1):
        t = float(i)
        v = 2.0 + 0.1 * rng.gauss(0.0, 1.0)
        raw = gain * v + rng.gauss(0.0, 0.02)
        ref = v + ref_offset + rng.gauss(0.0, 0.02)
        corrected = raw / GAIN if applied else raw
        alarm = det.step(t, (1.0, 0.0), corrected - ref, raw - ref, ref, applied)
        if alarm is not None:
            alarms.append((t, alarm))
    return alarms


def test_a_gain_step_of_the_log_is_withdrawn_in_the_sea_before_it() -> None:
    """A 27 % gain step (1.1 → 0.8) of a calibrated log alarms within three samples; the
    calibration fits the run worse than raw: to be withdrawn, with the detector's
    current before the step (the log's mean shifted, the reference's did not)."""
    det = ChangeDetector(water=True)
    rng = random.Random(1)
    assert not _feed(det, 0, 120, GAIN, rng)
    alarms = _feed(det, 120, 130, 0.8, rng)
    assert alarms
    t, alarm = alarms[0]
    assert t <= 122.0
    assert alarm.withdraw and not alarm.sea_jumped
    assert alarm.current_before is not None
    assert abs(alarm.current_before[0]) < 0.05  # the sea before: no current
    ss_app, ss_raw = alarm.detail["ss_applied"], alarm.detail["ss_raw"]
    assert isinstance(ss_app, float) and isinstance(ss_raw, float) and ss_app > ss_raw


def test_a_jump_of_the_reference_alone_is_the_seas() -> None:
    """The reference jumps by 0.5 m/s and the log does not (a tidal front): the alarm
    withdraws nothing, says the sea jumped, and the detector starts again."""
    det = ChangeDetector(water=True)
    rng = random.Random(2)
    assert not _feed(det, 0, 120, GAIN, rng)
    alarms = _feed(det, 120, 124, GAIN, rng, ref_offset=0.5)
    assert alarms
    _, alarm = alarms[0]
    assert not alarm.withdraw and alarm.sea_jumped and alarm.current_before is None
    assert det.cusum.hi == det.cusum.lo == 0.0 and not det.held


def test_a_step_holds_the_calibration_until_the_alarm() -> None:
    """The first reading after a step of the log beyond HOLD_SIGMAS holds the applied
    calibration (raw goes out) before the CUSUM alarms."""
    det = ChangeDetector(water=True)
    rng = random.Random(4)
    _feed(det, 0, 120, GAIN, rng)
    assert not det.held
    assert not _feed(det, 120, 121, 0.8, rng)
    assert det.held
