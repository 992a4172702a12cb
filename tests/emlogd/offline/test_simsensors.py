"""The simulated trial's sensors: the GNSS receiver's timing and noise, the faults on
the lines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers import make_decoder
from drivers.nmea0183 import Rmc
from emlogd.offline.simkinematics import DT_S, START_EPOCH_S, Kinematics
from emlogd.offline.simsensors import (
    EMLOG2,
    FAULT_RATES,
    GNSS_LAG_S,
    Faults,
    Line,
    gnss_lines,
    with_sensor,
)


def _steady(speed: float, n_s: float = 3000.0, accel: float = 0.0) -> Kinematics:
    t = np.arange(0.0, n_s, DT_S)
    surge = speed + accel * t
    zero = np.zeros_like(t)
    return Kinematics(t, surge, zero, np.full_like(t, math.radians(30.0)), zero, zero)


def _rmc(k: Kinematics, seed: int) -> list[tuple[float, Rmc]]:
    lines: list[Line] = []
    faults = Faults(np.random.default_rng(seed))
    gnss_lines(k, START_EPOCH_S, np.random.default_rng(seed), faults, lines)
    dec = make_decoder("nmea0183", "gnss", errors="skip")
    out = []
    for ln in lines:
        for r in dec.feed(ln.data):
            if isinstance(r, Rmc):
                out.append((ln.t - START_EPOCH_S, r))
    return out


def test_gnss_noise_grows_in_course_at_low_speed() -> None:
    """GNSS SOG is off by about 0.05 m/s (1σ) at any speed; COG by about 0.05/SOG rad."""
    for speed in (0.3, 2.0):
        fixes = _rmc(_steady(speed), 5)
        assert len(fixes) == pytest.approx(3000, abs=10)
        sog = np.array([r.sog_mps for _, r in fixes])
        cog = np.array([r.cog_true_deg for _, r in fixes])
        assert sog.mean() == pytest.approx(speed, abs=0.01)
        assert 0.04 < sog.std() < 0.06
        cog_err = np.radians((cog - 30.0 + 180.0) % 360.0 - 180.0)
        assert cog_err.std() == pytest.approx(0.05 / speed, rel=0.15)


def test_gnss_velocity_lags_and_fixes_fall_on_whole_seconds(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each fix is stamped on a whole UTC second and reports the velocity of GNSS_LAG_S earlier."""
    monkeypatch.setattr("emlogd.offline.simsensors.GNSS_NOISE_MPS", 0.0)
    accel = 0.01
    fixes = _rmc(_steady(1.0, n_s=300.0, accel=accel), 6)
    t_fix = np.array([r.time_utc.timestamp() - START_EPOCH_S for _, r in fixes if r.time_utc])
    assert len(t_fix) == len(fixes) and np.all(t_fix == np.round(t_fix))
    t_rx = np.array([t for t, _ in fixes])
    assert np.all((t_rx - t_fix > 0.1) & (t_rx - t_fix < 0.2))
    sog = np.array([r.sog_mps for _, r in fixes])
    age = np.mean((1.0 + accel * t_fix) - sog) / accel
    assert age == pytest.approx(GNSS_LAG_S, abs=0.05)


SENTENCE = "$VWVHW,,T,,M,3.50,N,6.48,K*6A"


def test_a_sentence_and_an_ensemble_take_the_same_faults(monkeypatch: pytest.MonkeyPatch) -> None:
    """Faults.text and Faults.binary draw alike: with one seed, the same bytes as a sentence
    and as a binary ensemble are dropped, truncated, prefixed with noise or corrupted at
    the same lines, counted alike; the sentence keeps its CR LF, and a corrupted one its
    ``$`` and checksum, a corrupted ensemble its two-byte header."""
    for kind in FAULT_RATES:
        monkeypatch.setitem(FAULT_RATES, kind, 0.15)
    text, binary = Faults(np.random.default_rng(7)), Faults(np.random.default_rng(7))
    raw = SENTENCE.encode("ascii")
    for _ in range(2000):
        t, b = text.text(SENTENCE), binary.binary(raw)
        assert (t is None) == (b is None)
        if t is None or b is None:
            continue
        assert t.endswith(b"\r\n") and len(t) == len(b) + 2
        if t[:-2] != b:  # corrupted: one byte of each differs from the line, not the frame
            assert len(b) == len(raw)
            (i,) = [k for k in range(len(raw)) if t[k] != raw[k]]
            (j,) = [k for k in range(len(raw)) if b[k] != raw[k]]
            assert 1 <= i < len(raw) - 3 and t[i] in b"#%"
            assert j >= 2 and b[j] == raw[j] ^ 0x5A
    assert text.counts == binary.counts
    assert all(n > 150 for n in text.counts.values()), text.counts


def test_with_sensor_two_axis_keys() -> None:
    """misalign, mt and bt set emlog2's two-axis model; mt follows m unless given; a
    misalignment beyond its range is refused."""
    s = with_sensor(EMLOG2, {"misalign": 3.0, "bt": 0.04})
    assert s.two_axis.misalign_deg == pytest.approx(3.0)
    assert s.two_axis.m_t == EMLOG2.params.m and s.two_axis.b_t_mps == 0.04
    assert with_sensor(s, {"m": 0.1}).two_axis.m_t == pytest.approx(0.1)
    assert with_sensor(s, {"mt": -0.2, "m": 0.1}).two_axis.m_t == pytest.approx(-0.2)
    with pytest.raises(ValueError, match="misalign"):
        with_sensor(EMLOG2, {"misalign": 30.0})
