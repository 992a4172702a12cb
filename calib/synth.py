"""Synthetic speed data for tests, benchmarks and demonstrations.

Generates a true speed through the water for the five trajectory types of the
paper (section IV-B: transit, figure-8, straight, circles, return; their mean
speeds), applies an error model (:mod:`calib.models`) plus white noise to make a
raw EMlog series, and adds white noise to make a reference. Everything is
seeded through an explicit ``numpy.random.Generator``.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from calib.crossval import Segment
from calib.errors import DataError
from calib.models import FloatArray, Params, forward_array

TrajectoryKind = Literal["transit", "figure-8", "straight", "circles", "return"]

PAPER_TRIAL: tuple[tuple[TrajectoryKind, float], ...] = (
    ("transit", 125.0),
    ("figure-8", 27.0),
    ("straight", 15.0),
    ("circles", 24.0),
    ("return", 30.0),
)
"""The paper's five segments and their durations in minutes (221 min in total)."""

_MEAN_MPS: dict[TrajectoryKind, float] = {
    "transit": 1.95,
    "figure-8": 1.48,
    "straight": 1.59,
    "circles": 1.85,
    "return": 1.37,
}


def speed_profile(kind: TrajectoryKind, t_s: FloatArray, rng: np.random.Generator) -> FloatArray:
    """A plausible true speed through the water for one trajectory type.

    Args:
        kind: trajectory type (mean speeds as in the paper).
        t_s: sample times in s, shape (N,).
        rng: random generator (random phases and slow speed changes).

    Returns:
        Speeds in m/s, shape (N,), positive.

    Raises:
        DataError: unknown kind.
    """
    if kind not in _MEAN_MPS:
        raise DataError(f"unknown trajectory kind {kind!r}")
    mean = _MEAN_MPS[kind]
    phase = rng.uniform(0.0, 2.0 * math.pi, size=3)
    t = np.asarray(t_s, dtype=np.float64)
    if kind == "figure-8":  # two turns per ~90 s cycle, each slowing the vessel
        v = mean + 0.45 * np.sin(2.0 * math.pi * t / 45.0 + phase[0])
    elif kind == "circles":
        v = mean + 0.35 * np.sin(2.0 * math.pi * t / 60.0 + phase[0])
    elif kind == "straight":
        v = mean + 0.03 * np.sin(2.0 * math.pi * t / 120.0 + phase[0])
    else:  # transits: slow throttle changes
        v = (
            mean
            + 0.25 * np.sin(2.0 * math.pi * t / 600.0 + phase[0])
            + 0.1 * np.sin(2.0 * math.pi * t / 97.0 + phase[1])
        )
    return np.asarray(np.maximum(v, 0.05), dtype=np.float64)


def simulate_segment(
    name: str,
    kind: TrajectoryKind,
    duration_s: float,
    rate_hz: float,
    params: Params,
    rng: np.random.Generator,
    *,
    sigma_raw_mps: float = 0.05,
    sigma_ref_mps: float = 0.01,
    t0_s: float = 0.0,
) -> Segment:
    """One synthetic segment: raw = f(v) + noise, ref = v + noise, aligned samples.

    Args:
        name: segment label.
        kind: trajectory type.
        duration_s: length in s.
        rate_hz: sample rate of the unit under test, Hz.
        params: the true error model of the EMlog.
        rng: random generator.
        sigma_raw_mps: raw white-noise standard deviation, m/s.
        sigma_ref_mps: reference white-noise standard deviation, m/s.
        t0_s: time of the first sample, s.

    Returns:
        The segment ``(name, t_s, raw_mps, ref_mps)``.

    Raises:
        DataError: non-positive duration or rate.
    """
    if not (duration_s > 0.0 and rate_hz > 0.0):
        raise DataError("duration_s and rate_hz must be positive")
    n = round(duration_s * rate_hz)
    t = t0_s + np.arange(n, dtype=np.float64) / rate_hz
    v = speed_profile(kind, t, rng)
    raw = forward_array(params, v) + rng.normal(0.0, sigma_raw_mps, n)
    ref = v + rng.normal(0.0, sigma_ref_mps, n)
    return Segment(name, t, raw, ref)


def paper_trial(
    params: Params, rng: np.random.Generator, *, rate_hz: float = 1.0, sigma_raw_mps: float = 0.05
) -> list[Segment]:
    """The five segments of :data:`PAPER_TRIAL` (221 min), back to back in time.

    Args:
        params: the true error model of the EMlog.
        rng: random generator.
        rate_hz: sample rate of the unit under test (1 Hz: 13 260 samples).
        sigma_raw_mps: raw white-noise standard deviation, m/s.

    Returns:
        Five segments named after their trajectory type.
    """
    segments = []
    t0 = 0.0
    for kind, minutes in PAPER_TRIAL:
        seg = simulate_segment(
            kind, kind, minutes * 60.0, rate_hz, params, rng, sigma_raw_mps=sigma_raw_mps, t0_s=t0
        )
        segments.append(seg)
        t0 += minutes * 60.0
    return segments
