"""The simulated trial's vessel motion: the paper's five trajectories integrated as
surge, sway from sideslip in turns, heading, and a sea current (the physics is in
:mod:`emlogd.offline.simulate`'s description)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from calib.models import FloatArray

TrajectoryKind = Literal["transit", "figure-8", "straight", "circles", "return"]
CirclesMode = Literal["steps", "constant"]

START_EPOCH_S = 1749715200.0
"""The trial starts 2025-06-12 08:00:00 UTC (any fixed time: files are reproducible)."""

GAP_S = 300.0
"""Idle time between two trajectories, s (scaled with ``scale``)."""

DT_S = 0.05
"""Integration step of the kinematics, s."""

FIGURE8_SWING_RAD = 2.404825557695773
"""Heading swing of the figure-8, the first zero of the Bessel function J0."""


@dataclass(frozen=True, slots=True)
class TrajectorySpec:
    """One trajectory of the trial (paper section IV-B).

    Attributes:
        index: 1-based order in the trial (and the file name prefix).
        kind: trajectory type.
        duration_min: duration at ``scale = 1``, minutes.
        mean_mps: target mean speed through the water, m/s.
    """

    index: int
    kind: TrajectoryKind
    duration_min: float
    mean_mps: float

    @property
    def filename(self) -> str:
        """The capture file name, e.g. ``2-figure8.cap``."""
        return f"{self.index}-{self.kind.replace('-', '')}.cap"


TRAJECTORIES: tuple[TrajectorySpec, ...] = (
    TrajectorySpec(1, "transit", 125.0, 1.95),
    TrajectorySpec(2, "figure-8", 27.0, 1.48),
    TrajectorySpec(3, "straight", 15.0, 1.59),
    TrajectorySpec(4, "circles", 24.0, 1.85),
    TrajectorySpec(5, "return", 30.0, 1.37),
)


@dataclass(frozen=True, slots=True)
class Kinematics:
    """The vessel's motion on the integration grid (all arrays shape (N,))."""

    t: FloatArray
    """Time since the trajectory start, s."""
    surge: FloatArray
    """Speed through the water along the hull, m/s."""
    sway: FloatArray
    """Speed through the water to starboard, m/s."""
    heading: FloatArray
    """Heading, rad clockwise from north."""
    current_e: FloatArray
    current_n: FloatArray
    """Sea current, m/s east and north."""

    def ground_ship(self) -> tuple[FloatArray, FloatArray]:
        """Velocity over ground in the ship frame (forward, starboard), m/s."""
        s, c = np.sin(self.heading), np.cos(self.heading)
        fwd = self.surge + self.current_e * s + self.current_n * c
        stb = self.sway + self.current_e * c - self.current_n * s
        return fwd, stb

    def position(self) -> tuple[FloatArray, FloatArray]:
        """East and north position over ground, m, from the start."""
        s, c = np.sin(self.heading), np.cos(self.heading)
        ve = self.surge * s + self.sway * c + self.current_e
        vn = self.surge * c - self.sway * s + self.current_n
        return np.cumsum(ve) * DT_S, np.cumsum(vn) * DT_S


def _lowpass(x: FloatArray, tau_s: float) -> FloatArray:
    """First-order lag (the hull's response to a throttle or rudder command)."""
    alpha = DT_S / (tau_s + DT_S)
    out = np.empty_like(x)
    acc = float(x[0])
    for i, xi in enumerate(x.tolist()):
        acc += alpha * (xi - acc)
        out[i] = acc
    return out


def _steps(
    t: FloatArray, rng: np.random.Generator, period_s: float, levels: FloatArray
) -> FloatArray:
    """A piecewise-constant command changing level every ~period_s."""
    n_changes = max(1, int(t[-1] / period_s) + 2)
    times = np.cumsum(rng.uniform(0.6, 1.4, n_changes) * period_s)
    values = rng.choice(levels, n_changes + 1)
    return np.asarray(values[np.searchsorted(times, t)], dtype=np.float64)


