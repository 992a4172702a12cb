"""The calibration record: what the daemon applies and persists, and what an offline fit saves.

One record for every producer (the online filter, ``emlogd calibrate`` with least
squares or the Kalman filter) and every consumer (the daemon's warm start,
``emlogd evaluate``, ``emlogd replay --state``); the state file
(:mod:`emlogd.calfile`) holds one per UUT. A record is checked before it is used
(:func:`check`): parameters inside the physical envelope, a covariance that is
symmetric positive-definite with sane magnitudes and matches the model, a known
model and a finite lag.

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from calib.errors import ModelError
from calib.estimate import Estimate, Estimated
from calib.kalman import check_covariance
from calib.models import Layout
from calib.twoaxis import ENVELOPE, MAX_MISALIGN_DEG
from emlogd.pipeline.integrity import Envelope

Method = Literal["online", "kf", "ls"]
"""Who produced a calibration: the daemon's filter, or an offline fit."""

MAX_VARIANCE = 1e4
"""A covariance entry above this (in the state's units squared) is not a calibration."""

MAX_ABS_LAG_S = 60.0
"""Without a UUT's settings (a file checked alone), a lag beyond ±this is no latency."""


@dataclass(frozen=True, slots=True)
class Calibration(Estimated):
    """A calibration of one UUT.

    Attributes:
        uut: the UUT port name.
        estimate: the error model's parameters (the model is ``params.model``), their
            standard deviations by short name (None: not determined), and the current
            (north, east) at ``t`` with its standard deviations, m/s, when determined.
        lag_s: the UUT's latency behind its reference, s (None: unknown).
        current: whether the calibration was estimated with the current states.
        covariance: the filter's covariance over :attr:`Layout.states` (online and kf),
            for a warm start; empty when there is none (ls).
        method: ``online``, ``kf`` or ``ls``.
        t: record time the calibration refers to, s since the epoch.
        n_samples: samples learnt from.
        reference: ``port`` and ``field`` of the reference it was learnt against.
        unidentifiable: the unknowns the data did not determine (held at their prior).
        nis_mean: running NIS mean (online, kf).
        reset: the UUT was reset by the operator: no calibration (params are nominal).
        two_axis: a two-axis log's figures learnt online (``axes: 2``) and validated:
            ``misalign_deg``, ``m_t``, ``b_t_mps`` and their σ (``misalign_std_deg``,
            ``m_t_std``, ``b_t_std_mps``); None: none.
    """

    uut: str
    estimate: Estimate
    lag_s: float | None
    current: bool = False
    covariance: tuple[tuple[float, ...], ...] = ()
    method: Method = "online"
    t: float = 0.0
    n_samples: int = 0
    reference: Mapping[str, str] = field(default_factory=dict)
    unidentifiable: tuple[str, ...] = ()
    nis_mean: float | None = None
    reset: bool = False
    two_axis: Mapping[str, float] | None = None

    @property
    def layout(self) -> Layout:
        """The unknowns (and the filter's state layout) of this calibration."""
        return Layout(self.params.model, self.current)


def check(cal: Calibration, envelope: Envelope, max_lag_s: float | None = None) -> str:
    """``""`` when the calibration may be used, else why not (one line).

    Checks: a finite lag within ``[0, max_lag_s]`` (the UUT's ``max_lag_s``; without
    it within ±:data:`MAX_ABS_LAG_S`) — for a reset record too, which keeps the lag;
    parameters inside ``envelope``; the current (if any) within it; a covariance, when
    present, of the layout's shape, finite, symmetric and positive-definite with no
    variance above :data:`MAX_VARIANCE`; standard deviations finite and non-negative.
    """
    why = check_lag(cal.lag_s, max_lag_s) or check_two_axis(cal.two_axis)
    if why:
        return why
    if cal.reset:
        return ""
    why = envelope.check(cal.params, cal.current_mps)
    if why:
        return why
    for name, sd in cal.param_std.items():
        if sd is not None and not (math.isfinite(sd) and sd >= 0.0):
            return f"standard deviation of {name} is {sd!r}"
    if cal.covariance:
        n = cal.layout.n
        try:
            check_covariance(cal.covariance, n)
        except ModelError as exc:
            return str(exc)
        if float(np.max(np.abs(np.asarray(cal.covariance)))) > MAX_VARIANCE:
            return "covariance magnitudes are not a calibration's"
    return ""


