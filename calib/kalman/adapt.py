"""The filter's noise scales: how much the measurement noises it was given are scaled
by what its innovations show ("Honest noise" in :mod:`calib.kalman.filters`).

Two running estimates of the scale λ follow one learnt raw update at a time:
:func:`matched_scale`, the running mean of each update's own measure of λ weighted by
the noises' share of the innovation variance, and :func:`slow_scale`, the running mean
of the log NIS at its own scale (robust to a few outliers). Both take the innovation
``y``, its variance ``s`` at the scale in use, the state's share of it and the summed
noises ``r_sum = R_raw + R_ref``: at a scale x the innovation variance is the state's
share plus ``x·r_sum`` (never less than ``min(s, x·r_sum)``).

Must not import: drivers, emlogd, or any I/O module (the stdlib only).
"""

from __future__ import annotations

import math

Innovation = tuple[float, float, float]
"""``(s, s_state, r_sum)``: the innovation variance at the scale in use, the state's
share of it, and the measurement noises it was given, (m/s)²."""

NOISE_SCALE_MIN = 0.0025
"""The smallest noise scale λ: σ a twentieth of what the sensors promise. With the
default noises (a log's 0.1 kn, GNSS's 0.3 m/s) a block innovation's noise
``√(λ·(R_raw + R_ref))`` is then 0.015 m/s: the quantisation error of a 0.1-kn reading
that repeats through a block (0.1 kn/√12), which no averaging removes."""

NOISE_SCALE_MAX = 100.0
"""The largest noise scale λ: σ ten times what the sensors promise."""

ADAPT_NIS_CAP = 9.0
"""A NIS counts at most this much in the noise scale's update (a 3σ innovation: a χ²(1)
capped there keeps a mean of 0.97, and one outlier cannot multiply λ by more than
``1 + (ADAPT_NIS_CAP − 1)/W``, W the weights in the running mean)."""

ADAPT_NIS_CAP_SLOW = 25.0
"""A NIS counts at most this much in the slow noise scale's update (one outlier moves
λ_slow by at most ``exp(4.5/N_λ)``)."""

ADAPT_NIS_MIN = 1e-6
"""A NIS counts at least this much in the slow noise scale's update (its logarithm: a
zero innovation, a quantised reading's, would pull λ_slow to its floor at once)."""

MEAN_LOG_CHI2_1 = -1.2703628454614782
"""E[ln x] for x ~ χ²(1) (ψ(1/2) + ln 2): the mean log NIS of a consistent filter."""


def _variance_at(scale: float, innovation: Innovation) -> float:
    s, s_state, r_sum = innovation
    return max(s_state + scale * r_sum, min(s, scale * r_sum))


def matched_scale(
    lam: float, weights: float, y: float, innovation: Innovation, memory: float
) -> tuple[float, float]:
    """λ and the weights in its running mean after one innovation ``y``: λ̂ from its NIS
    (capped at :data:`ADAPT_NIS_CAP`, at least 0) averaged with a memory of ``memory``
    updates, weighted by the noises' share of the innovation variance; λ within
    [:data:`NOISE_SCALE_MIN`, :data:`NOISE_SCALE_MAX`]."""
    r_sum = innovation[2]
    s_lam = _variance_at(lam, innovation)
    share = min(lam * r_sum / s_lam, 1.0)
    lam_hat = max(lam + (min(y * y / s_lam, ADAPT_NIS_CAP) - 1.0) * s_lam / r_sum, 0.0)
    weights = weights * (1.0 - 1.0 / memory) + share
    lam += share / weights * (lam_hat - lam)  # share > 0: λ is at least its floor
    return min(max(lam, NOISE_SCALE_MIN), NOISE_SCALE_MAX), weights


def slow_scale(slow: float, y: float, innovation: Innovation, a: float) -> float:
    """λ_slow after one innovation ``y``: its log moved by ``a`` (the running mean's step)
    times the noises' share of the log NIS's excess over a χ²(1)'s mean
    (:data:`MEAN_LOG_CHI2_1`), the NIS within [:data:`ADAPT_NIS_MIN`,
    :data:`ADAPT_NIS_CAP_SLOW`]; λ_slow within [:data:`NOISE_SCALE_MIN`,
    :data:`NOISE_SCALE_MAX`]."""
    s_slow = _variance_at(slow, innovation)
    nis = min(max(y * y / s_slow, ADAPT_NIS_MIN), ADAPT_NIS_CAP_SLOW)
    share = min(slow * innovation[2] / s_slow, 1.0)
    slow *= math.exp(a * share * (math.log(nis) - MEAN_LOG_CHI2_1))
    return min(max(slow, NOISE_SCALE_MIN), NOISE_SCALE_MAX)
