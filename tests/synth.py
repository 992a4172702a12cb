"""Synthetic speed data for the tests, the benchmarks and docs/kf_vs_ls.py (not part of
the installed package: import it as ``tests.synth`` from the repository root).

Generates a true speed through the water for the five trajectory types of the
paper (section IV-B: transit, figure-8, straight, circles, return; their mean
speeds), applies an error model (:mod:`calib.models`) plus white noise to make a
raw EMlog series, and adds white noise to make a reference. For a log reporting both
axes, :func:`two_axis_trial` flies one manoeuvre with a DVL and a two-axis log. Everything is
seeded through an explicit ``numpy.random.Generator``.

Imports calib, numpy and the stdlib only (no drivers, no emlogd, no I/O).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from calib.crossval import Segment
from calib.errors import DataError
from calib.models import FloatArray, Params, forward_array
from calib.twoaxis import TwoAxisParams, TwoAxisSeries

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


@dataclass(frozen=True, eq=False)
class WaterFrameSeries:
    """A synthetic segment in the water frame: a current seen through the heading.

    Attributes:
        t_s: sample times, s, shape (N,).
        u_water_mps: true speed through the water along the hull, m/s.
        heading_deg: true heading, degrees in [0, 360).
        current_mps: the current (north, east) at each sample, m/s, shape (N, 2).
        ref_mps: the reference over the ground along the hull (``u + c·(cos ψ, sin ψ)``
            plus noise), m/s.
        raw_mps: the EMlog reading ``f(u)`` plus noise, m/s.
    """

    t_s: FloatArray
    u_water_mps: FloatArray
    heading_deg: FloatArray
    current_mps: FloatArray
    ref_mps: FloatArray
    raw_mps: FloatArray


def heading_profile(kind: TrajectoryKind, t_s: FloatArray, rng: np.random.Generator) -> FloatArray:
    """A plausible heading (degrees in [0, 360)) for one trajectory type.

    Figure-8: the heading swings ±138° around a course once per 90 s (the first zero
    of J0, so the eight closes); circles: a full turn every 120 s; straight: a course
    held within a degree; transits: a course change every ~8 minutes.

    Raises:
        DataError: unknown kind.
    """
    if kind not in _MEAN_MPS:
        raise DataError(f"unknown trajectory kind {kind!r}")
    t = np.asarray(t_s, dtype=np.float64)
    course = rng.uniform(0.0, 360.0)
    if kind == "figure-8":
        psi = course + math.degrees(2.404825557695773) * np.sin(2.0 * math.pi * t / 90.0)
    elif kind == "circles":
        psi = course + 360.0 * t / 120.0
    elif kind == "straight":
        psi = course + 1.0 * np.sin(2.0 * math.pi * t / 60.0)
    else:
        legs = np.floor((t - t[0]) / 480.0).astype(int)
        turns = rng.uniform(-60.0, 60.0, int(legs.max()) + 1)
        psi = course + np.cumsum(turns)[legs]
    return np.asarray(np.mod(psi, 360.0), dtype=np.float64)


def water_frame_segment(
    kind: TrajectoryKind,
    duration_s: float,
    rate_hz: float,
    params: Params,
    rng: np.random.Generator,
    *,
    current_mps: tuple[float, float] = (0.1, -0.15),
    current_swing_mps: float = 0.0,
    constant_speed: bool = False,
    sigma_raw_mps: float = 0.05,
    sigma_ref_mps: float = 0.01,
) -> WaterFrameSeries:
    """One synthetic segment with a sea current and a heading.

    Args:
        kind: trajectory type (speed and heading profiles).
        duration_s: length, s.
        rate_hz: sample rate, Hz.
        params: the EMlog's true error model.
        rng: random generator.
        current_mps: mean current (north, east), m/s.
        current_swing_mps: amplitude of a tidal change of the current over 6 h, m/s.
        constant_speed: hold the speed through the water at the trajectory's mean.
        sigma_raw_mps: EMlog white noise, m/s.
        sigma_ref_mps: reference white noise, m/s.

    Raises:
        DataError: non-positive duration or rate, unknown kind.
    """
    if not (duration_s > 0.0 and rate_hz > 0.0):
        raise DataError("duration_s and rate_hz must be positive")
    n = round(duration_s * rate_hz)
    t = np.arange(n, dtype=np.float64) / rate_hz
    u = np.full(n, _MEAN_MPS[kind]) if constant_speed else speed_profile(kind, t, rng)
    psi = heading_profile(kind, t, rng)
    tide = current_swing_mps * np.sin(2.0 * math.pi * t / 21600.0)
    cur = np.column_stack((current_mps[0] + tide, current_mps[1] - 0.5 * tide))
    rad = np.radians(psi)
    ground = u + cur[:, 0] * np.cos(rad) + cur[:, 1] * np.sin(rad)
    ref = ground + rng.normal(0.0, sigma_ref_mps, n)
    raw = forward_array(params, u) + rng.normal(0.0, sigma_raw_mps, n)
    return WaterFrameSeries(t, u, psi, cur, ref, raw)


TWO_AXIS_CURRENT_NE = (0.15, -0.1)
TWO_AXIS_TRUTH = TwoAxisParams(Params("EM3", m=-0.11, b_mps=-0.05), math.radians(3.0), -0.09, 0.04)
"""A sensor turned 3° to starboard, the transverse scale 2 % off the longitudinal one."""
TWO_AXIS_FIGURES: dict[str, float] = {
    "misalign_deg": 3.0,
    "misalign_std_deg": 0.1,
    "m_t": -0.08,
    "m_t_std": 0.005,
    "b_t_mps": 0.04,
    "b_t_std_mps": 0.004,
}
"""A state file's two-axis figures (:attr:`emlogd.pipeline.calibration.Calibration.two_axis`)
of a log turned 3° to starboard, its transverse scale −0.08 and bias 0.04 m/s (``emlogd
simulate --sensor emlog2:misalign=3,mt=-0.08,bt=0.04``)."""


def two_axis_trial(
    kind: str, truth: TwoAxisParams, seed: int, n: int = 16200, dt: float = 0.1
) -> dict[str, np.ndarray]:
    """27 min at 10 Hz of one manoeuvre, as the simulator flies it: heading, surge,
    sway (−0.6·rate·surge in turns), a constant current, a DVL and a two-axis log
    with 0.05 m/s of noise on each axis."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    ph = rng.uniform(0.0, 2.0 * math.pi)
    if kind == "figure-8":
        om = 2.0 * math.pi / 90.0
        rate = 2.405 * om * np.cos(om * t + ph)
        u = 1.83 - 0.7 * np.cos(om * t + ph) ** 2
    elif kind == "circles":
        rate = np.full(n, 2.0 * math.pi / 120.0)
        u = 1.85 + 0.3 * np.sign(np.sin(2.0 * math.pi * t / 240.0 + ph))
    else:
        rate = 0.002 * np.sin(2.0 * math.pi * t / 60.0 + ph)
        u = 1.59 + 0.02 * np.sin(2.0 * math.pi * t / 120.0)
    psi = rng.uniform(0.0, 2.0 * math.pi) + np.cumsum(rate) * dt
    w = -0.6 * rate * u
    cn, ce = TWO_AXIS_CURRENT_NE
    gf = u + cn * np.cos(psi) + ce * np.sin(psi)
    gs = w - cn * np.sin(psi) + ce * np.cos(psi)
    rl, rt = truth.forward(u, w)
    return {
        "t": t,
        "u": u,
        "w": w,
        "hd": np.degrees(psi) % 360.0,
        "gf": gf + rng.normal(0.0, 0.01, n),
        "gs": gs + rng.normal(0.0, 0.01, n),
        "rl": rl + rng.normal(0.0, 0.05, n),
        "rt": rt + rng.normal(0.0, 0.05, n),
    }


def two_axis_series(d: dict[str, np.ndarray]) -> TwoAxisSeries:
    """The fits' series of a :func:`two_axis_trial` (its ``gf gs rl rt hd``)."""
    return TwoAxisSeries.of(d["gf"], d["gs"], d["rl"], d["rt"], d["hd"])
