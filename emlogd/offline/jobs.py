"""Offline calibration on captures: calibrate, evaluate, cross-validate.

The offline commands pair a unit under test (an EMlog port) with a reference (the
DVL's bottom or water track, or another EMlog) from capture files
(:mod:`emlogd.offline.dataset`), estimate the UUT's latency by cross-correlation, and hand
lag-aligned arrays to :mod:`calib`. The result objects carry the stable JSON views
documented in the README.

Parameters files (``--save PARAMS.yaml``) are YAML with a schema version; they
record the model, the parameters and their standard errors, and the pairing
(UUT, reference, lag) so that ``evaluate`` can apply them without repeating it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml

from calib.crossval import ESTIMATORS, CrossValResult, Segment, cross_validate
from calib.errors import CalibrationError
from calib.excitation import identifiability
from calib.kalman import KfConfig, run_kf
from calib.lag import LagEstimate, estimate_lag
from calib.lsq import fit_ls
from calib.metrics import improvement_pct, nis_stats, rmse
from calib.models import PARAM_NAMES, Layout, Params, check_model, correct_array
from drivers.errors import EmlogdError
from emlogd.offline.dataset import (
    AlignedPair,
    CaptureData,
    Component,
    ReferenceField,
    align,
    load_capture,
)

Method = Literal["ls", "kf"]
ProgressFn = Callable[[str, float], None]

PARAMS_SCHEMA = 1
DEFAULT_MAX_LAG_S = 10.0
"""Lag search range ±s: the paper's EMlogs lag 3.2 s and 0.45 s."""

MIN_LAG_CORRELATION = 0.6
"""A per-capture lag estimate with a weaker peak correlation is not trusted (a straight
run at constant speed correlates at ~0.4 wherever the lag is)."""


class OfflineError(EmlogdError):
    """An offline job cannot run on these captures (the message says why)."""


@dataclass(frozen=True, slots=True)
class Pairing:
    """Which series is calibrated against which.

    Attributes:
        uut: the EMlog port to calibrate.
        ref: the reference port.
        ref_field: ``bottom`` (DVL bottom track), ``water`` (DVL :WS) or ``speed``
            (another EMlog's VHW/VBW: relative calibration).
        uut_source: the UUT sentence (``VHW`` or ``VBW``; default VHW, else VBW).
        component: ``longitudinal`` (default: an EMlog measures along the hull) or
            ``magnitude``.
    """

    uut: str
    ref: str
    ref_field: ReferenceField = "bottom"
    uut_source: str | None = None
    component: Component = "longitudinal"

    def __post_init__(self) -> None:
        if self.uut == self.ref and self.ref_field == "speed":
            raise OfflineError("the UUT and the reference must differ")

    def as_dict(self) -> dict[str, object]:
        """Plain types."""
        return {
            "uut": self.uut,
            "ref": self.ref,
            "ref_field": self.ref_field,
            "uut_source": self.uut_source,
            "component": self.component,
        }


def load_captures(
    paths: Sequence[str | Path], pairing: Pairing, progress: ProgressFn | None = None
) -> list[CaptureData]:
    """Decode the two ports of ``pairing`` from each capture.

    Raises:
        OfflineError: a capture lacks one of the ports.
        CaptureFormatError: a malformed capture (names file and line).
    """
    out = []
    for i, p in enumerate(paths):
        if progress is not None:
            progress(f"reading {Path(p).name}", i / max(len(paths), 1))
        try:
            out.append(load_capture(p, {pairing.uut, pairing.ref}))
        except KeyError as exc:
            raise OfflineError(str(exc.args[0])) from None
    return out


def _series(data: CaptureData, pairing: Pairing) -> tuple[Any, Any]:
    try:
        uut = data.uut_series(pairing.uut, pairing.uut_source)
        ref = data.reference_series(pairing.ref, pairing.ref_field)
    except KeyError as exc:
        raise OfflineError(str(exc.args[0])) from None
    return uut, ref


