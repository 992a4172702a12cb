"""``emlogd replay --truth`` on a log that learns two axes (``axes: 2``): its corrected
VBW scored on both axes against a simulated trial's truth.

Every VBW reading of such a log is recorded with the forward speed the one-axis
calibration gave it, scored as a replay with ``axes: 1`` emits it (in the VBW's
hundredths of a knot, :func:`as_sent`: the emitted VBW carries the same rounding, which
against the unrounded speed reads as a loss of up to 0.2 % where both are the same
sentence), and whether learnt two-axis figures were applied; the VBW it emitted is decoded as a receiver would read
it. Each is scored against the truth's speed through the water along and athwart the
hull at the reading's time less the sensor's true latency; the floor is the reading
corrected with the true parameters (:meth:`calib.twoaxis.TwoAxisParams.correct`), as
``evaluate --axes 2 --truth`` scores it. Scores are given over the whole replay, over
the readings emitted with the figures applied, and per trajectory of the trial; and
the athwart speed per window of :data:`~emlogd.offline.simfaults.WINDOW_S` (those with
fewer than :data:`~emlogd.offline.simfaults.MIN_WINDOW_SAMPLES` scored readings left
out), over the whole replay and per trajectory (its windows from its first reading),
whose worst against raw and against the floor say whether the corrected VBW was ever
worse than the reading it replaced; and the forward speed per window likewise, whose
worst against the one-axis calibration's (``forward_worst_window_one_axis``) says
whether the emitted forward speed was ever worse than what ``axes: 1`` emits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from calib.models import FloatArray
from drivers import make_decoder
from drivers.nmea0183 import NmeaDecoder
from drivers.nmea0183.encoders import fmt_number
from drivers.records import KNOT_MPS, Rejected
from emlogd.offline.simfaults import MIN_WINDOW_SAMPLES, WINDOW_S
from emlogd.offline.simtruth import Truth
from emlogd.pipeline.core import Emit, Pipeline


def as_sent(v_mps: FloatArray) -> FloatArray:
    """Speeds as a VBW sentence carries them and a receiver reads them back, m/s: in
    knots to the encoder's two decimals (:func:`drivers.nmea0183.encoders.fmt_number`)."""
    kn = [float(fmt_number(x / KNOT_MPS, 2)) if math.isfinite(x) else math.nan for x in v_mps]
    return np.asarray(kn, dtype=np.float64) * KNOT_MPS


def _rms(x: FloatArray) -> float | None:
    x = x[np.isfinite(x)]
    return round(math.sqrt(float(np.mean(x * x))), 5) if x.size else None


