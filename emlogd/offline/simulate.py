"""A sea trial like the paper's (section IV), written as capture v1 files.

The paper's MARVEL data set is not public, so emlogd carries its own trial. The
simulator integrates 2D vessel kinematics (surge, sway from sideslip in turns,
heading) for the paper's five trajectories, adds a slowly varying sea current, and
samples three sensors the way the real ones report:

- ``emlog1`` (Airmar DX900+ style): ``$VWVHW`` at 1 Hz, 3.2 s latency, 4800 baud;
- ``emlog2`` (Ben Marine Alize style): ``$VMVBW`` at 10 Hz and ``$VMVHW`` at 5 Hz,
  0.45 s latency, 38400 baud;
- ``dvl`` (Rowe SeaPILOT): PD6 ensembles (or PD0 with ``dvl_format="pd0"``) at
  10 Hz with bottom-lock losses, 115200 baud; the heading is in its ``:SA`` line
  (PD0: the variable leader);
- ``gnss``: ``$GPRMC`` at 1 Hz on whole UTC seconds, 9600 baud; SOG and COG from the
  ground velocity of 0.6 s earlier (the receiver's filter) plus 0.05 m/s of white
  noise on each of east and north (so COG noise grows as 0.05/SOG rad at low speed).
  It has no heading of its own: ``--ref gnss --ref-field gnss`` projects it with the
  DVL's heading (the ``auto`` heading source).

Physics (ship frame x forward, y starboard; heading ψ clockwise from north):
speed through water = ground velocity − current, resolved in the body frame. The
EMlogs see the surge speed through the water through their error model
``raw = a·u² + (1+m)·u + b`` plus white noise, delayed by their latency and
quantised to 0.01 kn by the two-decimal NMEA field. The DVL bottom track sees the
ground velocity in the ship frame, i.e. surge and sway *plus the current* — the
contamination the paper discusses — with millimetre noise and no latency (it is
the time reference: the truth latencies are relative to it).

Faults, at documented per-line rates (:data:`FAULT_RATES`): a corrupted character
(bad checksum or a bad field), a truncated line, a burst of line-noise bytes, and a
dropped line. Receive times carry the serial transmission time plus up to 5 ms of
scheduling jitter.

The current is slowly varying (at most 0.3 m/s) unless a constant one is given
(``current``); the circles are flown at three throttle settings unless ``circles`` is
``constant``. Neither option changes a random draw: the EMlogs' bytes are the same
for any current. The GNSS draws from a random stream of its own and its faults are
drawn after the other ports', so adding it left the EMlog and DVL bytes as they were.

Next to the captures, ``truth.yaml`` (the sensors' true error models and latencies,
per-trajectory figures) and ``truth.csv.gz`` (the truth per sample at 10 Hz: true
speed through the water along the hull, heading, current, bottom lock), which
:func:`read_truth` reads and :func:`score_truth` scores speeds against.

Every file, the truth files included, is a pure function of the arguments: two runs
give identical bytes.
"""

from __future__ import annotations

import dataclasses
import gzip
import io
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import yaml

from calib.metrics import ImoVerdict, imo_verdict
from calib.models import FloatArray, Params, check_model, correct_array, forward_array
from drivers.errors import EmlogdError
from drivers.io.capture import CaptureWriter
from drivers.nmea0183 import encode_rmc, encode_vbw, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline import ProgressFn
from emlogd.offline.simfaults import SensorFault, SwitchingCurrent

DvlFormat = Literal["pd6", "pd0"]
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
class EmlogSpec:
    """A simulated EMlog.

    Attributes:
        port: capture port name.
        params: the true error model (measured = f(true)).
        latency_s: delay of the reading behind the truth, s.
        noise_mps: white noise on each reading, m/s (1σ).
        baud: serial rate, bit/s (sets the transmission delay).
        talker: NMEA talker ID.
    """

    port: str
    params: Params
    latency_s: float
    noise_mps: float
    baud: int
    talker: str
    fault: SensorFault | None = None
    """A fault injected into the readings (:mod:`emlogd.offline.simfaults`)."""


EMLOG1 = EmlogSpec("emlog1", Params("EM4", 0.03, 0.17, 0.12), 3.2, 0.03, 4800, "VW")
EMLOG2 = EmlogSpec("emlog2", Params("EM4", -0.02, -0.11, -0.05), 0.45, 0.05, 38400, "VM")
SENSOR_LIMITS = {
    "a": (-0.2, 0.2),
    "m": (-0.5, 0.5),
    "b": (-1.0, 1.0),
    "latency": (0.0, 8.0),
    "noise": (0.0, 0.5),
}
"""The ranges :func:`check_emlog` accepts: curvature a (s/m), scale m, bias b (m/s),
latency (s, within the default ``max_lag_s`` of 10 s with room for the lag search's
reach) and white noise (m/s, 1σ); ``emlogd simulate --sensor`` names them so."""