@dataclass(frozen=True, slots=True)
class LagReport:
    """The lag used, and how it was found.

    Attributes:
        lag_s: the UUT latency applied, s (positive: the UUT reports late).
        source: ``auto`` (estimated), ``given``, or ``fallback`` (no capture gave a
            trusted estimate: 0 s is used and ``note`` says why).
        per_capture: capture name -> estimate (auto and fallback).
        note: why the fallback was used.
    """

    lag_s: float
    source: Literal["auto", "given", "fallback"]
    per_capture: dict[str, LagEstimate] = field(default_factory=dict)
    note: str = ""

    def as_dict(self) -> dict[str, object]:
        """Plain types."""
        return {
            "lag_s": self.lag_s,
            "source": self.source,
            "note": self.note,
            "per_capture": {
                k: {"lag_s": e.lag_s, "peak_corr": e.peak_corr, "at_bound": e.at_bound}
                for k, e in self.per_capture.items()
            },
        }


def find_lag(
    datas: Sequence[CaptureData],
    pairing: Pairing,
    lag: float | None,
    *,
    max_lag_s: float = DEFAULT_MAX_LAG_S,
) -> LagReport:
    """The UUT latency: ``lag`` if given, else estimated per capture and combined.

    The combined estimate is the median of the trusted per-capture estimates (robust
    to one capture whose correlation peak is shifted, e.g. by a current rotating with
    the heading in circles) (peak correlation ≥ :data:`MIN_LAG_CORRELATION`, not at the search bound).
    Without any, the lag is 0 s and the report's ``source`` is ``fallback``.

    Raises:
        OfflineError: ``lag`` is not finite.
    """
    if lag is not None:
        if not math.isfinite(lag):
            raise OfflineError("lag must be a finite number of seconds")
        return LagReport(float(lag), "given")
    per: dict[str, LagEstimate] = {}
    for d in datas:
        uut, ref = _series(d, pairing)
        uu, ru = uut.usable(pairing.component), ref.usable(pairing.component)
        try:
            per[d.name] = estimate_lag(
                uut.t[uu],
                uut.values(pairing.component)[uu],
                ref.t[ru],
                ref.values(pairing.component)[ru],
                max_lag_s,
                step_s=0.1,
            )
        except CalibrationError:
            continue
    good = [e for e in per.values() if e.peak_corr >= MIN_LAG_CORRELATION and not e.at_bound]
    if not good:
        return LagReport(
            0.0,
            "fallback",
            per,
            f"no capture shows a clear correlation peak (r ≥ {MIN_LAG_CORRELATION}) within "
            f"±{max_lag_s:g} s: lag 0 s used; pass --lag SECONDS",
        )
    lag_s = float(np.median([e.lag_s for e in good]))
    return LagReport(lag_s, "auto", per)


def aligned(datas: Sequence[CaptureData], pairing: Pairing, lag_s: float) -> list[AlignedPair]:
    """One lag-aligned pair per capture (reference outages left out)."""
    out = []
    for d in datas:
        uut, ref = _series(d, pairing)
        out.append(align(uut, ref, lag_s, component=pairing.component))
    return out


def _concat(pairs: Sequence[AlignedPair]) -> tuple[np.ndarray[Any, Any], ...]:
    t = np.concatenate([p.t for p in pairs]) if pairs else np.empty(0)
    raw = np.concatenate([p.raw for p in pairs]) if pairs else np.empty(0)
    ref = np.concatenate([p.ref for p in pairs]) if pairs else np.empty(0)
    return t, raw, ref


def _fin(x: float) -> float | None:
    return x if math.isfinite(x) else None


@dataclass(frozen=True, slots=True)
class CalibrationResult:
    """What ``emlogd calibrate`` found (JSON keys: :meth:`to_dict`)."""

    captures: tuple[str, ...]
    pairing: Pairing
    method: Method
    params: Params
    stderr: dict[str, float]
    lag: LagReport
    n_samples: int
    rmse_raw: float
    rmse_cal: float
    identifiable: bool
    reason: str
    condition_number: float
    nis_mean: float | None = None
    nis_frac_inside: float | None = None

    @property
    def improvement_pct(self) -> float:
        """Improvement of the calibrated RMSE over the raw one, %."""
        return improvement_pct(self.rmse_raw, self.rmse_cal)

    def to_dict(self) -> dict[str, object]:
        """The stable JSON document (README: ``calibrate --json``)."""
        return {
            "model": self.params.model,
            "method": self.method,
            "params": self.params.as_dict(),
            "stderr": {k: _fin(v) for k, v in self.stderr.items()},
            "lag_s": self.lag.lag_s,
            "lag": self.lag.as_dict(),
            "rmse_raw": _fin(self.rmse_raw),
            "rmse_cal": _fin(self.rmse_cal),
            "improvement_pct": _fin(self.improvement_pct),
            "identifiable": self.identifiable,
            "reason": self.reason,
            "condition_number": _fin(self.condition_number),
            "n_samples": self.n_samples,
            "nis_mean": self.nis_mean,
            "nis_frac_inside": self.nis_frac_inside,
            "uut": self.pairing.uut,
            "ref": self.pairing.ref,
            "ref_field": self.pairing.ref_field,
            "captures": list(self.captures),
        }