TWO_AXIS_KEYS = ("misalign_deg", "misalign_std_deg", "m_t", "m_t_std", "b_t_mps", "b_t_std_mps")
"""The figures of a record's ``two_axis``."""
TWO_AXIS_LON_KEYS = ("lon_a_spm", "lon_m", "lon_b_mps")
"""The longitudinal parameters a record's ``two_axis`` may carry besides (all three or
none): the two-axis fit's ``a`` s/m, ``m``, ``b`` m/s on the sensor's axis, in the
record's error model."""


def check_two_axis(fig: Mapping[str, float] | None) -> str:
    """``""`` when a record's two-axis figures (None: none) may be used, else why not:
    every figure of :data:`TWO_AXIS_KEYS` (and of :data:`TWO_AXIS_LON_KEYS`, all or
    none) finite, |α| ≤ :data:`calib.twoaxis.MAX_MISALIGN_DEG`, the transverse scale
    and bias and the longitudinal parameters within the two-axis envelope
    (:data:`calib.twoaxis.ENVELOPE`: 0.5 and 1 m/s; 0.1 s/m, 0.5, 1 m/s), σ
    non-negative."""
    if fig is None:
        return ""
    keys = sorted(TWO_AXIS_KEYS + (TWO_AXIS_LON_KEYS if "lon_m" in fig else ()))
    if sorted(fig) != keys:
        return (
            f"two-axis figures must be {', '.join(TWO_AXIS_KEYS)} "
            f"(and {', '.join(TWO_AXIS_LON_KEYS)}, all or none)"
        )
    for k in keys:
        v = fig[k]
        if not math.isfinite(v) or ("std" in k and v < 0.0):
            return f"two-axis {k} is {v!r}"
    bounds = {"misalign_deg": MAX_MISALIGN_DEG, "m_t": ENVELOPE["m_t"], "b_t_mps": ENVELOPE["b_t"]}
    if "lon_m" in fig:
        bounds |= {"lon_a_spm": ENVELOPE["a"], "lon_m": ENVELOPE["m"], "lon_b_mps": ENVELOPE["b"]}
    for k, bound in bounds.items():
        if abs(fig[k]) > bound:
            return f"two-axis {k} {fig[k]:+.3g} outside ±{bound:g}"
    return ""


def check_lag(lag_s: float | None, max_lag_s: float | None) -> str:
    """``""`` when ``lag_s`` (None: unknown) may be a UUT's lag, else why not: a finite
    lag in ``[0, max_lag_s]``, or within ±:data:`MAX_ABS_LAG_S` without a bound."""
    if lag_s is None:
        return ""
    if max_lag_s is None:
        if not (math.isfinite(lag_s) and abs(lag_s) <= MAX_ABS_LAG_S):
            return f"lag {lag_s!r} s is not a latency"
        return ""
    if not (math.isfinite(lag_s) and 0.0 <= lag_s <= max_lag_s):
        return f"lag {lag_s!r} s is outside [0, {max_lag_s:g}] s (max_lag_s)"
    return ""


class HasEnvelope(Protocol):
    """A UUT's settings as far as loading a calibration is concerned."""

    @property
    def port(self) -> str:
        """The UUT port."""

    @property
    def envelope(self) -> Envelope:
        """Its physical envelope."""

    @property
    def max_lag_s(self) -> float:
        """Its longest lag, s."""


def checker(uuts: Iterable[HasEnvelope]) -> Callable[[Calibration], str]:
    """The check of a loaded calibration against its UUT's envelope and lag bounds (a
    default envelope and ±:data:`MAX_ABS_LAG_S` for a UUT the config does not have)."""
    limits = {u.port: (u.envelope, u.max_lag_s) for u in uuts}

    def check_one(cal: Calibration) -> str:
        envelope, max_lag_s = limits.get(cal.uut, (Envelope(), None))
        return check(cal, envelope, max_lag_s)

    return check_one
