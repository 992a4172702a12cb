"""The offline commands on both axes of a log (``--axes 2``): a misaligned two-axis log
calibrated, evaluated and cross-validated against a two-axis reference.

A two-axis log sends ``$--VBW`` (forward and athwart speed through the water); its
reference is a DVL's bottom track, whose ensembles carry both horizontal axes in the
ship frame and the heading. Each capture is decoded by the drivers' own decoders
(records the decoder rejects are counted and skipped); the readings are paired with
the reference and the heading at ``t − lag`` by the alignment rule of
:mod:`emlogd.pipeline.align`, the lag being the one-axis commands' (measured on the
longitudinal axis, :func:`emlogd.offline.jobs.find_lag`, or given).

The model and its identifiability are :mod:`calib.twoaxis`'s. Accuracy is scored in
the water frame on each axis: each capture's current is fitted with the parameters
frozen (:func:`calib.twoaxis.fit_current_two_axis`, the ideal aligned sensor for the
raw readings), and the corrected forward and athwart speeds are compared with the
reference less that current.

The forward speed reported beside a one-axis calibration of the same readings (the
result's ``one_axis``) is the daemon's (:mod:`emlogd.offline.twoaxis_forward`): each
reading's by the correction of the smaller expected error, the one-axis
calibration's wherever α is refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from calib.errors import CalibrationError
from calib.models import FloatArray, Params, check_model
from calib.twoaxis import (
    TwoAxisFit,
    TwoAxisParams,
    TwoAxisSeries,
    fit_current_two_axis,
    fit_two_axis,
    leeway_deg,
    water_velocity,
)
from calib.twoaxis_kf import kf_two_axis
from drivers import make_decoder
from drivers.io.capture import CaptureReader, capture_name
from drivers.records import Rejected, SpeedRecord
from emlogd.fileio import write_atomic
from emlogd.offline.jobs import OfflineError
from emlogd.offline.simtruth import Truth
from emlogd.offline.twoaxis_forward import (
    NO_ONE_AXIS,
    ForwardRule,
    forward_speed,
    one_axis_forward,
)
from emlogd.pipeline.align import DEFAULT_MAX_GAP_S, interpolate
from emlogd.pipeline.twoaxis_learn import CURRENT_KNOT_S

TwoAxisMethod = Literal["ls", "kf"]

TWO_AXIS_KIND = "emlogd-two-axis-calibration"
"""The ``kind`` of a two-axis parameters file (``calibrate --axes 2 --save``)."""


@dataclass(frozen=True, eq=False)
class TwoAxisRecording:
    """A two-axis log's readings and its two-axis reference from one capture.

    Attributes:
        path: the capture.
        uut: the log's port.
        t_read: reading receive times, s.
        raw_l: forward readings, m/s.
        raw_t: athwart readings (+ starboard), m/s.
        t_ref: reference sample times, s.
        ref_fwd: the reference's ground speed forward, m/s (nan: invalid).
        ref_stb: its ground speed to starboard, m/s (nan: invalid).
        heading: the heading sent with the reference, degrees (nan: none).
        rejects: decoder rejects by port and reason.
    """

    path: str
    uut: str
    t_read: FloatArray
    raw_l: FloatArray
    raw_t: FloatArray
    t_ref: FloatArray
    ref_fwd: FloatArray
    ref_stb: FloatArray
    heading: FloatArray
    rejects: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The capture's file name without ``.cap``/``.gz`` (:func:`capture_name`)."""
        return capture_name(self.path)

    def aligned(self, lag_s: float, max_gap_s: float = DEFAULT_MAX_GAP_S) -> TwoAxisAligned:
        """Readings paired with the reference and heading at ``t − lag`` (the alignment
        rule of :mod:`emlogd.pipeline.align`); only the samples with all of them."""
        q = self.t_read - lag_s
        ok_f = np.isfinite(self.ref_fwd) & np.isfinite(self.ref_stb)
        fwd = interpolate(self.t_ref, self.ref_fwd, ok_f, q, max_gap_s, cadence=True)
        stb = interpolate(self.t_ref, self.ref_stb, ok_f, q, max_gap_s, cadence=True)
        hd = interpolate(
            self.t_ref,
            self.heading,
            np.isfinite(self.heading),
            q,
            max_gap_s,
            angular=True,
            cadence=True,
        )
        ok = np.isfinite(fwd) & np.isfinite(stb) & np.isfinite(hd)
        ok &= np.isfinite(self.raw_l) & np.isfinite(self.raw_t)
        return TwoAxisAligned(
            self.t_read[ok], self.raw_l[ok], self.raw_t[ok], fwd[ok], stb[ok], hd[ok]
        )