def _sensor_values(e: EmlogSpec) -> dict[str, float]:
    """The values :data:`SENSOR_LIMITS` names, of one EMlog."""
    p = e.params
    return {"a": p.a_spm, "m": p.m, "b": p.b_mps, "latency": e.latency_s, "noise": e.noise_mps}


def check_emlog(e: EmlogSpec) -> None:
    """Refuse an EMlog outside :data:`SENSOR_LIMITS`.

    Raises:
        ValueError: naming the value and its range.
    """
    for name, x in _sensor_values(e).items():
        lo, hi = SENSOR_LIMITS[name]
        if not (math.isfinite(x) and lo <= x <= hi):
            raise ValueError(f"{e.port} {name} must be within [{lo:g}, {hi:g}], not {x!r}")


def with_sensor(e: EmlogSpec, given: Mapping[str, float]) -> EmlogSpec:
    """``e`` with some of the values :data:`SENSOR_LIMITS` names replaced (its EM4
    error model, latency, noise), checked by :func:`check_emlog`.

    Raises:
        ValueError: a name :data:`SENSOR_LIMITS` does not know, or a value outside it.
    """
    for key in given:
        if key not in SENSOR_LIMITS:
            raise ValueError(f"{key!r}: expected KEY=V with KEY one of {', '.join(SENSOR_LIMITS)}")
    v = _sensor_values(e) | dict(given)
    new = dataclasses.replace(
        e,
        params=Params("EM4", v["a"], v["m"], v["b"]),
        latency_s=v["latency"],
        noise_mps=v["noise"],
    )
    check_emlog(new)
    return new


DVL_PORT = "dvl"
DVL_BAUD = 115200
DVL_NOISE_MPS = 0.01
"""DVL bottom-track noise per axis, m/s (1σ), before the 1 mm/s quantisation."""

GNSS_PORT = "gnss"
GNSS_BAUD = 9600
GNSS_NOISE_MPS = 0.05
"""GNSS velocity noise on each of east and north, m/s (1σ): SOG σ ≈ 0.05 m/s, COG σ ≈
0.05/SOG rad."""
GNSS_LAG_S = 0.6
"""Age of the GNSS velocity at its fix time, s (the receiver's filter)."""
GNSS_OUTPUT_DELAY_S = 0.1
"""Time from the fix to the first byte of its RMC, s. With the 9600-baud transmission
the reference reaches the receiver about 0.78 s behind the truth."""
GNSS_ORIGIN_DEG = (43.1, 5.9)
"""Latitude and longitude of every trajectory's start (positions in the RMC)."""
EARTH_RADIUS_M = 6_371_000.0

MAX_CURRENT_MPS = 3.0
"""Largest current component :func:`simulate` accepts, m/s."""

TRUTH_CSV = "truth.csv.gz"
TRUTH_COLUMNS = (
    "t",
    "trajectory",
    "stw_mps",
    "heading_deg",
    "current_n_mps",
    "current_e_mps",
    "bottom_lock",
)
"""Columns of the truth per sample: receive-clock time (epoch s), trajectory index
(1–5), true speed through the water along the hull (m/s), heading (degrees true),
sea current north and east (m/s), DVL bottom lock (0/1)."""
TRUTH_STEP = 2
"""Every second integration step goes to the truth CSV."""
TRUTH_RATE_HZ = 1.0 / (DT_S * TRUTH_STEP)

FAULT_RATES: dict[str, float] = {
    "corrupt": 2e-4,
    "truncate": 2e-4,
    "noise_burst": 1e-4,
    "dropout": 5e-4,
}
"""Per-line (per-ensemble for PD0) fault probabilities."""


@dataclass(slots=True)
class TrajectoryTruth:
    """What really happened during one trajectory (written to truth.yaml)."""

    name: str
    file: str
    t_start: float
    duration_s: float
    mean_stw_mps: float
    std_stw_mps: float
    mean_sog_mps: float
    max_current_mps: float
    bottom_lock_fraction: float
    lines: dict[str, int] = field(default_factory=dict)
    faults: dict[str, int] = field(default_factory=dict)
    rmse_raw_mps: dict[str, float] = field(default_factory=dict)
    rmse_best_mps: dict[str, float] = field(default_factory=dict)
    rmse_floor_mps: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        """Plain types for YAML."""
        return {
            "name": self.name,
            "file": self.file,
            "t_start": self.t_start,
            "duration_s": round(self.duration_s, 3),
            "mean_stw_mps": round(self.mean_stw_mps, 4),
            "std_stw_mps": round(self.std_stw_mps, 4),
            "mean_sog_mps": round(self.mean_sog_mps, 4),
            "max_current_mps": round(self.max_current_mps, 4),
            "bottom_lock_fraction": round(self.bottom_lock_fraction, 4),
            "lines": dict(self.lines),
            "faults": dict(self.faults),
            "rmse_raw_mps": {k: round(v, 4) for k, v in self.rmse_raw_mps.items()},
            "rmse_best_mps": {k: round(v, 4) for k, v in self.rmse_best_mps.items()},
            "rmse_floor_mps": {k: round(v, 4) for k, v in self.rmse_floor_mps.items()},
        }


