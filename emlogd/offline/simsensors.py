"""The simulated trial's sensors: the two EMlogs, the DVL and the GNSS receiver, each
written the way the real one reports (rates, latencies, noise, serial timing), and the
faults on their lines (:data:`FAULT_RATES`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Literal

import numpy as np
import numpy.typing as npt

from calib.models import FloatArray, Params, forward_array
from calib.twoaxis import TwoAxisParams
from drivers.nmea0183 import encode_rmc, encode_vbw, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline.simfaults import SensorFault
from emlogd.offline.simkinematics import START_EPOCH_S, Kinematics, interp

DvlFormat = Literal["pd6", "pd0"]


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
    misalign_deg: float = 0.0
    """The sensor's forward axis from the bow, degrees (> 0: to starboard): it reads
    ``u·cos α + w·sin α`` forward and ``−u·sin α + w·cos α`` athwart
    (:class:`calib.twoaxis.TwoAxisParams`)."""
    m_t: float | None = None
    """The transverse scale error (None: the longitudinal ``m``)."""
    b_t_mps: float = 0.0
    """The transverse bias, m/s."""

    @property
    def two_axis(self) -> TwoAxisParams:
        """The sensor's two-axis model (the longitudinal its EM4 parameters)."""
        return TwoAxisParams(
            self.params,
            math.radians(self.misalign_deg),
            self.params.m if self.m_t is None else self.m_t,
            self.b_t_mps,
        )


EMLOG1 = EmlogSpec("emlog1", Params("EM4", 0.03, 0.17, 0.12), 3.2, 0.03, 4800, "VW")
EMLOG2 = EmlogSpec("emlog2", Params("EM4", -0.02, -0.11, -0.05), 0.45, 0.05, 38400, "VM")
SENSOR_LIMITS = {
    "a": (-0.2, 0.2),
    "m": (-0.5, 0.5),
    "b": (-1.0, 1.0),
    "latency": (0.0, 8.0),
    "noise": (0.0, 0.5),
    "misalign": (-10.0, 10.0),
    "mt": (-0.5, 0.5),
    "bt": (-1.0, 1.0),
}
"""The ranges :func:`check_emlog` accepts: curvature a (s/m), scale m, bias b (m/s),
latency (s, within the default ``max_lag_s`` of 10 s with room for the lag search's
reach), white noise (m/s, 1σ), the misalignment (degrees, > 0: the sensor's forward
axis to starboard of the bow), the transverse scale and bias (m/s); ``emlogd
simulate --sensor`` names them so."""


def _sensor_values(e: EmlogSpec) -> dict[str, float]:
    """The values :data:`SENSOR_LIMITS` names, of one EMlog."""
    p = e.params
    return {
        "a": p.a_spm,
        "m": p.m,
        "b": p.b_mps,
        "latency": e.latency_s,
        "noise": e.noise_mps,
        "misalign": e.misalign_deg,
        "mt": p.m if e.m_t is None else e.m_t,
        "bt": e.b_t_mps,
    }


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
    error model, latency, noise, misalignment, transverse scale and bias), checked by
    :func:`check_emlog`. The transverse scale follows ``m`` unless given.

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
        misalign_deg=v["misalign"],
        m_t=v["mt"] if ("mt" in given or e.m_t is not None) else None,
        b_t_mps=v["bt"],
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

FAULT_RATES: dict[str, float] = {
    "corrupt": 2e-4,
    "truncate": 2e-4,
    "noise_burst": 1e-4,
    "dropout": 5e-4,
}
"""Per-line (per-ensemble for PD0) fault probabilities."""


def bottom_lock(t: FloatArray, rng: np.random.Generator) -> npt.NDArray[np.bool_]:
    """Bottom lock as a two-state Markov chain (mean 10 min locked, 25 s lost)."""
    lock = np.ones(t.size, dtype=bool)
    now = float(rng.exponential(600.0))
    while now < t[-1]:
        lost = float(rng.uniform(8.0, 45.0))
        lock[(t >= now) & (t < now + lost)] = False
        now += lost + float(rng.exponential(600.0))
    return lock


@dataclass(slots=True)
class Line:
    """One line (or binary ensemble) of a port as the capture receives it."""

    t: float
    """Receive time, epoch s."""
    port: str
    data: bytes
    """The wire bytes (a text line ends in CR LF)."""
    binary: bool


NOISE_BURST_BYTES = (3, 40)
"""A noise burst is this many random bytes (the upper bound excluded) before a line."""


@dataclass(slots=True)
class Faults:
    """The faults on the trial's lines: at most one per line, drawn at :data:`FAULT_RATES`,
    counted by kind. A text line and a binary ensemble take the same draws; only the
    corruption (a character of the sentence, a byte of the ensemble) and the CR LF differ."""

    rng: np.random.Generator
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FAULT_RATES, 0))

    def text(self, line: str) -> bytes | None:
        """Apply at most one fault to a text line; None means dropped. Returns the wire bytes."""
        return self._apply(line.encode("ascii"), binary=False)

    def binary(self, chunk: bytes) -> bytes | None:
        """Apply at most one fault to a binary ensemble; None means dropped."""
        return self._apply(chunk, binary=True)

    def _draw(self) -> str | None:
        """The fault of the next line (a key of :data:`FAULT_RATES`), or None."""
        u = float(self.rng.random())
        edge = 0.0
        for kind, p in FAULT_RATES.items():
            edge += p
            if u < edge:
                return kind
        return None

    def _apply(self, data: bytes, *, binary: bool) -> bytes | None:
        end = b"" if binary else b"\r\n"
        kind = self._draw()
        if kind is None:
            return data + end
        self.counts[kind] += 1
        if kind == "dropout":
            return None
        if kind == "corrupt":
            return self._corrupt(data, binary) + end
        if kind == "truncate":
            return data[: int(self.rng.integers(1, len(data)))] + end
        size = int(self.rng.integers(*NOISE_BURST_BYTES))
        return bytes(self.rng.integers(0, 256, size, dtype=np.uint8)) + data + end

    def _corrupt(self, data: bytes, binary: bool) -> bytes:
        """One byte spoilt: a binary ensemble's (past its two-byte header ID) flipped, a
        sentence's (past its ``$``, before its checksum) made ``#`` (``%`` if it was)."""
        b = bytearray(data)
        if binary:
            b[int(self.rng.integers(2, len(b)))] ^= 0x5A
        else:
            i = int(self.rng.integers(1, max(2, len(b) - 3)))
            b[i] = ord("#") if b[i] != ord("#") else ord("%")
        return bytes(b)