@dataclass(frozen=True, eq=False)
class TwoAxisAligned:
    """Aligned two-axis samples (all finite)."""

    t: FloatArray
    raw_l: FloatArray
    raw_t: FloatArray
    ref_fwd: FloatArray
    ref_stb: FloatArray
    heading: FloatArray

    def __len__(self) -> int:
        return int(self.t.size)

    def series(self) -> TwoAxisSeries:
        """The series :func:`calib.twoaxis.fit_two_axis` and its kin take.

        Raises:
            DataError: no samples, or a value that is not finite.
        """
        return TwoAxisSeries.of(self.ref_fwd, self.ref_stb, self.raw_l, self.raw_t, self.heading)


def record_two_axis(path: str | Path, uut: str, reference: str) -> TwoAxisRecording:
    """Decode one capture: the log's VBW water pair and the DVL's bottom track.

    Args:
        path: capture v1 file.
        uut: the log's port (its VBW sentences give both axes).
        reference: the DVL's port (bottom track in the ship frame, with its heading).

    Raises:
        OfflineError: the capture lacks a port, or the log sends no two-axis speed.
    """
    reader = CaptureReader(path, errors="skip")
    missing = [p for p in (uut, reference) if p not in reader.ports]
    if missing:
        raise OfflineError(
            f"{path}: no port {', '.join(missing)} (has {', '.join(reader.ports) or 'none'})"
        )
    decoders = {p: make_decoder(reader.ports[p], p, errors="skip") for p in (uut, reference)}
    read: list[tuple[float, float, float]] = []
    ref: list[tuple[float, float, float, float]] = []
    t_last = 0.0
    for t, port, data, _ in reader.received():
        dec = decoders.get(port)
        if dec is None:
            continue
        t_last = t
        for rec in dec.feed(data):
            if not isinstance(rec, Rejected):
                for sp in dec.speed_records(rec):
                    _take(sp, t, uut, reference, read, ref)
    for dec in decoders.values():
        for rec in dec.flush():
            if not isinstance(rec, Rejected):
                for sp in dec.speed_records(rec):
                    _take(sp, t_last, uut, reference, read, ref)
    if not read:
        raise OfflineError(f"{path}: {uut} sends no VBW with a transverse speed through the water")
    r = np.asarray(read, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(ref, dtype=np.float64).reshape(-1, 4)
    order_r, order_f = np.argsort(r[:, 0], kind="stable"), np.argsort(f[:, 0], kind="stable")
    r, f = r[order_r], f[order_f]
    return TwoAxisRecording(
        str(path),
        uut,
        r[:, 0],
        r[:, 1],
        r[:, 2],
        f[:, 0],
        f[:, 1],
        f[:, 2],
        f[:, 3],
        {p: {str(k): v for k, v in d.counters.rejects.items()} for p, d in decoders.items()},
    )


def _take(
    sp: SpeedRecord,
    t: float,
    uut: str,
    reference: str,
    read: list[tuple[float, float, float]],
    ref: list[tuple[float, float, float, float]],
) -> None:
    if sp.port == uut and sp.source == "VBW" and sp.kind == "stw":
        if sp.valid and sp.longitudinal_mps is not None and sp.transverse_mps is not None:
            read.append((t, sp.longitudinal_mps, sp.transverse_mps))
    elif sp.port == reference and sp.role == "bottom":
        ok = sp.valid and sp.longitudinal_mps is not None and sp.transverse_mps is not None
        hd = sp.heading_true_deg if sp.heading_true_deg is not None else math.nan
        if ok:
            assert sp.longitudinal_mps is not None and sp.transverse_mps is not None
            ref.append((t, sp.longitudinal_mps, sp.transverse_mps, hd))
        else:
            ref.append((t, math.nan, math.nan, hd))


def _concat(pairs: Sequence[TwoAxisAligned]) -> TwoAxisAligned:
    return TwoAxisAligned(
        *(np.concatenate([getattr(p, k) for p in pairs]) for k in TwoAxisAligned.__annotations__)
    )


@dataclass(frozen=True, slots=True)
class AxisScores:
    """RMSE per axis in the water frame, raw and corrected, of one set of samples.

    Attributes:
        n_samples: samples scored.
        rmse_l_raw: forward, the raw reading, m/s.
        rmse_l_cal: forward, corrected (:func:`~emlogd.offline.twoaxis_forward.
            forward_speed`), m/s.
        rmse_t_raw: athwart, the raw reading, m/s.
        rmse_t_cal: athwart, corrected, m/s.
        leeway_rms_deg: RMS of the corrected leeway angle, degrees.
        rmse_l_one_axis: forward, the one-axis calibration's, m/s (nan: none known).
    """

    n_samples: int
    rmse_l_raw: float
    rmse_l_cal: float
    rmse_t_raw: float
    rmse_t_cal: float
    leeway_rms_deg: float
    rmse_l_one_axis: float = math.nan

    def to_dict(self) -> dict[str, object]:
        """Plain types for JSON."""
        return {
            "n_samples": self.n_samples,
            "rmse_l_raw": _fin(self.rmse_l_raw),
            "rmse_l_cal": _fin(self.rmse_l_cal),
            "rmse_t_raw": _fin(self.rmse_t_raw),
            "rmse_t_cal": _fin(self.rmse_t_cal),
            "leeway_rms_deg": _fin(self.leeway_rms_deg),
            "rmse_l_one_axis": _fin(self.rmse_l_one_axis),
        }


def _fin(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else x


def _rms(x: FloatArray) -> float:
    x = x[np.isfinite(x)]
    return math.sqrt(float(np.mean(x * x))) if x.size else math.nan


def score(params: TwoAxisParams, a: TwoAxisAligned, rule: ForwardRule = NO_ONE_AXIS) -> AxisScores:
    """RMSE per axis of the raw and the corrected readings (the forward speed by
    ``rule``; the one-axis calibration's scored too where it has one) against the reference less
    the capture's current, fitted for each calibration (the raw reading's for the
    ideal sensor) linear between knots :data:`CURRENT_KNOT_S` apart
    (:func:`calib.twoaxis.fit_current_two_axis`). On a steady heading at a steady
    speed that current takes each axis's offset, the misalignment's ``sin α·u``
    included, for the raw reading and the calibration alike: there they score alike
    and only a truth (:func:`truth_scores`) tells them apart."""
    n = len(a)
    if n == 0:
        return AxisScores(0, math.nan, math.nan, math.nan, math.nan, math.nan)
    ideal = TwoAxisParams(Params(params.model))
    fwd = forward_speed(a.t, a.raw_l, a.raw_t, params, rule)
    one = (
        None if rule.one_axis is None else one_axis_forward(a.raw_l, a.raw_t, params, rule.one_axis)
    )
    out: list[float] = []
    for p in (ideal, params):
        cur = fit_current_two_axis(
            p,
            a.series(),
            t_s=a.t,
            current_knot_s=CURRENT_KNOT_S,
        )
        u, w = water_velocity(a.ref_fwd, a.ref_stb, a.heading, cur)
        cu, cw = p.correct(a.raw_l, a.raw_t)
        out += [_rms((fwd if p is params else cu) - u), _rms(cw - w)]
    one_rmse = _rms(one - u) if one is not None else math.nan
    lee = leeway_deg(fwd, params.correct(a.raw_l, a.raw_t)[1])
    return AxisScores(n, out[0], out[2], out[1], out[3], _rms(lee), one_rmse)


@dataclass(frozen=True, slots=True)
class TwoAxisResult:
    """A two-axis calibration from captures (``calibrate --axes 2``)."""

    fit: TwoAxisFit
    uut: str
    reference: str
    lag_s: float
    lag_source: str
    captures: tuple[str, ...]
    scores: AxisScores
    rule: ForwardRule = NO_ONE_AXIS
    """Whose forward speed is reported, with the one-axis calibration beside."""

    def to_dict(self) -> dict[str, object]:
        """JSON keys (README: ``calibrate --axes 2 --json``)."""
        return {
            "axes": 2,
            "uut": self.uut,
            "reference": self.reference,
            "captures": list(self.captures),
            "lag_s": self.lag_s,
            "lag_source": self.lag_source,
            **self.fit.to_dict(),
            **self.rule.to_dict(),
            "scores": self.scores.to_dict(),
        }


def forward_rule(fit: TwoAxisFit, one_axis: Params | None) -> ForwardRule:
    """The forward rule of a fit beside the one-axis calibration ``one_axis``: α's
    refusal, with its reason, where the fit did not determine it."""
    if "alpha" not in fit.ident.unidentifiable:
        return ForwardRule(one_axis)
    return ForwardRule(one_axis, fit.ident.verdict("alpha").reason or "misalignment refused")


def calibrate_two_axis(
    recs: Sequence[TwoAxisRecording],
    model: str,
    method: TwoAxisMethod,
    lag_s: float,
    *,
    lag_source: str = "given",
    reference: str = "dvl",
    one_axis: Params | None = None,
) -> TwoAxisResult:
    """Fit the two-axis model on every capture together (least squares: a current per
    current linear between knots :data:`CURRENT_KNOT_S` apart; the filter: a current
    that wanders); ``one_axis`` the one-axis calibration of the same forward readings,
    kept beside it and weighed against it for the forward speed (:func:`forward_rule`).

    Raises:
        OfflineError: no aligned sample, a bad method or model.
    """
    if method not in ("ls", "kf"):
        raise OfflineError(f"method must be ls or kf, not {method!r}")
    try:
        name = check_model(model)
    except CalibrationError as exc:
        raise OfflineError(str(exc)) from None
    pairs = [r.aligned(lag_s) for r in recs]
    a = _concat(pairs)
    if len(a) == 0:
        raise OfflineError(
            "no reading has a reference and a heading within the alignment gap at "
            f"lag {lag_s:.2f} s"
        )
    if method == "ls":
        fit = fit_two_axis(
            name,
            a.series(),
            t_s=a.t,
            current_knot_s=CURRENT_KNOT_S,
        )
    else:
        fit = kf_two_axis(
            name,
            a.t,
            a.series(),
            current_knot_s=CURRENT_KNOT_S,
        )
    rule = forward_rule(fit, one_axis)
    scores = score(fit.params, a, rule)
    return TwoAxisResult(
        fit,
        recs[0].uut if recs else "",
        reference,
        lag_s,
        lag_source,
        tuple(r.path for r in recs),
        scores,
        rule,
    )


@dataclass(frozen=True, slots=True)
class TwoAxisRow:
    """Frozen two-axis parameters applied to one capture."""

    capture: str
    scores: AxisScores

    def to_dict(self) -> dict[str, object]:
        """JSON keys (README: ``evaluate --axes 2 --json``)."""
        return {"capture": self.capture, **self.scores.to_dict()}


def evaluate_two_axis(
    recs: Sequence[TwoAxisRecording],
    params: TwoAxisParams,
    lag_s: float,
    rule: ForwardRule = NO_ONE_AXIS,
) -> list[TwoAxisRow]:
    """RMSE per axis, raw and corrected (the forward speed by ``rule``), per capture."""
    return [TwoAxisRow(r.path, score(params, r.aligned(lag_s), rule)) for r in recs]


@dataclass(frozen=True, slots=True)
class CrossRow:
    """Trained on one capture, evaluated on another."""

    train: str
    test: str
    misalign_deg: float
    misalign_std_deg: float | None
    reason: str
    scores: AxisScores

    def to_dict(self) -> dict[str, object]:
        """JSON keys (README: ``crossval --axes 2 --json``)."""
        return {
            "train": self.train,
            "test": self.test,
            "misalign_deg": self.misalign_deg,
            "misalign_std_deg": _fin(self.misalign_std_deg),
            "reason": self.reason,
            **self.scores.to_dict(),
        }


def crossval_two_axis(
    recs: Sequence[TwoAxisRecording],
    model: str,
    lag_s: float,
    one_axis: Sequence[Params | None] | None = None,
) -> list[CrossRow]:
    """Least squares trained on each capture, evaluated on every other; ``one_axis``
    the one-axis calibration trained on each capture (None where there is none), the
    forward speed weighed against it (:func:`forward_rule`).

    Raises:
        OfflineError: fewer than two captures.
    """
    if len(recs) < 2:
        raise OfflineError("cross-validation needs at least two captures")
    name = check_model(model)
    pairs = [r.aligned(lag_s) for r in recs]
    rows = []
    for i, tr in enumerate(pairs):
        if len(tr) == 0:
            continue
        fit = fit_two_axis(
            name,
            tr.series(),
            t_s=tr.t,
            current_knot_s=CURRENT_KNOT_S,
        )
        rule = forward_rule(fit, one_axis[i] if one_axis is not None else None)
        for j, te in enumerate(pairs):
            if j != i:
                rows.append(
                    CrossRow(
                        recs[i].name,
                        recs[j].name,
                        fit.misalign_deg,
                        fit.misalign_std_deg,
                        fit.ident.reason,
                        score(fit.params, te, rule),
                    )
                )
    return rows


def save_two_axis(path: str | Path, result: TwoAxisResult) -> None:
    """Write a two-axis calibration file (YAML, atomic)."""
    doc = {"kind": TWO_AXIS_KIND, "version": 1, **result.to_dict()}
    write_atomic(Path(path), yaml.safe_dump(doc, sort_keys=False).encode("utf-8"))


def load_two_axis(path: str | Path) -> tuple[TwoAxisParams, dict[str, Any]]:
    """Read a file written by :func:`save_two_axis`: the parameters, validated
    (a model, finite values, a misalignment within ±20°), and the document.

    Raises:
        OfflineError: unreadable, another kind, or parameters refused (names the file).
    """
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise OfflineError(f"{path}: cannot read the two-axis calibration file: {exc}") from None
    if not isinstance(doc, dict) or doc.get("kind") != TWO_AXIS_KIND:
        raise OfflineError(f"{path}: not a two-axis calibration file (kind {TWO_AXIS_KIND})")
    try:
        p = doc["params"]
        model = check_model(str(doc["model"]))
        lon = Params(
            model,
            float(p.get("a", 0.0)),
            float(p.get("m", 0.0)),
            float(p.get("b", 0.0)),
        )
        params = TwoAxisParams(
            lon,
            math.radians(float(p["misalign_deg"])),
            float(p["m_t"]),
            float(p["b_t"]),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise OfflineError(f"{path}: bad two-axis parameters: {exc}") from None
    return params, doc


def rule_of(doc: dict[str, Any], path: str | Path = "") -> ForwardRule:
    """The forward rule a two-axis calibration file states: its ``one_axis``
    calibration (None in a file written without it) and α's refusal.

    Raises:
        OfflineError: a ``one_axis`` that is not a calibration (names the file).
    """
    one = doc.get("one_axis")
    params = None
    if one is not None:
        try:
            params = Params(
                check_model(str(one["model"])),
                float(one.get("a", 0.0)),
                float(one.get("m", 0.0)),
                float(one.get("b", 0.0)),
            )
        except (KeyError, TypeError, ValueError, AttributeError, CalibrationError) as exc:
            raise OfflineError(f"{path}: bad one-axis calibration: {exc}") from None
    refused = "alpha" in (doc.get("unidentifiable") or [])
    return ForwardRule(params, str(doc.get("reason") or "misalignment refused") if refused else "")


@dataclass(frozen=True, slots=True)
class TruthAxisScores:
    """Readings of one capture scored against a simulated trial's truth, per axis.

    Attributes:
        n_samples: samples scored.
        rmse_l_raw: forward, raw, m/s.
        rmse_l_cal: forward, corrected, m/s.
        rmse_l_floor: forward, corrected with the true parameters (the noise), m/s.
        rmse_t_raw: athwart, raw, m/s.
        rmse_t_cal: athwart, corrected, m/s.
        rmse_t_floor: athwart, corrected with the true parameters, m/s.
        rmse_l_one_axis: forward, the one-axis calibration's, m/s (nan: none known).
    """

    n_samples: int
    rmse_l_raw: float
    rmse_l_cal: float
    rmse_l_floor: float
    rmse_t_raw: float
    rmse_t_cal: float
    rmse_t_floor: float
    rmse_l_one_axis: float = math.nan

    def to_dict(self) -> dict[str, object]:
        """Plain types for JSON (README: ``evaluate --axes 2 --truth``)."""
        out: dict[str, object] = {"n_samples": self.n_samples}
        for k in self.__slots__:
            if k != "n_samples":
                out[k] = _fin(getattr(self, k))
        return out


def truth_scores(
    rec: TwoAxisRecording,
    params: TwoAxisParams,
    truth: Truth,
    lag_s: float,
    rule: ForwardRule = NO_ONE_AXIS,
) -> TruthAxisScores:
    """Raw, corrected (the forward speed by ``rule``; the one-axis calibration's too
    where it has one) and true-parameter corrected readings of ``rec`` against the
    truth's speed through the water along and athwart the hull at the reading's time
    less the sensor's true latency.

    Raises:
        TruthError: the truth has no athwart speed or no such EMlog.
    """
    true_params = truth.two_axis(rec.uut)
    _, latency = truth.emlog(rec.uut)
    a = rec.aligned(lag_s)
    q = a.t - latency
    u, w = truth.stw_at(q), truth.trans_at(q)
    ok = np.isfinite(u) & np.isfinite(w)
    # the choice weighs the readings of the last CHOICE_S before each: made on every reading
    cu_all = forward_speed(a.t, a.raw_l, a.raw_t, params, rule)
    rl, rt, cu = a.raw_l[ok], a.raw_t[ok], cu_all[ok]
    u, w = u[ok], w[ok]
    cw = params.correct(rl, rt)[1]
    fu, fw = true_params.correct(rl, rt)
    one = None if rule.one_axis is None else one_axis_forward(rl, rt, params, rule.one_axis)
    return TruthAxisScores(
        int(ok.sum()),
        _rms(rl - u),
        _rms(cu - u),
        _rms(fu - u),
        _rms(rt - w),
        _rms(cw - w),
        _rms(fw - w),
        _rms(one - u) if one is not None else math.nan,
    )