@dataclass(frozen=True, slots=True)
class SimulationResult:
    """What :func:`simulate` wrote.

    Attributes:
        outdir: the output directory.
        files: the capture files, in trial order.
        truth_path: the truth YAML file.
        trajectories: per-trajectory truth.
        elapsed_s: wall time taken, s.
    """

    outdir: Path
    files: tuple[Path, ...]
    truth_path: Path
    trajectories: tuple[TrajectoryTruth, ...]
    elapsed_s: float


# ------------------------------------------------------------------ kinematics


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


def _bottom_lock(t: FloatArray, rng: np.random.Generator) -> npt.NDArray[np.bool_]:
    """Bottom lock as a two-state Markov chain (mean 10 min locked, 25 s lost)."""
    lock = np.ones(t.size, dtype=bool)
    now = float(rng.exponential(600.0))
    while now < t[-1]:
        lost = float(rng.uniform(8.0, 45.0))
        lock[(t >= now) & (t < now + lost)] = False
        now += lost + float(rng.exponential(600.0))
    return lock


# ------------------------------------------------------------------ sensors


@dataclass(slots=True)
class _Line:
    t: float
    port: str
    data: bytes
    binary: bool


@dataclass(slots=True)
class _Faults:
    rng: np.random.Generator
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FAULT_RATES, 0))

    def text(self, line: str) -> bytes | None:
        """Apply at most one fault to a text line; None means dropped. Returns the wire bytes."""
        u = float(self.rng.random())
        raw = line.encode("ascii")
        edge = 0.0
        for kind, p in FAULT_RATES.items():
            edge += p
            if u >= edge:
                continue
            self.counts[kind] += 1
            if kind == "dropout":
                return None
            if kind == "corrupt":
                i = int(self.rng.integers(1, max(2, len(raw) - 3)))
                b = bytearray(raw)
                b[i] = ord("#") if b[i] != ord("#") else ord("%")
                return bytes(b) + b"\r\n"
            if kind == "truncate":
                return raw[: int(self.rng.integers(1, len(raw)))] + b"\r\n"
            noise = bytes(self.rng.integers(0, 256, int(self.rng.integers(3, 40)), dtype=np.uint8))
            return noise + raw + b"\r\n"
        return raw + b"\r\n"

    def binary(self, chunk: bytes) -> bytes | None:
        """Apply at most one fault to a binary ensemble."""
        u = float(self.rng.random())
        edge = 0.0
        for kind, p in FAULT_RATES.items():
            edge += p
            if u >= edge:
                continue
            self.counts[kind] += 1
            if kind == "dropout":
                return None
            b = bytearray(chunk)
            if kind == "corrupt":
                b[int(self.rng.integers(2, len(b)))] ^= 0x5A
                return bytes(b)
            if kind == "truncate":
                return bytes(b[: int(self.rng.integers(1, len(b)))])
            noise = bytes(self.rng.integers(0, 256, int(self.rng.integers(3, 40)), dtype=np.uint8))
            return noise + bytes(b)
        return chunk


def _interp(k: Kinematics, x: FloatArray, at: FloatArray) -> FloatArray:
    return np.asarray(np.interp(at, k.t, x), dtype=np.float64)


def _emlog_lines(
    emlog: EmlogSpec,
    k: Kinematics,
    t0: float,
    rng: np.random.Generator,
    faults: _Faults,
    out: list[_Line],
) -> tuple[FloatArray, FloatArray]:
    """Emit an EMlog's sentences; return (sample times, raw readings in m/s) of its STW series."""
    p = emlog.params
    period_vhw = 1.0 if emlog.port == "emlog1" else 0.2
    phase = float(rng.uniform(0.0, period_vhw))
    t_vhw = np.arange(phase + emlog.latency_s, k.t[-1], period_vhw)
    true_u = _interp(k, k.surge, t_vhw - emlog.latency_s)
    raw = forward_array(p, true_u) + rng.normal(0.0, emlog.noise_mps, t_vhw.size)
    if emlog.fault is not None:
        raw = emlog.fault.apply(t0 - START_EPOCH_S + t_vhw - emlog.latency_s, raw, round(t0))
    # the sentence carries two decimals of knots: the receiver sees the quantised value
    raw = np.round(raw / KNOT_MPS, 2) * KNOT_MPS
    byte_s = 10.0 / emlog.baud
    jitter = rng.uniform(0.0, 0.005, t_vhw.size)
    for ti, vi, ji in zip(t_vhw.tolist(), raw.tolist(), jitter.tolist(), strict=True):
        line = encode_vhw(vi, talker=emlog.talker)
        wire = faults.text(line)
        if wire is not None:
            out.append(_Line(t0 + ti + len(wire) * byte_s + ji, emlog.port, wire, False))
    if emlog.port == "emlog2":
        t_vbw = np.arange(phase + 0.05 + emlog.latency_s, k.t[-1], 0.1)
        u = _interp(k, k.surge, t_vbw - emlog.latency_s)
        w = _interp(k, k.sway, t_vbw - emlog.latency_s)
        long_ = forward_array(p, u) + rng.normal(0.0, emlog.noise_mps, t_vbw.size)
        if emlog.fault is not None:
            long_ = emlog.fault.apply(
                t0 - START_EPOCH_S + t_vbw - emlog.latency_s, long_, round(t0) + 1
            )
        trans = (1.0 + p.m) * w + rng.normal(0.0, emlog.noise_mps, t_vbw.size)
        jit = rng.uniform(0.0, 0.005, t_vbw.size)
        for ti, li, tr, ji in zip(
            t_vbw.tolist(), long_.tolist(), trans.tolist(), jit.tolist(), strict=True
        ):
            line = encode_vbw(li, tr, talker=emlog.talker)
            wire = faults.text(line)
            if wire is not None:
                out.append(_Line(t0 + ti + len(wire) * byte_s + ji, emlog.port, wire, False))
    return t_vhw, raw


