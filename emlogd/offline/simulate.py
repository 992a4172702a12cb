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
quantised to 0.01 kn by the two-decimal NMEA field. ``emlog2``'s VBW carries the
athwart speed too, ``(1 + m_t)·w + b_t`` (the transverse scale ``m_t`` is ``m``
unless given); a sensor turned by a misalignment α (``--sensor
emlog2:misalign=DEG``) reads the water's velocity on its own axes,
``u·cos α + w·sin α`` forward (VHW and VBW) and ``−u·sin α + w·cos α`` athwart
(:class:`calib.twoaxis.TwoAxisParams`). With no misalignment and no transverse error
given the bytes are those of a trial without them. The DVL bottom track sees the
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
speed through the water along and athwart the hull, heading, current, bottom lock), which
:func:`read_truth` reads and :func:`score_truth` scores speeds against.

Every file, the truth files included, is a pure function of the arguments: two runs
give identical bytes.

The motion is in :mod:`emlogd.offline.simkinematics`, the sensors and their faults in
:mod:`emlogd.offline.simsensors`, the truth files and the scoring in
:mod:`emlogd.offline.simtruth`; this module writes the trial and exports their names.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from calib.models import FloatArray, correct_array
from drivers.io.capture import CaptureWriter
from emlogd.offline import ProgressFn
from emlogd.offline.simfaults import SwitchingCurrent
from emlogd.offline.simkinematics import (
    DT_S,
    FIGURE8_SWING_RAD,
    GAP_S,
    START_EPOCH_S,
    TRAJECTORIES,
    CirclesMode,
    Kinematics,
    TrajectoryKind,
    TrajectorySpec,
    interp,
    kinematics,
)
from emlogd.offline.simsensors import (
    DVL_BAUD,
    DVL_NOISE_MPS,
    DVL_PORT,
    EARTH_RADIUS_M,
    EMLOG1,
    EMLOG2,
    FAULT_RATES,
    GNSS_BAUD,
    GNSS_LAG_S,
    GNSS_NOISE_MPS,
    GNSS_ORIGIN_DEG,
    GNSS_OUTPUT_DELAY_S,
    GNSS_PORT,
    SENSOR_LIMITS,
    DvlFormat,
    EmlogSpec,
    Faults,
    Line,
    bottom_lock,
    check_emlog,
    dvl_lines,
    emlog_lines,
    gnss_lines,
    with_sensor,
)
from emlogd.offline.simtruth import (
    TRUTH_COLUMNS,
    TRUTH_CSV,
    TRUTH_RATE_HZ,
    TRUTH_STEP,
    TrajectoryTruth,
    Truth,
    TruthError,
    TruthScore,
    read_truth,
    ref_at,
    rmse,
    score_truth,
    truth_rows,
    write_truth_csv,
)

__all__ = [
    "DT_S",
    "DVL_BAUD",
    "DVL_NOISE_MPS",
    "DVL_PORT",
    "EARTH_RADIUS_M",
    "EMLOG1",
    "EMLOG2",
    "FAULT_RATES",
    "FIGURE8_SWING_RAD",
    "GAP_S",
    "GNSS_BAUD",
    "GNSS_LAG_S",
    "GNSS_NOISE_MPS",
    "GNSS_ORIGIN_DEG",
    "GNSS_OUTPUT_DELAY_S",
    "GNSS_PORT",
    "MAX_CURRENT_MPS",
    "MIN_SCALE",
    "SENSOR_LIMITS",
    "START_EPOCH_S",
    "TRAJECTORIES",
    "TRUTH_COLUMNS",
    "TRUTH_CSV",
    "TRUTH_RATE_HZ",
    "TRUTH_STEP",
    "CirclesMode",
    "DvlFormat",
    "EmlogSpec",
    "Kinematics",
    "SimulationResult",
    "TrajectoryKind",
    "TrajectorySpec",
    "TrajectoryTruth",
    "Truth",
    "TruthError",
    "TruthScore",
    "check_emlog",
    "kinematics",
    "read_truth",
    "score_truth",
    "simulate",
    "with_sensor",
]


MAX_CURRENT_MPS = 3.0
"""Largest current component :func:`simulate` accepts, m/s."""

MIN_SCALE = 0.005
"""Smallest duration factor :func:`simulate` accepts: the shortest trajectory (the
15-min straight leg) 4.5 s long, so that every capture holds readings of both logs
with a reference (seeds 1–10 checked). A shorter one held none, and a scale near
zero ended in an ``IndexError``."""


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
        seed: random seed (0 or more); the output is a pure function of the arguments.
        scale: duration factor (``0.1`` makes every trajectory 10 % as long), from
            :data:`MIN_SCALE` to 10.
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
        ValueError: ``scale`` not in [:data:`MIN_SCALE`, 10], a negative ``seed``, an unknown ``dvl_format`` or ``circles``,
            a current that is not finite or beyond ±3 m/s, or an EMlog outside the
            ranges of :func:`check_emlog` or on another port.
    """
    _check_arguments(scale, dvl_format, circles, current, emlogs)
    if seed < 0:
        raise ValueError(f"seed must be 0 or more, not {seed}")
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
        lock = bottom_lock(k.t, rng)
        faults = Faults(np.random.default_rng(rng.integers(2**63)))
        lines: list[Line] = []
        series = {e.port: emlog_lines(e, k, t0, rng, faults, lines) for e in emlogs}
        t_ref, v_ref, ok = dvl_lines(k, lock, t0, rng, faults, lines, dvl_format)
        gnss_lines(k, t0, gnss_rng, faults, lines)  # last: earlier ports' faults stay put
        lines.sort(key=lambda ln: ln.t)
        rows.append(truth_rows(spec.index, k, lock, t0))
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
            ref, usable = ref_at(t_ref, v_ref, ok, t_s - e.latency_s)
            truth.rmse_raw_mps[e.port] = rmse(raw[usable], ref[usable])
            truth.rmse_best_mps[e.port] = rmse(correct_array(e.params, raw[usable]), ref[usable])
            stw = interp(k, k.surge, t_s - e.latency_s)
            truth.rmse_floor_mps[e.port] = rmse(correct_array(e.params, raw), stw)
        truths.append(truth)
        files.append(path)
        t0 += duration + GAP_S * scale
        if on_written is not None:
            on_written(truth, path)
        if progress is not None:
            progress(f"simulate: {spec.filename}", spec.index / len(TRAJECTORIES))
    write_truth_csv(out / TRUTH_CSV, np.concatenate(rows))
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
                "misalign_deg": e.misalign_deg,
                "m_t": e.two_axis.m_t,
                "b_t_mps": e.b_t_mps,
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


def _check_arguments(
    scale: float,
    dvl_format: str,
    circles: str,
    current: tuple[float, float] | None,
    emlogs: tuple[EmlogSpec, EmlogSpec],
) -> None:
    """Refuse what :func:`simulate` refuses (its ``Raises``), naming the argument."""
    if not MIN_SCALE <= scale <= 10.0:
        raise ValueError(f"scale must be in [{MIN_SCALE:g}, 10], not {scale}")
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


def _plain(data: bytes) -> bool:
    """A wire line that a capture can store as text: printable ASCII ending in CR LF."""
    if not data.endswith(b"\r\n"):
        return False
    return all(32 <= c < 127 for c in data[:-2])