def calibrate(
    datas: Sequence[CaptureData],
    pairing: Pairing,
    model: str,
    method: Method,
    *,
    lag: float | None = None,
    kf_config: KfConfig | None = None,
) -> CalibrationResult:
    """Estimate ``model`` of the UUT from every capture together.

    LS fits all aligned samples at once; KF runs the filter through the captures in
    order (continuing its state) and reports the final estimate with σ from P.
    ``identifiable`` and the condition number come from the excitation of the
    aligned reference speeds (:func:`calib.excitation.excitation`).

    Raises:
        OfflineError: no aligned samples.
    """
    if method not in ("ls", "kf"):
        raise OfflineError(f"method must be ls or kf, not {method!r}")
    lag_report = find_lag(datas, pairing, lag)
    pairs = aligned(datas, pairing, lag_report.lag_s)
    t, raw, ref = _concat(pairs)
    if raw.size == 0:
        raise OfflineError(
            f"no {pairing.uut} sample has a valid {pairing.ref} reference at lag "
            f"{lag_report.lag_s:.2f} s"
        )
    names = tuple(d.path for d in datas)
    kfc = kf_config if kf_config is not None else KfConfig()
    exc = identifiability(Layout(check_model(model)), ref, raw, kfc.r_raw_mps2 + kfc.r_ref_mps2)
    nis_mean = nis_frac = None
    if method == "ls":
        fit = fit_ls(model, ref, raw)
        params = fit.params
        stderr = {k: (math.inf if v is None else v) for k, v in fit.stderr.items()}
    else:
        run = run_kf(model, t, raw, ref, kf_config, history=False)
        params = run.params
        stderr = dict(run.param_std)
        stats = nis_stats(run.nis[np.isfinite(run.nis)])
        nis_mean, nis_frac = stats.mean, stats.frac_inside
    cal = correct_array(params, raw)
    return CalibrationResult(
        captures=names,
        pairing=pairing,
        method=method,
        params=params,
        stderr=stderr,
        lag=lag_report,
        n_samples=int(raw.size),
        rmse_raw=rmse(ref, raw),
        rmse_cal=rmse(ref, cal),
        identifiable=exc.identifiable,
        reason=exc.reason,
        condition_number=exc.cond_info,
        nis_mean=nis_mean,
        nis_frac_inside=nis_frac,
    )


# ------------------------------------------------------------------ parameters files


@dataclass(frozen=True, slots=True)
class ParamsFile:
    """A saved calibration: parameters plus the pairing and lag they assume."""

    params: Params
    stderr: dict[str, float]
    pairing: Pairing
    lag_s: float
    method: str
    identifiable: bool
    trained_on: tuple[str, ...]


