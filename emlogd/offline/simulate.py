"""A sea trial like the paper's (section IV), written as capture v1 files.

The paper's MARVEL data set is not public, so emlogd carries its own trial. The
simulator integrates 2D vessel kinematics (surge, sway from sideslip in turns,
heading) for the paper's five trajectories, adds a slowly varying sea current, and
samples three sensors the way the real ones report:

- ``emlog1`` (Airmar DX900+ style): ``$VWVHW`` at 1 Hz, 3.2 s latency, 4800 baud;
- ``emlog2`` (Ben Marine Alize style): ``$VMVBW`` at 10 Hz and ``$VMVHW`` at 5 Hz,
  0.45 s latency, 38400 baud;
- ``dvl`` (Rowe SeaPILOT): PD6 ensembles (or PD0 with ``dvl_format="pd0"``) at
  10 Hz with bottom-lock losses, 115200 baud.

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

Every file, the truth file included, is a pure function of (seed, scale,
dvl_format): two runs give identical bytes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
import yaml

from calib.models import Params, correct_array, forward_array
from drivers.io.capture import CaptureWriter
from drivers.nmea0183 import encode_vbw, encode_vhw
from drivers.records import KNOT_MPS

FloatArray = npt.NDArray[np.float64]
Progress = Callable[[str, float], None]
DvlFormat = Literal["pd6", "pd0"]
TrajectoryKind = Literal["transit", "figure-8", "straight", "circles", "return"]

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


EMLOG1 = EmlogSpec("emlog1", Params("EM4", 0.03, 0.17, 0.12), 3.2, 0.03, 4800, "VW")
EMLOG2 = EmlogSpec("emlog2", Params("EM4", -0.02, -0.11, -0.05), 0.45, 0.05, 38400, "VM")
DVL_PORT = "dvl"
DVL_BAUD = 115200
DVL_NOISE_MPS = 0.01
"""DVL bottom-track noise per axis, m/s (1σ), before the 1 mm/s quantisation."""

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


def kinematics(spec: TrajectorySpec, duration_s: float, rng: np.random.Generator) -> Kinematics:
    """Integrate surge, heading and sideslip for one trajectory.

    Args:
        spec: the trajectory.
        duration_s: its (scaled) duration, s.
        rng: random generator.

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
    progress: Progress | None = None,
) -> SimulationResult:
    """Write the five trajectories and ``truth.yaml`` into ``outdir``.

    Args:
        outdir: output directory (created if missing; existing files are replaced).
        seed: random seed; the output is a pure function of (seed, scale, dvl_format).
        scale: duration factor (``0.1`` makes every trajectory 10 % as long).
        dvl_format: ``"pd6"`` (default) or ``"pd0"``.
        progress: called with (message, fraction done) after each trajectory.

    Returns:
        What was written.

    Raises:
        ValueError: ``scale`` not in (0, 10] or an unknown ``dvl_format``.
    """
    if not 0.0 < scale <= 10.0:
        raise ValueError(f"scale must be in (0, 10], not {scale}")
    if dvl_format not in ("pd6", "pd0"):
        raise ValueError(f"dvl_format must be 'pd6' or 'pd0', not {dvl_format!r}")
    started = time.perf_counter()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    root = np.random.SeedSequence(seed)
    t0 = START_EPOCH_S
    truths: list[TrajectoryTruth] = []
    files: list[Path] = []
    ports = {"emlog1": "nmea0183", "emlog2": "nmea0183", DVL_PORT: dvl_format}
    for spec, child in zip(TRAJECTORIES, root.spawn(len(TRAJECTORIES)), strict=True):
        rng = np.random.default_rng(child)
        duration = spec.duration_min * 60.0 * scale
        k = kinematics(spec, duration, rng)
        lock = _bottom_lock(k.t, rng)
        faults = _Faults(np.random.default_rng(rng.integers(2**63)))
        lines: list[_Line] = []
        series = {e.port: _emlog_lines(e, k, t0, rng, faults, lines) for e in (EMLOG1, EMLOG2)}
        t_ref, v_ref, ok = _dvl_lines(k, lock, t0, rng, faults, lines, dvl_format)
        lines.sort(key=lambda ln: ln.t)
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
        for e in (EMLOG1, EMLOG2):
            t_s, raw = series[e.port]
            ref, usable = _ref_at(t_ref, v_ref, ok, t_s - e.latency_s)
            truth.rmse_raw_mps[e.port] = _rmse(raw[usable], ref[usable])
            truth.rmse_best_mps[e.port] = _rmse(correct_array(e.params, raw[usable]), ref[usable])
        truths.append(truth)
        files.append(path)
        t0 += duration + GAP_S * scale
        if progress is not None:
            progress(f"simulate: {spec.filename}", spec.index / len(TRAJECTORIES))
    truth_path = out / "truth.yaml"
    doc = {
        "schema": 1,
        "generator": "emlogd simulate",
        "seed": seed,
        "scale": scale,
        "dvl_format": dvl_format,
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
            for e in (EMLOG1, EMLOG2)
        }
        | {DVL_PORT: {"format": dvl_format, "noise_mps": DVL_NOISE_MPS, "baud": DVL_BAUD}},
        "trajectories": [t.as_dict() for t in truths],
    }
    truth_path.write_text(
        "# emlogd simulate truth: what the captures should let a calibration find.\n"
        "# rmse_raw_mps: raw reading vs DVL bottom track (longitudinal) at the true latency;\n"
        "# rmse_best_mps: the same after the true inverse model (the floor any calibration\n"
        "# can reach: noise, quantisation and current in the reference remain).\n"
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
