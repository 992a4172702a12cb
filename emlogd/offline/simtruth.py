"""The simulated trial's truth: what each trajectory was (``truth.yaml``), the truth per
sample (``truth.csv.gz``), reading it back (:func:`read_truth`) and scoring speeds
against it (:func:`score_truth`)."""

from __future__ import annotations

import gzip
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import yaml

from calib.metrics import ImoVerdict, imo_verdict
from calib.models import FloatArray, Params, check_model, correct_array
from calib.twoaxis import TwoAxisParams
from drivers.errors import EmlogdError
from emlogd.offline.simkinematics import DT_S, Kinematics

TRUTH_CSV = "truth.csv.gz"
TRUTH_COLUMNS = (
    "t",
    "trajectory",
    "stw_mps",
    "heading_deg",
    "current_n_mps",
    "current_e_mps",
    "bottom_lock",
    "stw_trans_mps",
)
"""Columns of the truth per sample: receive-clock time (epoch s), trajectory index
(1–5), true speed through the water along the hull (m/s), heading (degrees true),
sea current north and east (m/s), DVL bottom lock (0/1), true speed through the
water athwart the hull (m/s, + starboard: the sway of turns)."""
TRUTH_COLUMNS_ONE_AXIS = TRUTH_COLUMNS[:-1]
"""The columns of a truth written before the athwart speed was (read as such)."""
TRUTH_STEP = 2
"""Every second integration step goes to the truth CSV."""
TRUTH_RATE_HZ = 1.0 / (DT_S * TRUTH_STEP)


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


def rmse(a: FloatArray, b: FloatArray) -> float:
    d = a - b
    return float(math.sqrt(float(np.mean(d * d)))) if d.size else math.nan


def ref_at(
    t_ref: FloatArray, v_ref: FloatArray, ok: npt.NDArray[np.bool_], t: FloatArray
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Reference interpolated at ``t``; usable where both neighbours are valid."""
    idx = np.clip(np.searchsorted(t_ref, t), 1, t_ref.size - 1)
    usable = ok[idx] & ok[idx - 1] & (t >= t_ref[0]) & (t <= t_ref[-1])
    return np.asarray(np.interp(t, t_ref, v_ref), dtype=np.float64), usable


# ------------------------------------------------------------------ the trial


def truth_rows(index: int, k: Kinematics, lock: npt.NDArray[np.bool_], t0: float) -> FloatArray:
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
            k.sway[sl],
        ]
    )


def write_truth_csv(path: Path, rows: FloatArray) -> None:
    """Write the truth rows as gzip CSV, byte-identical for identical rows (no mtime)."""
    text = io.StringIO()
    text.write(",".join(TRUTH_COLUMNS) + "\n")
    np.savetxt(
        text, rows, fmt=["%.3f", "%d", "%.4f", "%.3f", "%.4f", "%.4f", "%d", "%.4f"], delimiter=","
    )
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
        stw_trans_mps: true speed through the water athwart the hull, m/s (None: a
            truth written without it).
    """

    t: FloatArray
    trajectory: npt.NDArray[np.int64]
    stw_mps: FloatArray
    heading_deg: FloatArray
    current_n_mps: FloatArray
    current_e_mps: FloatArray
    bottom_lock: npt.NDArray[np.bool_]
    sensors: dict[str, dict[str, object]]
    stw_trans_mps: FloatArray | None = None

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

    def trans_at(self, t: npt.ArrayLike) -> FloatArray:
        """True athwart speed through the water at times ``t``, as :meth:`stw_at`.

        Raises:
            TruthError: the truth has no athwart speed.
        """
        if self.stw_trans_mps is None:
            raise TruthError("the truth has no athwart speed (simulate it again)")
        q = np.asarray(t, dtype=np.float64)
        ok = np.isfinite(self.stw_at(q))
        v = np.interp(q, self.t, self.stw_trans_mps)
        return np.asarray(np.where(ok, v, np.nan), dtype=np.float64)

    def two_axis(self, port: str) -> TwoAxisParams:
        """A simulated EMlog's true two-axis model (misalignment 0 and the transverse
        scale the longitudinal one in a truth written without them).

        Raises:
            TruthError: ``port`` is not a simulated EMlog.
        """
        params, _ = self.emlog(port)
        spec = self.sensors[port]
        return TwoAxisParams(
            params,
            math.radians(float(spec.get("misalign_deg", 0.0))),  # type: ignore[arg-type]
            float(spec.get("m_t", params.m)),  # type: ignore[arg-type]
            float(spec.get("b_t_mps", 0.0)),  # type: ignore[arg-type]
        )

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

    def paired(
        self, port: str, t: npt.ArrayLike, raw: npt.ArrayLike, corrected: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """A UUT's readings paired with the truth: each reading received at ``t`` with
        the true speed through the water at ``t`` minus the EMlog's true latency; the
        samples without a truth there (idle time between trajectories) or without a
        finite reading or corrected speed left out.

        Returns:
            ``(t, raw, corrected, true_stw)`` of the samples kept, in their order.

        Raises:
            TruthError: ``port`` is not a simulated EMlog.
        """
        _, latency = self.emlog(port)
        tt = np.asarray(t, dtype=np.float64)
        r = np.asarray(raw, dtype=np.float64)
        c = np.asarray(corrected, dtype=np.float64)
        stw = self.stw_at(tt - latency)
        ok = np.isfinite(stw) & np.isfinite(r) & np.isfinite(c)
        return tt[ok], r[ok], c[ok], stw[ok]


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
            if tuple(header) not in (TRUTH_COLUMNS, TRUTH_COLUMNS_ONE_AXIS):
                raise ValueError(f"columns {header}, expected {list(TRUTH_COLUMNS)}")
            data = np.loadtxt(f, delimiter=",", ndmin=2)
    except (OSError, EOFError, ValueError, UnicodeDecodeError) as exc:
        raise TruthError(f"{csv_path}: {exc}") from None
    if data.shape[1] != len(header) or np.any(np.diff(data[:, 0]) <= 0.0):
        raise TruthError(f"{csv_path}: expected {len(header)} columns in time order")
    return Truth(
        t=data[:, 0].copy(),
        trajectory=data[:, 1].astype(np.int64),
        stw_mps=data[:, 2].copy(),
        heading_deg=data[:, 3].copy(),
        current_n_mps=data[:, 4].copy(),
        current_e_mps=data[:, 5].copy(),
        bottom_lock=data[:, 6] > 0.5,
        sensors=sensors,
        stw_trans_mps=data[:, 7].copy() if data.shape[1] > 7 else None,
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
    """Score a UUT's readings and their corrected speeds against the truth, paired as
    :meth:`Truth.paired` pairs them; the floor is the readings corrected with the
    EMlog's true error model.

    Raises:
        TruthError: ``port`` is not a simulated EMlog.
    """
    params, _ = truth.emlog(port)
    _, r, c, stw = truth.paired(port, t, raw, corrected)
    return TruthScore(
        int(stw.size),
        rmse(r, stw),
        rmse(c, stw),
        rmse(correct_array(params, r), stw),
        imo_verdict(stw, r),
        imo_verdict(stw, c),
    )