class AthwartScorer:
    """Records the two-axis logs' VBW readings and emitted VBW, and scores them."""

    def __init__(self, pipeline: Pipeline) -> None:
        self.rows: dict[str, list[tuple[float, float, float, float, bool]]] = {}
        self.decoders: dict[str, NmeaDecoder] = {}
        self.emitted_vbw: dict[str, dict[float, tuple[float, float]]] = {}
        for name, ax in pipeline.two_axis.items():
            rows: list[tuple[float, float, float, float, bool]] = []
            self.rows[name] = rows
            ax.tap = lambda t, v, rl, rt, on, rows=rows: rows.append((t, v, rl, rt, on))
            self.decoders[name] = make_decoder("nmea0183", name, errors="skip")
            self.emitted_vbw[name] = {}

    def emitted(self, emits: Sequence[Emit]) -> None:
        """Decode the two-axis logs' corrected VBW as a receiver would."""
        for e in emits:
            dec = self.decoders.get(e.port)
            if dec is None or e.sentence[3:6] != "VBW":
                continue
            for rec in dec.feed(e.sentence.encode("ascii") + b"\r\n"):
                if isinstance(rec, Rejected):
                    continue
                for sp in dec.speed_records(rec):
                    if sp.kind == "stw" and sp.longitudinal_mps is not None:
                        tr = sp.transverse_mps if sp.transverse_mps is not None else math.nan
                        self.emitted_vbw[e.port][e.t] = (sp.longitudinal_mps, tr)

    def scores(self, truth: Truth) -> dict[str, dict[str, object]]:
        """Per two-axis log: RMSE athwart (raw, corrected, floor) and forward (the
        one-axis calibration's, the emitted, floor), m/s, over all its readings, over
        those emitted with the figures applied, and per trajectory.

        Raises:
            TruthError: a log the truth does not know, or a truth without athwart speeds.
        """
        return {name: self._score(name, truth) for name in self.rows}

    def _score(self, name: str, truth: Truth) -> dict[str, object]:
        rows = self.rows[name]
        a = np.asarray([r[:4] for r in rows], dtype=np.float64).reshape(-1, 4)
        on = np.asarray([r[4] for r in rows], dtype=bool)
        got = self.emitted_vbw[name]
        em = np.asarray([got.get(r[0], (math.nan, math.nan)) for r in rows], dtype=np.float64)
        em = em.reshape(-1, 2)
        true_params = truth.two_axis(name)
        _, latency = truth.emlog(name)
        q = a[:, 0] - latency
        u, w = truth.stw_at(q), truth.trans_at(q)
        fu, fw = true_params.correct(a[:, 2], a[:, 3])
        err = {
            "t_raw": a[:, 3] - w,
            "t_corrected": em[:, 1] - w,
            "t_floor": fw - w,
            "l_one_axis": as_sent(a[:, 1]) - u,
            "l_corrected": em[:, 0] - u,
            "l_floor": fu - u,
        }
        idx = np.clip(np.searchsorted(truth.t, q), 0, max(truth.t.size - 1, 0))
        traj = truth.trajectory[idx] if truth.t.size else np.zeros(q.size, dtype=np.int64)

        def block(sel: npt.NDArray[np.bool_]) -> dict[str, object]:
            out: dict[str, object] = {"n_samples": int(np.count_nonzero(sel & np.isfinite(w)))}
            for k, e in err.items():
                out[f"rmse_{k}"] = _rms(e[sel])
            return out

        everything = np.ones(q.size, dtype=bool)
        athwart = (err["t_raw"], err["t_corrected"], err["t_floor"])
        forward = (err["l_one_axis"], err["l_corrected"], err["l_floor"])

        def windows(sel: npt.NDArray[np.bool_]) -> dict[str, object]:
            fw = _worst_windows(*(x[sel] for x in (q, *forward)))["worst_window_raw"]
            if isinstance(fw, dict):
                fw = {_FORWARD_KEYS.get(k, k): v for k, v in fw.items()}
            return _worst_windows(*(x[sel] for x in (q, *athwart))) | {
                "forward_worst_window_one_axis": fw
            }

        return {
            **block(everything),
            "applied": block(on),
            **windows(everything),
            "by_trajectory": {
                str(int(k)): block(traj == k)
                | {"applied_share": round(float(np.mean(on[traj == k])), 3)}
                | windows(traj == k)
                for k in np.unique(traj)
            },
        }


_FORWARD_KEYS = {
    "rmse_t_raw": "rmse_l_one_axis",
    "rmse_t_corrected": "rmse_l_corrected",
    "rmse_t_floor": "rmse_l_floor",
}
"""A forward window's scores named as the forward speed's (:func:`_worst_windows`
names the athwart speed's)."""


def _worst_windows(
    t: FloatArray, e_raw: FloatArray, e_cor: FloatArray, e_floor: FloatArray
) -> dict[str, object]:
    """The athwart speed per window of :data:`WINDOW_S` from the first reading: the
    window whose emitted RMSE is furthest above raw's (``worst_window_raw``) and the one
    furthest above the floor's (``worst_window_floor``), each ``{"t0", "n_samples",
    "rmse_t_raw", "rmse_t_corrected", "rmse_t_floor", "ratio"}``, and how many windows
    were scored; None where no window has :data:`MIN_WINDOW_SAMPLES` scored readings.
    Given the forward errors (the one-axis calibration's for raw's), the same of the
    forward speed, the keys' ``raw`` then the one-axis calibration's."""
    ok = np.isfinite(e_raw) & np.isfinite(e_cor) & np.isfinite(e_floor)
    rows: list[dict[str, float | int]] = []
    if np.any(ok):
        tt, er, ec, ef = t[ok], e_raw[ok], e_cor[ok], e_floor[ok]
        idx = np.floor((tt - tt[0]) / WINDOW_S).astype(np.int64)
        for k in np.unique(idx).tolist():
            sel = idx == k
            n = int(np.count_nonzero(sel))
            if n < MIN_WINDOW_SAMPLES:
                continue
            r, c, f = (math.sqrt(float(np.mean(x[sel] * x[sel]))) for x in (er, ec, ef))
            rows.append({"t0": float(tt[0] + k * WINDOW_S), "n": n, "raw": r, "cor": c, "floor": f})

    def worst(by: str) -> dict[str, object] | None:
        scored = [w for w in rows if w[by] > 0.0]
        if not scored:
            return None
        w = max(scored, key=lambda x: x["cor"] / x[by])
        return {
            "t0": round(w["t0"], 3),
            "n_samples": w["n"],
            "rmse_t_raw": round(w["raw"], 5),
            "rmse_t_corrected": round(w["cor"], 5),
            "rmse_t_floor": round(w["floor"], 5),
            "ratio": round(w["cor"] / w[by], 4),
        }

    return {
        "windows": len(rows),
        "worst_window_raw": worst("raw"),
        "worst_window_floor": worst("floor"),
    }