def save_params(path: str | Path, result: CalibrationResult) -> None:
    """Write ``result`` as a parameters file (atomic: temp file, fsync, rename)."""
    doc = {
        "schema": PARAMS_SCHEMA,
        "kind": "emlogd-params",
        "model": result.params.model,
        "params": result.params.as_dict(),
        "stderr": {k: _fin(v) for k, v in result.stderr.items()},
        "method": result.method,
        "lag_s": result.lag.lag_s,
        "identifiable": result.identifiable,
        "pairing": result.pairing.as_dict(),
        "trained_on": list(result.captures),
        "rmse_raw": _fin(result.rmse_raw),
        "rmse_cal": _fin(result.rmse_cal),
    }
    p = Path(path)
    tmp = p.with_name(f".{p.name}.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write("# emlogd calibration parameters (emlogd calibrate --save)\n")
        yaml.safe_dump(doc, f, sort_keys=False)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(p)


def load_params(path: str | Path) -> ParamsFile:
    """Read a parameters file.

    Raises:
        OfflineError: unreadable, wrong schema or malformed (the message names the file).
    """
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise OfflineError(f"{path}: cannot read parameters: {exc}") from None
    if not isinstance(doc, dict) or doc.get("kind") != "emlogd-params":
        raise OfflineError(f"{path}: not an emlogd parameters file")
    if doc.get("schema") != PARAMS_SCHEMA:
        raise OfflineError(
            f"{path}: schema {doc.get('schema')!r}, this emlogd reads {PARAMS_SCHEMA}"
        )
    try:
        model = str(doc["model"])
        values = doc["params"]
        theta = [float(values[name]) for name in PARAM_NAMES[check_model(model)]]
        params = Params.from_theta(model, theta)
        pr = doc["pairing"]
        pairing = Pairing(
            str(pr["uut"]),
            str(pr["ref"]),
            pr.get("ref_field", "bottom"),
            pr.get("uut_source"),
            pr.get("component", "longitudinal"),
        )
        stderr = {
            str(k): (math.inf if v is None else float(v))
            for k, v in (doc.get("stderr") or {}).items()
        }
        return ParamsFile(
            params,
            stderr,
            pairing,
            float(doc["lag_s"]),
            str(doc.get("method", "")),
            bool(doc.get("identifiable", False)),
            tuple(doc.get("trained_on") or ()),
        )
    except (KeyError, TypeError, ValueError, AttributeError, CalibrationError) as exc:
        raise OfflineError(f"{path}: malformed parameters file: {exc!r}") from None


# ------------------------------------------------------------------ evaluate


@dataclass(frozen=True, slots=True)
class EvaluationRow:
    """Frozen parameters applied to one capture."""

    capture: str
    n_samples: int
    rmse_raw: float
    rmse_cal: float

    @property
    def improvement_pct(self) -> float:
        """Improvement %, calibrated vs raw."""
        return improvement_pct(self.rmse_raw, self.rmse_cal)

    def to_dict(self) -> dict[str, object]:
        """Stable JSON keys (README: ``evaluate --json``)."""
        return {
            "capture": self.capture,
            "n_samples": self.n_samples,
            "rmse_raw": _fin(self.rmse_raw),
            "rmse_cal": _fin(self.rmse_cal),
            "improvement_pct": _fin(self.improvement_pct),
        }


def evaluate(
    datas: Sequence[CaptureData], params: Params, pairing: Pairing, lag_s: float
) -> list[EvaluationRow]:
    """RMSE raw and calibrated per capture, with frozen ``params``."""
    rows = []
    for d, pair in zip(datas, aligned(datas, pairing, lag_s), strict=True):
        if len(pair) == 0:
            rows.append(EvaluationRow(d.path, 0, math.nan, math.nan))
            continue
        cal = correct_array(params, pair.raw)
        rows.append(EvaluationRow(d.path, len(pair), rmse(pair.ref, pair.raw), rmse(pair.ref, cal)))
    return rows


# ------------------------------------------------------------------ cross-validation


def crossval(
    datas: Sequence[CaptureData],
    pairing: Pairing,
    *,
    lag: float | None = None,
    estimators: Sequence[str] = ESTIMATORS,
    kf_config: KfConfig | None = None,
    workers: int | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> tuple[CrossValResult, LagReport]:
    """Every estimator trained on every capture, evaluated on every other one.

    Segments are named after the captures (file stem). ``workers`` defaults to the
    CPU count when there is enough work to pay for the processes.

    Raises:
        OfflineError: fewer than two captures or duplicate names.
    """
    if len(datas) < 2:
        raise OfflineError("cross-validation needs at least two captures")
    lag_report = find_lag(datas, pairing, lag)
    pairs = aligned(datas, pairing, lag_report.lag_s)
    segs = [Segment(d.name, p.t, p.raw, p.ref) for d, p in zip(datas, pairs, strict=True)]
    if len({s.name for s in segs}) != len(segs):
        raise OfflineError("captures must have distinct file names (they name the segments)")
    n = sum(len(p) for p in pairs)
    if workers is None:
        workers = min(os.cpu_count() or 1, 4) if n > 20_000 else 1
    result = cross_validate(
        segs, estimators, kf_config=kf_config, progress=progress, workers=workers
    )
    return result, lag_report