def emlog_lines(
    emlog: EmlogSpec,
    k: Kinematics,
    t0: float,
    rng: np.random.Generator,
    faults: Faults,
    out: list[Line],
) -> tuple[FloatArray, FloatArray]:
    """Emit an EMlog's sentences; return (sample times, raw readings in m/s) of its STW series."""
    p = emlog.params
    period_vhw = 1.0 if emlog.port == "emlog1" else 0.2
    phase = float(rng.uniform(0.0, period_vhw))
    t_vhw = np.arange(phase + emlog.latency_s, k.t[-1], period_vhw)
    true_u = interp(k, k.surge, t_vhw - emlog.latency_s)
    if emlog.misalign_deg:  # the forward axis of a turned sensor
        alpha = math.radians(emlog.misalign_deg)
        true_w = interp(k, k.sway, t_vhw - emlog.latency_s)
        true_u = true_u * math.cos(alpha) + true_w * math.sin(alpha)
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
            out.append(Line(t0 + ti + len(wire) * byte_s + ji, emlog.port, wire, False))
    if emlog.port == "emlog2":
        t_vbw = np.arange(phase + 0.05 + emlog.latency_s, k.t[-1], 0.1)
        u = interp(k, k.surge, t_vbw - emlog.latency_s)
        w = interp(k, k.sway, t_vbw - emlog.latency_s)
        if emlog.misalign_deg:  # the sensor's own axes
            alpha = math.radians(emlog.misalign_deg)
            u, w = (
                u * math.cos(alpha) + w * math.sin(alpha),
                -u * math.sin(alpha) + w * math.cos(alpha),
            )
        long_ = forward_array(p, u) + rng.normal(0.0, emlog.noise_mps, t_vbw.size)
        if emlog.fault is not None:
            long_ = emlog.fault.apply(
                t0 - START_EPOCH_S + t_vbw - emlog.latency_s, long_, round(t0) + 1
            )
        gain_t = 1.0 + (p.m if emlog.m_t is None else emlog.m_t)
        trans = gain_t * w + rng.normal(0.0, emlog.noise_mps, t_vbw.size)
        if emlog.b_t_mps:
            trans = trans + emlog.b_t_mps
        jit = rng.uniform(0.0, 0.005, t_vbw.size)
        for ti, li, tr, ji in zip(
            t_vbw.tolist(), long_.tolist(), trans.tolist(), jit.tolist(), strict=True
        ):
            line = encode_vbw(li, tr, talker=emlog.talker)
            wire = faults.text(line)
            if wire is not None:
                out.append(Line(t0 + ti + len(wire) * byte_s + ji, emlog.port, wire, False))
    return t_vhw, raw


def dvl_lines(
    k: Kinematics,
    lock: npt.NDArray[np.bool_],
    t0: float,
    rng: np.random.Generator,
    faults: Faults,
    out: list[Line],
    dvl_format: DvlFormat,
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
    """Emit the DVL ensembles; return (times, measured longitudinal m/s, valid)."""
    from drivers.rdi_ascii import encode_pd6

    if dvl_format == "pd0":
        from drivers.rdi_pd0 import encode_pd0
    t_ens = np.arange(float(rng.uniform(0.0, 0.1)), k.t[-1], 0.1)
    fwd, stb = k.ground_ship()
    f = np.round(interp(k, fwd, t_ens) + rng.normal(0.0, DVL_NOISE_MPS, t_ens.size), 3)
    s = np.round(interp(k, stb, t_ens) + rng.normal(0.0, DVL_NOISE_MPS, t_ens.size), 3)
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
                out.append(Line(t_rx + len(wire) * byte_s, DVL_PORT, wire, True))
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
            out.append(Line(t_rx + sent * byte_s, DVL_PORT, wire, False))
    return t_ens, f, valid


def gnss_lines(
    k: Kinematics,
    t0: float,
    rng: np.random.Generator,
    faults: Faults,
    out: list[Line],
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
    ve_f = interp(k, ve, at) + rng.normal(0.0, GNSS_NOISE_MPS, t_fix.size)
    vn_f = interp(k, vn, at) + rng.normal(0.0, GNSS_NOISE_MPS, t_fix.size)
    sog = np.hypot(ve_f, vn_f)
    cog = np.degrees(np.arctan2(ve_f, vn_f)) % 360.0
    east, north = k.position()
    lat = GNSS_ORIGIN_DEG[0] + np.degrees(interp(k, north, at) / EARTH_RADIUS_M)
    lon = GNSS_ORIGIN_DEG[1] + np.degrees(
        interp(k, east, at) / (EARTH_RADIUS_M * math.cos(math.radians(GNSS_ORIGIN_DEG[0])))
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
            out.append(Line(t_rx, GNSS_PORT, wire, False))
    return int(t_fix.size)