def kinematics(
    spec: TrajectorySpec,
    duration_s: float,
    rng: np.random.Generator,
    *,
    current: tuple[float, float] | None = None,
    circles: CirclesMode = "steps",
) -> Kinematics:
    """Integrate surge, heading and sideslip for one trajectory.

    The random draws do not depend on ``current`` or ``circles``: the other options
    and every sensor stream stay the same when only these change.

    Args:
        spec: the trajectory.
        duration_s: its (scaled) duration, s.
        rng: random generator.
        current: a constant sea current (north, east), m/s; None: the slowly varying
            current (a base vector plus tidal-like wander, at most 0.3 m/s).
        circles: ``steps`` (the loops at three throttle settings) or ``constant`` (at
            one commanded speed, the paper's recommendation for the current).

    Returns:
        The motion on a :data:`DT_S` grid.
    """
    n = max(2, round(duration_s / DT_S))
    t = np.arange(n, dtype=np.float64) * DT_S
    mean = spec.mean_mps
    ph = rng.uniform(0.0, 2.0 * math.pi, 4)
    kind = spec.kind
    if kind == "figure-8":
        # ~90 s cycle: a loop to port then one to starboard; speed dips in each turn.
        # Heading psi = c + A sin(wt) with A = 2.405 rad, the first zero of J0: the
        # mean of the unit heading vector over a cycle is J0(A) = 0, so the eight
        # closes on itself instead of creeping along the course.
        omega = 2.0 * math.pi / 90.0
        rate = FIGURE8_SWING_RAD * omega * np.cos(omega * t + ph[0])
        u_cmd = mean + 0.35 - 0.7 * np.cos(omega * t + ph[0]) ** 2
    elif kind == "circles":
        # full loops of ~2 min at three throttle settings
        rate = np.full(n, 2.0 * math.pi / 120.0)
        u_cmd = mean + _steps(t, rng, 240.0, np.array([-0.3, 0.0, 0.3]))
        if circles == "constant":
            u_cmd = np.full(n, mean)
    elif kind == "straight":
        rate = 0.002 * np.sin(2.0 * math.pi * t / 60.0 + ph[0])
        u_cmd = mean + 0.02 * np.sin(2.0 * math.pi * t / 120.0 + ph[1])
    else:  # transit and return: course changes and throttle changes
        rate = _steps(t, rng, 480.0, np.array([0.0, 0.0, 0.0, -0.02, 0.02]))
        rate = np.where(_steps(t, rng, 45.0, np.array([0.0, 1.0])) > 0.0, rate, 0.0)
        levels = np.array([-0.45, -0.25, 0.0, 0.25, 0.45]) * (1.0 if kind == "transit" else 0.8)
        u_cmd = (
            mean + _steps(t, rng, 300.0, levels) + 0.08 * np.sin(2.0 * math.pi * t / 97.0 + ph[1])
        )
    surge = _lowpass(np.maximum(u_cmd, 0.2), 5.0)
    surge *= mean / float(np.mean(surge))  # hit the paper's mean speed
    rate = _lowpass(rate, 3.0)
    heading = np.mod(rng.uniform(0.0, 2.0 * math.pi) + np.cumsum(rate) * DT_S, 2.0 * math.pi)
    sway = -0.6 * rate * surge  # sideslip in turns: the stern swings out
    # A slowly varying current: a base vector plus tidal-like wander, |c| <= 0.3 m/s.
    base = rng.uniform(0.08, 0.2)
    direction = rng.uniform(0.0, 2.0 * math.pi)
    wander = 0.08 * np.sin(2.0 * math.pi * t / 2400.0 + ph[2])
    turn = direction + 0.5 * np.sin(2.0 * math.pi * t / 3600.0 + ph[3])
    mag = np.clip(base + wander, 0.0, 0.3)
    if current is not None:
        c_n, c_e = current
        return Kinematics(t, surge, sway, heading, np.full(n, c_e), np.full(n, c_n))
    return Kinematics(t, surge, sway, heading, mag * np.sin(turn), mag * np.cos(turn))


def interp(k: Kinematics, x: FloatArray, at: FloatArray) -> FloatArray:
    """``x``, a series on ``k``'s grid, interpolated at the times ``at``."""
    return np.asarray(np.interp(at, k.t, x), dtype=np.float64)
