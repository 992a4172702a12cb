"""Faults the simulator can inject, and the truth score per window that judges them.

The supervisor (:mod:`emlogd.pipeline.supervisor`) is tested against sensors that
change and seas that jump; this module describes those faults for
:func:`emlogd.offline.simulate.simulate` (``emlogs=(with_fault(EMLOG1, ...), ...)``,
``current_switch=...``) and scores a replay's emitted speeds against the true speed
through the water window by window (:func:`score_windows`), where a short bad spell
cannot hide in a long average.

Times are *trial* times: seconds since the first trajectory started (the idle gaps
between trajectories count), so "every hour" spans the captures.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from calib.models import FloatArray

if TYPE_CHECKING:
    from emlogd.offline.simulate import EmlogSpec, Truth

FaultKind = Literal["step", "dip", "drift", "stuck", "stall"]

WINDOW_S = 300.0
"""The window of :func:`score_windows`, s (the acceptance's 5 minutes)."""

MIN_WINDOW_SAMPLES = 30
"""A window with fewer scored readings is left out of :func:`score_windows`."""


@dataclass(frozen=True, slots=True)
class SensorFault:
    """A fault of a simulated EMlog, applied to its readings before quantisation.

    Attributes:
        kind: ``step`` (the gain becomes ``factor`` at ``at_s`` and stays), ``dip``
            (the gain is ``factor`` for ``duration_s`` from ``at_s``, again every
            ``period_s``), ``drift`` (fouling: the gain falls linearly from 1 at ``at_s``
            to ``factor`` at ``at_s + duration_s`` and stays there), ``stuck`` (from
            ``at_s`` the reading is ``value_mps`` plus white noise ``noise_mps``, for
            ``duration_s``), ``stall`` (a paddle wheel that stops: from ``at_s`` for
            ``duration_s`` the reading is uniform in ``[0, value_mps]``).
        at_s: trial time the fault starts, s.
        factor: the gain (step, dip, drift's end).
        duration_s: how long a dip, a drift's ramp, a stuck or stalled spell lasts, s.
        period_s: a dip's repeat, s.
        value_mps: the stuck value, or the stalled wheel's largest reading, m/s.
        noise_mps: the stuck reading's noise, m/s (1σ).
    """

    kind: FaultKind
    at_s: float
    factor: float = 1.0
    duration_s: float = math.inf
    period_s: float = math.inf
    value_mps: float = 0.0
    noise_mps: float = 0.0

    def gain(self, t: FloatArray) -> FloatArray:
        """The multiplier of the reading at trial times ``t`` (1 where none)."""
        g = np.ones_like(t)
        dt = t - self.at_s
        if self.kind == "step":
            g[dt >= 0.0] = self.factor
        elif self.kind == "dip":
            phase = np.mod(dt, self.period_s) if math.isfinite(self.period_s) else dt
            g[(dt >= 0.0) & (phase < self.duration_s)] = self.factor
        elif self.kind == "drift":
            frac = np.clip(dt / self.duration_s, 0.0, 1.0)
            g = 1.0 + (self.factor - 1.0) * frac
        return np.asarray(g, dtype=np.float64)

    def apply(self, t: FloatArray, raw: FloatArray, seed: int) -> FloatArray:
        """The faulty readings at trial times ``t`` (``seed``: the fault's own noise)."""
        out = raw * self.gain(t)
        if self.kind in ("stuck", "stall"):
            rng = np.random.default_rng(seed)
            on = (t >= self.at_s) & (t < self.at_s + self.duration_s)
            if self.kind == "stuck":
                vals = self.value_mps + rng.normal(0.0, self.noise_mps, t.size)
            else:
                vals = rng.uniform(0.0, self.value_mps, t.size)
            out = np.where(on, np.maximum(vals, 0.0), out)
        return np.asarray(out, dtype=np.float64)


def with_fault(e: EmlogSpec, fault: SensorFault) -> EmlogSpec:
    """``e`` with a fault."""
    return dataclasses.replace(e, fault=fault)


@dataclass(frozen=True, slots=True)
class SwitchingCurrent:
    """A current that jumps between zero and (``north``, ``east``) every ``period_s``
    (zero first): the worst case of a tidal front."""

    north_mps: float
    east_mps: float
    period_s: float

    def at(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(north, east) at trial times ``t``, m/s."""
        on = (np.floor_divide(t, self.period_s) % 2) == 1
        n = np.where(on, self.north_mps, 0.0)
        e = np.where(on, self.east_mps, 0.0)
        return np.asarray(n, dtype=np.float64), np.asarray(e, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class WindowScore:
    """One window's emitted and raw speeds against the truth."""

    t0: float
    """The window's start, epoch s."""
    n: int
    rmse_raw: float
    rmse_corrected: float

    @property
    def ratio(self) -> float:
        """Emitted over raw RMSE."""
        return self.rmse_corrected / self.rmse_raw if self.rmse_raw > 0.0 else math.inf


def score_windows(
    truth: Truth,
    port: str,
    t: npt.ArrayLike,
    raw: npt.ArrayLike,
    corrected: npt.ArrayLike,
    window_s: float = WINDOW_S,
) -> list[WindowScore]:
    """Score the emitted speeds against the truth per window of ``window_s``.

    Readings are paired with the truth by :meth:`~emlogd.offline.simtruth.Truth.paired`
    (the EMlog's true latency); windows are consecutive from the first reading, those
    with fewer than :data:`MIN_WINDOW_SAMPLES` scored readings left out (a silent
    output, or the idle time between trajectories).
    """
    tt, r, c, stw = truth.paired(port, t, raw, corrected)
    if not tt.size:
        return []
    idx = np.floor((tt - tt[0]) / window_s).astype(np.int64)
    out: list[WindowScore] = []
    for w in np.unique(idx).tolist():
        sel = idx == w
        n = int(sel.sum())
        if n < MIN_WINDOW_SAMPLES:
            continue
        er, ec = r[sel] - stw[sel], c[sel] - stw[sel]
        out.append(
            WindowScore(
                float(tt[0] + w * window_s),
                n,
                math.sqrt(float(np.mean(er * er))),
                math.sqrt(float(np.mean(ec * ec))),
            )
        )
    return out