def _dvl_lines(
    k: Kinematics,
    lock: npt.NDArray[np.bool_],
    t0: float,
    rng: np.random.Generator,
    faults: _Faults,
    out: list[_Line],
    dvl_format: DvlFormat,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
    """Emit the DVL ensembles; return (times, measured longitudinal m/s, valid)."""
    from drivers.rdi_ascii import encode_pd6

    if dvl_format == "pd0":
        from drivers.rdi_pd0 import encode_pd0
    t_ens = np.arange(float(rng.uniform(0.0, 0.1)), k.t[-1], 0.1)
    fwd, stb = k.ground_ship()
    f = np.round(_interp(k, fwd, t_ens) + rng.normal(0.0, DVL_NOISE_MPS, t_ens.size), 3)
    s = np.round(_interp(k, stb, t_ens) + rng.normal(0.0, DVL_NOISE_MPS, t_ens.size), 3)
    heading = np.degrees(np.interp(t_ens, k.t, np.unwrap(k.heading))) % 360.0
    valid = np.interp(t_ens, k.t, lock.astype(np.float64)) > 0.5
    depth = 25.0 + 10.0 * np.sin(2.0 * math.pi * (t0 + t_ens) / 1800.0)
    byte_s = 10.0 / DVL_BAUD
    jitter = rng.uniform(0.0, 0.005, t_ens.size)
    for i, ti in enumerate(t_ens.tolist()):
        stamp = datetime.fromtimestamp(t0 + ti, UTC)
        ok = bool(valid[i])
        vel = (float(f[i]), float(s[i])) if ok else None
        rng_m = float(depth[i]) if ok else None
        t_rx = t0 + ti + float(jitter[i])
        if dvl_format == "pd0":
            chunk = encode_pd0(
                ensemble_number=i + 1,
                timestamp=stamp,
                heading_deg=float(heading[i]),
                bottom_ship_mps=vel,
                range_m=rng_m,
            )
            wire = faults.binary(chunk)
            if wire is not None:
                out.append(_Line(t_rx + len(wire) * byte_s, DVL_PORT, wire, True))
            continue
        lines = encode_pd6(
            timestamp=stamp,
            heading_deg=float(heading[i]),
            bottom_ship_mps=None if vel is None else (vel[1], vel[0], 0.0),
            range_m=rng_m,
        )
        sent = 0
        for line in lines:
            wire = faults.text(line)
            if wire is None:
                continue
            sent += len(wire)
            out.append(_Line(t_rx + sent * byte_s, DVL_PORT, wire, False))
    return t_ens, f, valid


def _gnss_lines(
    k: Kinematics,
    t0: float,
    rng: np.random.Generator,
    faults: _Faults,
    out: list[_Line],
) -> int:
    """Emit the GNSS receiver's RMC sentences at 1 Hz; return how many fixes were made.

    Fixes fall on whole UTC seconds. The velocity is the ground velocity of
    :data:`GNSS_LAG_S` earlier (the receiver's filter) plus white noise of
    :data:`GNSS_NOISE_MPS` on each of east and north: SOG is off by about that σ and
    COG by about σ/SOG rad, which grows at low speed. The sentence leaves
    :data:`GNSS_OUTPUT_DELAY_S` after the fix, at :data:`GNSS_BAUD`.
    """
    first = math.ceil(t0) - t0
    t_fix = np.arange(first, k.t[-1], 1.0)
    s, c = np.sin(k.heading), np.cos(k.heading)
    ve = k.surge * s + k.sway * c + k.current_e
    vn = k.surge * c - k.sway * s + k.current_n
    at = t_fix - GNSS_LAG_S
    ve_f = _interp(k, ve, at) + rng.normal(0.0, GNSS_NOISE_MPS, t_fix.size)
    vn_f = _interp(k, vn, at) + rng.normal(0.0, GNSS_NOISE_MPS, t_fix.size)
    sog = np.hypot(ve_f, vn_f)
    cog = np.degrees(np.arctan2(ve_f, vn_f)) % 360.0
    east, north = k.position()
    lat = GNSS_ORIGIN_DEG[0] + np.degrees(_interp(k, north, at) / EARTH_RADIUS_M)
    lon = GNSS_ORIGIN_DEG[1] + np.degrees(
        _interp(k, east, at) / (EARTH_RADIUS_M * math.cos(math.radians(GNSS_ORIGIN_DEG[0])))
    )
    byte_s = 10.0 / GNSS_BAUD
    jitter = rng.uniform(0.0, 0.005, t_fix.size)
    for i, ti in enumerate(t_fix.tolist()):
        line = encode_rmc(
            datetime.fromtimestamp(round(t0 + ti), UTC),
            float(sog[i]),
            float(cog[i]),
            lat_deg=float(lat[i]),
            lon_deg=float(lon[i]),
        )
        wire = faults.text(line)
        if wire is not None:
            t_rx = t0 + ti + GNSS_OUTPUT_DELAY_S + len(wire) * byte_s + float(jitter[i])
            out.append(_Line(t_rx, GNSS_PORT, wire, False))
    return int(t_fix.size)


def _rmse(a: FloatArray, b: FloatArray) -> float:
    d = a - b
    return float(math.sqrt(float(np.mean(d * d)))) if d.size else math.nan


def _ref_at(
    t_ref: FloatArray, v_ref: FloatArray, ok: npt.NDArray[np.bool_], t: FloatArray
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Reference interpolated at ``t``; usable where both neighbours are valid."""
    idx = np.clip(np.searchsorted(t_ref, t), 1, t_ref.size - 1)
    usable = ok[idx] & ok[idx - 1] & (t >= t_ref[0]) & (t <= t_ref[-1])
    return np.asarray(np.interp(t, t_ref, v_ref), dtype=np.float64), usable


# ------------------------------------------------------------------ the trial


def simulate(
    outdir: str | Path,
    *,
    seed: int = 1,
    scale: float = 1.0,
    dvl_format: DvlFormat = "pd6",
    current: tuple[float, float] | None = None,
    circles: CirclesMode = "steps",
    emlogs: tuple[EmlogSpec, EmlogSpec] = (EMLOG1, EMLOG2),
    progress: ProgressFn | None = None,
    current_switch: SwitchingCurrent | None = None,
    on_written: Callable[[TrajectoryTruth, Path], None] | None = None,
) -> SimulationResult:
    """Write the five trajectories, ``truth.yaml`` and ``truth.csv.gz`` into ``outdir``.

    Args:
        outdir: output directory (created if missing; existing files are replaced).
        seed: random seed; the output is a pure function of the arguments.
        scale: duration factor (``0.1`` makes every trajectory 10 % as long).
        dvl_format: ``"pd6"`` (default) or ``"pd0"``.
        current: a constant sea current (north, east), m/s, each within ±3 m/s; None
            (default): the slowly varying current.
        circles: ``steps`` (default: the circles at three throttle settings) or
            ``constant`` (at one commanded speed).
        emlogs: the two EMlogs (ports ``emlog1`` and ``emlog2``; default
            :data:`EMLOG1` and :data:`EMLOG2`), see :func:`check_emlog`.
        progress: called with (message, fraction done) after each trajectory.
        current_switch: a current jumping between zero and a vector (replaces
            ``current``; :mod:`emlogd.offline.simfaults`).
        on_written: called with each trajectory's truth and capture as it is written
            (a caller can report each file as it comes).

    Returns:
        What was written.

    Raises:
        ValueError: ``scale`` not in (0, 10], an unknown ``dvl_format`` or ``circles``,
            a current that is not finite or beyond ±3 m/s, or an EMlog outside the
            ranges of :func:`check_emlog` or on another port.
    """
    if not 0.0 < scale <= 10.0:
        raise ValueError(f"scale must be in (0, 10], not {scale}")
    if dvl_format not in ("pd6", "pd0"):
        raise ValueError(f"dvl_format must be 'pd6' or 'pd0', not {dvl_format!r}")
    if circles not in ("steps", "constant"):
        raise ValueError(f"circles must be 'steps' or 'constant', not {circles!r}")
    if current is not None and not all(
        math.isfinite(c) and abs(c) <= MAX_CURRENT_MPS for c in current
    ):
        raise ValueError(
            f"current (north, east) must be finite and within ±{MAX_CURRENT_MPS:g} m/s, "
            f"not {current}"
        )
    if tuple(e.port for e in emlogs) != (EMLOG1.port, EMLOG2.port):
        raise ValueError(
            f"the EMlogs are ports {EMLOG1.port} and {EMLOG2.port}, in that order, "
            f"not {[e.port for e in emlogs]}"
        )
    for e in emlogs:
        check_emlog(e)
    started = time.perf_counter()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    root = np.random.SeedSequence(seed)
    t0 = START_EPOCH_S
    truths: list[TrajectoryTruth] = []
    files: list[Path] = []
    ports = {"emlog1": "nmea0183", "emlog2": "nmea0183", DVL_PORT: dvl_format}
    ports[GNSS_PORT] = "nmea0183"
    rows: list[FloatArray] = []
    for spec, child in zip(TRAJECTORIES, root.spawn(len(TRAJECTORIES)), strict=True):
        rng = np.random.default_rng(child)
        # the GNSS draws from a stream of its own: the other ports' bytes do not move
        gnss_rng = np.random.default_rng(child.spawn(1)[0])
        duration = spec.duration_min * 60.0 * scale
        k = kinematics(spec, duration, rng, current=current, circles=circles)
        if current_switch is not None:
            c_n, c_e = current_switch.at(t0 - START_EPOCH_S + k.t)
            k = dataclasses.replace(k, current_n=c_n, current_e=c_e)
        lock = _bottom_lock(k.t, rng)
        faults = _Faults(np.random.default_rng(rng.integers(2**63)))
        lines: list[_Line] = []
        series = {e.port: _emlog_lines(e, k, t0, rng, faults, lines) for e in emlogs}
        t_ref, v_ref, ok = _dvl_lines(k, lock, t0, rng, faults, lines, dvl_format)
        _gnss_lines(k, t0, gnss_rng, faults, lines)  # last: earlier ports' faults stay put
        lines.sort(key=lambda ln: ln.t)
        rows.append(_truth_rows(spec.index, k, lock, t0))
        path = out / spec.filename
        counts = dict.fromkeys(ports, 0)
        with CaptureWriter(path, ports) as writer:
            writer.comment(
                f"emlogd simulate: trajectory {spec.index} {spec.kind}, seed {seed}, "
                f"scale {scale}, dvl {dvl_format}"
            )
            for ln in lines:
                if ln.binary or not _plain(ln.data):
                    writer.write_chunk(ln.t, ln.port, ln.data)
                else:
                    writer.write_line(ln.t, ln.port, ln.data[:-2])
                counts[ln.port] += 1
        fwd, _ = k.ground_ship()
        truth = TrajectoryTruth(
            name=spec.kind,
            file=spec.filename,
            t_start=t0,
            duration_s=duration,
            mean_stw_mps=float(np.mean(k.surge)),
            std_stw_mps=float(np.std(k.surge)),
            mean_sog_mps=float(np.mean(fwd)),
            max_current_mps=float(np.max(np.hypot(k.current_e, k.current_n))),
            bottom_lock_fraction=float(np.mean(lock)),
            lines=counts,
            faults=dict(faults.counts),
        )
        for e in emlogs:
            t_s, raw = series[e.port]
            ref, usable = _ref_at(t_ref, v_ref, ok, t_s - e.latency_s)
            truth.rmse_raw_mps[e.port] = _rmse(raw[usable], ref[usable])
            truth.rmse_best_mps[e.port] = _rmse(correct_array(e.params, raw[usable]), ref[usable])
            stw = _interp(k, k.surge, t_s - e.latency_s)
            truth.rmse_floor_mps[e.port] = _rmse(correct_array(e.params, raw), stw)
        truths.append(truth)
        files.append(path)
        t0 += duration + GAP_S * scale
        if on_written is not None:
            on_written(truth, path)
        if progress is not None:
            progress(f"simulate: {spec.filename}", spec.index / len(TRAJECTORIES))
    _write_truth_csv(out / TRUTH_CSV, np.concatenate(rows))
    truth_path = out / "truth.yaml"
    doc = {
        "schema": 1,
        "generator": "emlogd simulate",
        "seed": seed,
        "scale": scale,
        "dvl_format": dvl_format,
        "current": "slowly varying"
        if current is None
        else {"north_mps": float(current[0]), "east_mps": float(current[1])},
        "circles": circles,
        "truth_csv": TRUTH_CSV,
        "latency_reference": "the DVL (no latency); EMlog latencies are relative to it",
        "fault_rates_per_line": dict(FAULT_RATES),
        "sensors": {
            e.port: {
                "model": "EM4",
                "a_spm": e.params.a_spm,
                "m": e.params.m,
                "b_mps": e.params.b_mps,
                "latency_s": e.latency_s,
                "noise_mps": e.noise_mps,
                "baud": e.baud,
                "talker": e.talker,
            }
            for e in emlogs
        }
        | {DVL_PORT: {"format": dvl_format, "noise_mps": DVL_NOISE_MPS, "baud": DVL_BAUD}}
        | {
            GNSS_PORT: {
                "sentence": "RMC",
                "rate_hz": 1.0,
                "noise_mps": GNSS_NOISE_MPS,
                "latency_s": GNSS_LAG_S,
                "output_delay_s": GNSS_OUTPUT_DELAY_S,
                "baud": GNSS_BAUD,
            }
        },
        "trajectories": [t.as_dict() for t in truths],
    }
    truth_path.write_text(
        "# emlogd simulate truth: what the captures should let a calibration find.\n"
        "# rmse_raw_mps: raw reading vs DVL bottom track (longitudinal) at the true latency;\n"
        "# rmse_best_mps: the same after the true inverse model (the floor any calibration\n"
        "# can reach against the DVL: noise, quantisation and current in the reference remain);\n"
        "# rmse_floor_mps: the true inverse model against the true speed through water.\n"
        f"# {TRUTH_CSV}: the truth per sample at {TRUTH_RATE_HZ:g} Hz (read_truth reads it).\n"
        + yaml.safe_dump(doc, sort_keys=False),
        encoding="utf-8",
    )
    return SimulationResult(
        out, tuple(files), truth_path, tuple(truths), time.perf_counter() - started
    )


def _plain(data: bytes) -> bool:
    """A wire line that a capture can store as text: printable ASCII ending in CR LF."""
    if not data.endswith(b"\r\n"):
        return False
    return all(32 <= c < 127 for c in data[:-2])


# ------------------------------------------------------------------ the truth per sample


def _truth_rows(index: int, k: Kinematics, lock: npt.NDArray[np.bool_], t0: float) -> FloatArray:
    """One trajectory's rows of the truth CSV (:data:`TRUTH_COLUMNS`)."""
    sl = slice(None, None, TRUTH_STEP)
    return np.column_stack(
        [
            t0 + k.t[sl],
            np.full(k.t[sl].size, float(index)),
            k.surge[sl],
            np.degrees(k.heading[sl]) % 360.0,
            k.current_n[sl],
            k.current_e[sl],
            lock[sl].astype(np.float64),
        ]
    )


def _write_truth_csv(path: Path, rows: FloatArray) -> None:
    """Write the truth rows as gzip CSV, byte-identical for identical rows (no mtime)."""
    text = io.StringIO()
    text.write(",".join(TRUTH_COLUMNS) + "\n")
    np.savetxt(text, rows, fmt=["%.3f", "%d", "%.4f", "%.3f", "%.4f", "%.4f", "%d"], delimiter=",")
    with path.open("wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as gz:
        gz.write(text.getvalue().encode("ascii"))


class TruthError(EmlogdError):
    """A truth directory cannot be read (the message names the file and why)."""


@dataclass(frozen=True, eq=False)
class Truth:
    """The truth of a simulated trial (``truth.csv.gz`` and ``truth.yaml``).

    Arrays have one entry per truth sample (:data:`TRUTH_RATE_HZ`), in time order.

    Attributes:
        t: time, epoch s (the captures' receive clock).
        trajectory: trajectory index, 1–5.
        stw_mps: true speed through the water along the hull, m/s.
        heading_deg: heading, degrees true.
        current_n_mps: sea current north, m/s.
        current_e_mps: sea current east, m/s.
        bottom_lock: the DVL's bottom lock.
        sensors: ``truth.yaml``'s ``sensors`` section (error models, latencies).
    """

    t: FloatArray
    trajectory: npt.NDArray[np.int64]
    stw_mps: FloatArray
    heading_deg: FloatArray
    current_n_mps: FloatArray
    current_e_mps: FloatArray
    bottom_lock: npt.NDArray[np.bool_]
    sensors: dict[str, dict[str, object]]

    def stw_at(self, t: npt.ArrayLike) -> FloatArray:
        """True speed through the water at times ``t``; nan outside the trajectories.

        Interpolated linearly between two samples of one trajectory, never across
        the idle time between two trajectories.
        """
        q = np.asarray(t, dtype=np.float64)
        n = self.t.size
        if n < 2:
            return np.full(q.shape, np.nan)
        idx = np.clip(np.searchsorted(self.t, q), 1, n - 1)
        inside = (q >= self.t[idx - 1]) & (q <= self.t[idx])
        same = self.trajectory[idx] == self.trajectory[idx - 1]
        v = np.interp(q, self.t, self.stw_mps)
        return np.asarray(np.where(inside & same, v, np.nan), dtype=np.float64)

    def emlog(self, port: str) -> tuple[Params, float]:
        """A simulated EMlog's true error model and latency (s, behind the truth).

        Raises:
            TruthError: ``port`` is not a simulated EMlog.
        """
        spec = self.sensors.get(port)
        if not isinstance(spec, dict) or "latency_s" not in spec or "m" not in spec:
            emlogs = [p for p, v in self.sensors.items() if isinstance(v, dict) and "m" in v]
            raise TruthError(f"the truth has no EMlog {port!r} (has {', '.join(emlogs)})")
        params = Params(
            check_model(str(spec.get("model", "EM4"))),
            float(spec["a_spm"]),  # type: ignore[arg-type]
            float(spec["m"]),  # type: ignore[arg-type]
            float(spec["b_mps"]),  # type: ignore[arg-type]
        )
        return params, float(spec["latency_s"])  # type: ignore[arg-type]


def read_truth(directory: str | Path) -> Truth:
    """Read the truth that :func:`simulate` wrote into ``directory``.

    Raises:
        TruthError: a file is missing or malformed.
    """
    d = Path(directory)
    csv_path, yaml_path = d / TRUTH_CSV, d / "truth.yaml"
    for p in (csv_path, yaml_path):
        if not p.is_file():
            raise TruthError(f"{p}: no such file (emlogd simulate writes it)")
    try:
        doc = yaml.safe_load(yaml_path.read_text(encoding="utf-8"))
        sensors = doc["sensors"]
        if not isinstance(sensors, dict):
            raise TypeError("sensors is not a mapping")
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise TruthError(f"{yaml_path}: not a simulation truth ({exc})") from None
    try:
        with gzip.open(csv_path, "rt", encoding="ascii") as f:
            header = f.readline().strip().split(",")
            if tuple(header) != TRUTH_COLUMNS:
                raise ValueError(f"columns {header}, expected {list(TRUTH_COLUMNS)}")
            data = np.loadtxt(f, delimiter=",", ndmin=2)
    except (OSError, EOFError, ValueError, UnicodeDecodeError) as exc:
        raise TruthError(f"{csv_path}: {exc}") from None
    if data.shape[1] != len(TRUTH_COLUMNS) or np.any(np.diff(data[:, 0]) <= 0.0):
        raise TruthError(f"{csv_path}: expected {len(TRUTH_COLUMNS)} columns in time order")
    return Truth(
        t=data[:, 0].copy(),
        trajectory=data[:, 1].astype(np.int64),
        stw_mps=data[:, 2].copy(),
        heading_deg=data[:, 3].copy(),
        current_n_mps=data[:, 4].copy(),
        current_e_mps=data[:, 5].copy(),
        bottom_lock=data[:, 6] > 0.5,
        sensors=sensors,
    )


@dataclass(frozen=True, slots=True)
class TruthScore:
    """A UUT's speeds scored against the true speed through the water.

    Attributes:
        n_samples: readings with a truth (and a corrected speed) scored.
        rmse_raw: raw readings vs the truth, m/s.
        rmse_corrected: the corrected speeds vs the truth, m/s.
        rmse_floor: raw readings through the true inverse model vs the truth, m/s
            (what a perfect calibration would reach: noise and quantisation remain).
    """

    n_samples: int
    rmse_raw: float
    rmse_corrected: float
    rmse_floor: float
    imo_raw: ImoVerdict | None = None
    """The raw readings' IMO A.824(19) verdict against the truth."""
    imo_corrected: ImoVerdict | None = None
    """The corrected speeds' IMO A.824(19) verdict against the truth."""

    def to_dict(self) -> dict[str, object]:
        """Stable JSON keys (README: ``evaluate --json`` and ``replay --json``)."""

        def fin(x: float) -> float | None:
            return round(x, 5) if math.isfinite(x) else None

        return {
            "n_samples": self.n_samples,
            "rmse_raw": fin(self.rmse_raw),
            "rmse_corrected": fin(self.rmse_corrected),
            "rmse_floor": fin(self.rmse_floor),
            "imo": None
            if self.imo_raw is None or self.imo_corrected is None
            else {"raw": self.imo_raw.as_dict(), "corrected": self.imo_corrected.as_dict()},
        }


def score_truth(
    truth: Truth, port: str, t: npt.ArrayLike, raw: npt.ArrayLike, corrected: npt.ArrayLike
) -> TruthScore:
    """Score a UUT's readings and their corrected speeds against the truth.

    Each reading received at ``t`` is paired with the true speed through the water
    at ``t`` minus the EMlog's true latency; samples without a truth there (idle time
    between trajectories) or without a finite corrected speed are left out.

    Raises:
        TruthError: ``port`` is not a simulated EMlog.
    """
    params, latency = truth.emlog(port)
    tt = np.asarray(t, dtype=np.float64)
    r = np.asarray(raw, dtype=np.float64)
    c = np.asarray(corrected, dtype=np.float64)
    stw = truth.stw_at(tt - latency)
    ok = np.isfinite(stw) & np.isfinite(r) & np.isfinite(c)
    floor = correct_array(params, r[ok])
    return TruthScore(
        int(ok.sum()),
        _rmse(r[ok], stw[ok]),
        _rmse(c[ok], stw[ok]),
        _rmse(floor, stw[ok]),
        imo_verdict(stw[ok], r[ok]),
        imo_verdict(stw[ok], c[ok]),
    )
