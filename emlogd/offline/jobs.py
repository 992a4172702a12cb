"""Offline calibration on captures: calibrate, evaluate, cross-validate.

A job names one UUT and its reference with the daemon's own settings
(:class:`~emlogd.pipeline.settings.UutSettings`: model, reference port and field,
current states, heading source...), reads the captures as the daemon would
(:mod:`emlogd.offline.dataset`), finds the lag with :mod:`calib.lag`'s one rule, and
fits:

- ``ls``: batch least squares over every aligned sample the daemon's learner learns
  from (:func:`calib.lsq.fit_ls`, with the current when asked; not a stalled reading,
  far below the reference at speed, nor a reference below ``min_ref_speed_mps``),
  estimating only what the data determine;
- ``kf``: the daemon's own online calibration (:mod:`emlogd.offline.online`)
  fed the recorded samples in order — so ``emlogd calibrate --method kf`` and
  ``emlogd replay`` give the same estimate for the same lag where neither the
  supervisor's change detector alarms nor the run leaves an unknown undetermined.
  Offline it estimates one model over the recordings, as least squares does: a change
  the supervisor saw does not re-open the learner (the daemon's does, so that what it
  offers next rests on readings after the change; on GNSS most such alarms are raised
  by the sea), and an unknown the whole run does not determine is reported at its
  prior, the others conditioned on it (:meth:`calib.kalman.KfCalibrator.condition`).

Whichever the method, the verdict on every unknown comes from the identifiability
rule over all aligned samples (:func:`calib.excitation.identifiability`). Results carry
the stable JSON views documented in the README; ``--save`` writes a calibration file
(:mod:`emlogd.calfile`), the format the daemon's state file uses too.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from calib.crossval import ESTIMATORS, CrossValResult, Segment, cross_validate
from calib.errors import CalibrationError
from calib.estimate import Estimate, Estimated
from calib.excitation import Identifiability, identifiability
from calib.kalman import KfConfig
from calib.lag import (
    LAG_FALLBACK_S,
    LagEstimate,
    accept,
    combine,
    estimate_lag,
)
from calib.lsq import fit_ls
from calib.metrics import (
    CURRENT_WINDOW_S,
    ImoVerdict,
    improvement_pct,
    nis_stats,
    water_imo,
    water_scores,
    water_targets,
)
from calib.models import (
    FloatArray,
    Layout,
    Params,
    check_model,
    correct_array,
    zero_params,
)
from drivers.errors import EmlogdError
from drivers.io.capture import REORDER_WINDOW_S
from emlogd.calfile import CalibrationFileError, dumps, loads
from emlogd.fileio import write_atomic
from emlogd.offline import ProgressFn
from emlogd.offline.dataset import (
    Aligned,
    CaptureContentError,
    Recording,
    block_means,
    concat_usable,
    record_captures,
)
from emlogd.offline.headings import heading_refusal, needs_heading, why_no_sample
from emlogd.offline.online import TraceWriter, run_online
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.integrity import STALL_FRACTION, UutHealth
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import AVERAGE_S

Method = Literal["ls", "kf"]

DEFAULT_MAX_LAG_S = 10.0
"""Lag search range ±s: the paper's EMlogs lag 3.2 s and 0.45 s."""


class OfflineError(EmlogdError):
    """An offline job cannot run on these captures (the message says why)."""


def load_captures(
    paths: Sequence[str | Path],
    settings: UutSettings,
    progress: ProgressFn | None = None,
    *,
    workers: int | None = None,
    strict: bool = False,
    reorder_window_s: float = REORDER_WINDOW_S,
) -> list[Recording]:
    """Read the UUT's inputs from each capture (in parallel when there are several).

    Malformed records are counted and skipped (``Recording.skips``), or raise with
    ``strict``; records up to ``reorder_window_s`` out of time order are put back in
    order.

    Raises:
        OfflineError: a capture lacks one of the ports.
        CaptureFormatError: a malformed capture (names file and line).
    """
    try:
        return record_captures(
            paths,
            settings,
            workers=workers,
            progress=progress,
            strict=strict,
            reorder_window_s=reorder_window_s,
        )
    except CaptureContentError as exc:
        raise OfflineError(str(exc.args[0])) from None


@dataclass(frozen=True, slots=True)
class LagReport:
    """The lag used, and how it was found.

    Attributes:
        lag_s: the UUT latency applied, s (positive: the UUT reports late).
        source: ``auto`` (estimated and accepted by :func:`calib.lag.accept`),
            ``given``, or ``fallback`` (no accepted estimate: an uncertain, negative or
            bound one is never used; :data:`calib.lag.LAG_FALLBACK_S`, ``note`` says why).
        per_capture: capture name -> estimate (auto and fallback).
        note: why the fallback was used.
    """

    lag_s: float
    source: Literal["auto", "given", "fallback"]
    per_capture: dict[str, LagEstimate] = field(default_factory=dict)
    note: str = ""
    max_lag_s: float = math.inf

    def as_dict(self) -> dict[str, object]:
        """Plain types."""
        return {
            "lag_s": self.lag_s,
            "source": self.source,
            "note": self.note,
            "per_capture": {
                k: {
                    "lag_s": e.lag_s,
                    "std_s": _fin(e.std_s),
                    "peak_corr": e.peak_corr,
                    "at_bound": e.at_bound,
                    "accepted": not accept(e, max_lag_s=self.max_lag_s),
                }
                for k, e in self.per_capture.items()
            },
        }


def find_lag(
    recs: Sequence[Recording],
    settings: UutSettings,
    lag: float | None,
    *,
    max_lag_s: float = DEFAULT_MAX_LAG_S,
) -> LagReport:
    """The UUT latency: ``lag`` if given, else estimated per capture and combined.

    Each capture's estimate uses the heading (the current modelled) when the UUT has
    current states; the accepted ones (:func:`calib.lag.accept`) are combined by
    :func:`calib.lag.combine`. Without any, the lag is :data:`calib.lag.LAG_FALLBACK_S`,
    ``source`` is ``fallback`` and ``note`` says why (the commands print it once on
    stderr).

    Raises:
        OfflineError: ``lag`` is not finite.
    """
    if lag is not None:
        if not math.isfinite(lag):
            raise OfflineError("lag must be a finite number of seconds")
        return LagReport(float(lag), "given")
    per: dict[str, LagEstimate] = {}
    for r in recs:
        ok = r.ok_ref & np.isfinite(r.v_ref)
        heading = None
        if settings.current:
            hok = ok & np.isfinite(r.heading)
            heading = (r.t_ref[hok], r.heading[hok])
        try:
            per[r.name] = estimate_lag(
                *_increasing(r.t_read, r.raw),
                *_increasing(r.t_ref[ok], r.v_ref[ok]),
                max_lag_s,
                step_s=0.1,
                heading=None if heading is None else _increasing(*heading),
            )
        except CalibrationError:
            continue
    good = [e for e in per.values() if not accept(e, max_lag_s=max_lag_s)]
    if not good:
        why = "; ".join(f"{k}: {accept(e, max_lag_s=max_lag_s)}" for k, e in per.items())
        return LagReport(
            LAG_FALLBACK_S,
            "fallback",
            per,
            f"lag not measured ({why or 'no capture has enough overlap to estimate it'}): "
            f"{LAG_FALLBACK_S:g} s used, each reading paired with the reference of its time; "
            "pass --lag SECONDS when known",
            max_lag_s,
        )
    return LagReport(combine(good), "auto", per, max_lag_s=max_lag_s)


def _increasing(t: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The samples whose time increases (the lag search needs strictly increasing times)."""
    keep = np.ones(t.size, dtype=bool)
    if t.size > 1:
        keep[1:] = np.diff(t) > 0.0
    return t[keep], v[keep]


def _fin(x: float | None) -> float | None:
    return x if x is not None and math.isfinite(x) else None


WORSE_THAN_RAW = "the calibrated speed is further from the water speed than the raw reading"
"""The reason given when a calibration's RMSE exceeds the raw reading's."""


@dataclass(frozen=True, slots=True)
class CalibrationResult(Estimated):
    """What ``emlogd calibrate`` found (JSON keys: :meth:`to_dict`): the estimate (the
    standard errors its ``param_std``) and how it was found and scored."""

    captures: tuple[str, ...]
    settings: UutSettings
    method: Method
    estimate: Estimate
    lag: LagReport
    n_samples: int
    rmse_raw: float
    rmse_cal: float
    ident: Identifiability
    nis_mean: float | None = None
    nis_frac_inside: float | None = None
    average_s: float = 0.0
    """``ls``: the block length the fit averaged over (0: every sample), s."""
    heading: dict[str, dict[str, object]] = field(default_factory=dict)
    """Per capture, the heading used (``Pipeline.heading_status``) when the reference or
    the model needs one."""
    noise_scale: float | None = None
    """``kf``: the factor the filter found on the configured noises (1: as configured)."""
    imo_raw: ImoVerdict | None = None
    """The IMO A.824(19) verdict of the raw reading (:func:`calib.metrics.water_imo`)."""
    imo_cal: ImoVerdict | None = None
    """The IMO A.824(19) verdict of the calibrated reading."""

    @property
    def improvement_pct(self) -> float:
        """Improvement of the calibrated RMSE over the raw one, %."""
        return improvement_pct(self.rmse_raw, self.rmse_cal)

    @property
    def worse_than_raw(self) -> bool:
        """The corrected reading is further from the water speed than the raw one."""
        return self.rmse_cal > self.rmse_raw

    @property
    def identifiable(self) -> bool:
        """Every unknown is determined and the calibration is no worse than raw."""
        return self.ident.identifiable and not self.worse_than_raw

    @property
    def reason(self) -> str:
        """Why the result is not identifiable (empty when it is)."""
        why = [self.ident.reason] if self.ident.reason else []
        if self.worse_than_raw:
            why.append(WORSE_THAN_RAW)
        return "; ".join(why)

    def calibration(self) -> Calibration:
        """The result as a calibration record (what ``--save`` writes)."""
        s = self.settings
        return Calibration(
            uut=s.port,
            estimate=self.estimate,
            lag_s=self.lag.lag_s,
            current=s.current,
            method=self.method,
            n_samples=self.n_samples,
            reference={"port": s.reference_port, "field": s.reference_field},
            unidentifiable=self.ident.unidentifiable,
            nis_mean=self.nis_mean,
        )

    def to_dict(self) -> dict[str, object]:
        """The stable JSON document (README: ``calibrate --json``)."""
        s = self.settings
        return {
            "model": self.params.model,
            "method": self.method,
            "params": self.params.as_dict(),
            "stderr": {k: _fin(v) for k, v in self.param_std.items()},
            "current": _current_doc(self.current_mps, self.current_std_mps),
            "lag_s": self.lag.lag_s,
            "lag": self.lag.as_dict(),
            "rmse_raw": _fin(self.rmse_raw),
            "rmse_cal": _fin(self.rmse_cal),
            "improvement_pct": _fin(self.improvement_pct),
            "imo": imo_doc(self.imo_raw, self.imo_cal),
            "identifiable": self.identifiable,
            "unidentifiable": list(self.ident.unidentifiable),
            "verdicts": {v.unknown: v.reason for v in self.ident.verdicts if not v.determined},
            "reason": self.reason,
            "condition_number": _fin(self.ident.cond_info),
            "n_samples": self.n_samples,
            "average_s": self.average_s,
            "nis_mean": self.nis_mean,
            "nis_frac_inside": self.nis_frac_inside,
            "noise_scale": self.noise_scale,
            "uut": s.port,
            "ref": s.reference_port,
            "ref_field": s.reference_field,
            "current_states": s.current,
            "captures": list(self.captures),
            "heading": self.heading,
        }


def imo_doc(raw: ImoVerdict | None, cal: ImoVerdict | None) -> dict[str, object] | None:
    """The IMO A.824(19) verdicts as JSON: ``{"raw": {...}, "cal": {...}}`` with each
    :meth:`calib.metrics.ImoVerdict.as_dict` (None when not scored)."""
    if raw is None or cal is None:
        return None
    return {"raw": raw.as_dict(), "cal": cal.as_dict()}


def _current_doc(
    cur: tuple[float, float] | None, std: tuple[float, float] | None
) -> dict[str, float | None] | None:
    if cur is None:
        return None
    return {
        "north_mps": cur[0],
        "east_mps": cur[1],
        "std_north_mps": None if std is None else _fin(std[0]),
        "std_east_mps": None if std is None else _fin(std[1]),
    }


def calibrate(
    recs: Sequence[Recording],
    settings: UutSettings,
    method: Method,
    *,
    lag: float | None = None,
    trace: str | Path | None = None,
    average_s: float | None = None,
) -> CalibrationResult:
    """Estimate the UUT's model (and current) from every capture together.

    Args:
        recs: the recordings.
        settings: the UUT.
        method: ``ls`` or ``kf``.
        lag: the lag in s, or None to estimate it.
        trace: ``kf`` only: write one CSV row per learnt-from reading here (time, raw,
            reference, emitted and corrected speed, every parameter and the current
            with their σ, NIS, state and the unknowns learning).
        average_s: ``ls`` only: fit block means over this many seconds (a noisy
            reference would otherwise shrink the scale: :func:`calib.lsq.block_average`);
            None: the settings' ``average_s`` (by default
            :data:`emlogd.pipeline.uut.AVERAGE_S` of the reference field), 0: every sample.

    Raises:
        OfflineError: no aligned samples, or a trace asked of ``ls``.
    """
    if trace is not None and method != "kf":
        raise OfflineError("--trace follows the Kalman filter: use it with --method kf")
    if method not in ("ls", "kf"):
        raise OfflineError(f"method must be ls or kf, not {method!r}")
    refusal = heading_refusal(recs, settings)
    if refusal is not None:
        raise OfflineError(refusal)
    lag_report = find_lag(recs, settings, lag)
    pairs = [r.aligned(lag_report.lag_s) for r in recs]
    t, raw, ref, heading = concat_usable(pairs, settings.current)
    if raw.size == 0:
        raise OfflineError(why_no_sample(recs, settings, lag_report.lag_s))
    layout = Layout(check_model(settings.model), settings.current)
    kf = settings.kf
    hd = heading if settings.current else None
    nis_mean = nis_frac = noise_scale = None
    window = 0.0
    if method == "ls":
        given = average_s if average_s is not None else settings.average_s
        window = given if given is not None else AVERAGE_S.get(settings.reference_field, 0.0)
        # what the daemon's learner does not learn from is not fitted either: a reading
        # far below the reference at speed (a log below its threshold, a stalled wheel)
        # or a reference below the learning speed
        learnt = [_learnable(p, settings) for p in pairs]
        fit_t, fit_raw, fit_ref, fit_heading = concat_usable(learnt, settings.current)
        if fit_raw.size == 0:
            raise OfflineError(
                f"no reading to learn from: all {raw.size} are stalled (at zero while the "
                f"reference moves, or below {STALL_FRACTION:g} of it at speed) or the "
                "reference is below "
                f"{settings.min_ref_speed_mps:g} m/s"
            )
        if window > 0.0:
            fit_t, fit_raw, fit_ref, fit_heading = block_means(learnt, settings.current, window)
            if fit_raw.size < 3:
                raise OfflineError(
                    f"fewer than 3 blocks of {window:g} s with a steady heading: "
                    "pass --average 0 to fit every sample"
                )
        fit_hd = fit_heading if settings.current else None
        fit = fit_ls(
            settings.model,
            fit_ref,
            fit_raw,
            heading_deg=fit_hd,
            current=settings.current,
            rule=settings.rule,
            # block means, as the filter learns from them: the correction at the
            # variance-weighted speed (a noisy reference would pull the scale down)
            # and a current per CURRENT_WINDOW_S (one over hours of tide would bias both)
            noise_ratio=kf.r_ref_mps2 / kf.r_raw_mps2 if window > 0.0 else None,
            t_s=fit_t,
            current_block_s=CURRENT_WINDOW_S if window > 0.0 else None,
        )
        estimate = fit.estimate
        ident = fit.ident
    else:
        with TraceWriter(trace) as tracer:
            cal = run_online(recs, settings, lag_report.lag_s, trace=tracer.row if trace else None)
        ident = identifiability(
            layout,
            ref - _projection(cal.kf.current_mps, heading) if settings.current else ref,
            raw,
            kf.r_raw_mps2 + kf.r_ref_mps2,
            heading_deg=hd,
            rule=settings.rule,
        )
        # an unknown the recordings do not determine is at its prior (the run's start:
        # the ideal sensor), the others conditioned on it: the filter learns what a
        # recent window determines, and a few blocks may have moved it (and, through
        # the covariance, the rest) where the whole run does not determine it
        held = zero_params(settings.model).as_dict()
        final = cal.kf.copy()
        final.condition({k: v for k, v in held.items() if k not in ident.determined})
        stderr = {k: (v if k in ident.determined else None) for k, v in final.param_std.items()}
        # the current is reported as the filter reports it (status, VDR, the trace's
        # current_determined): only when determined at the end of the run
        cur = final.current_mps if cal.ident_current() else None
        cur_std = final.current_std_mps if cur is not None else None
        estimate = Estimate(final.params, stderr, cur, cur_std)
        noise_scale = cal.kf.noise_scale
        if cal.nis:
            stats = nis_stats(np.array(cal.nis, dtype=np.float64))
            nis_mean, nis_frac = stats.mean, stats.frac_inside
    params = estimate.params
    corrected = correct_array(params, raw)
    targets = water_targets(t, ref, raw, corrected, hd, params)
    rmse_raw, rmse_cal = water_scores(targets)
    imo_raw, imo_cal = water_imo(targets)
    return CalibrationResult(
        captures=tuple(r.path for r in recs),
        settings=settings,
        method=method,
        estimate=estimate,
        lag=lag_report,
        n_samples=int(raw.size),
        rmse_raw=rmse_raw,
        rmse_cal=rmse_cal,
        ident=ident,
        nis_mean=nis_mean,
        nis_frac_inside=nis_frac,
        average_s=window,
        heading={r.path: r.heading_info for r in recs} if needs_heading(settings) else {},
        noise_scale=noise_scale,
        imo_raw=imo_raw,
        imo_cal=imo_cal,
    )


def _learnable(p: Aligned, settings: UutSettings) -> Aligned:
    """``p`` without the samples the daemon's learner would not learn from (their
    reference taken away): a stalled reading (:meth:`UutHealth.stalled`) or a reference
    slower than ``min_ref_speed_mps``."""
    ref = p.ref
    with np.errstate(invalid="ignore"):
        stalled = np.asarray(_STALLED(p.raw, ref), dtype=bool)  # the learner's rule, per sample
        slow = np.abs(ref) < settings.min_ref_speed_mps
    return dataclasses.replace(p, ref=np.where(stalled | slow, np.nan, ref))


_STALLED = np.frompyfunc(UutHealth.stalled, 2, 1)


def _projection(cur: tuple[float, float] | None, heading_deg: FloatArray) -> FloatArray:
    if cur is None:
        return np.zeros_like(heading_deg)
    psi = np.radians(heading_deg)
    return np.asarray(cur[0] * np.cos(psi) + cur[1] * np.sin(psi), dtype=np.float64)


# ------------------------------------------------------------------ calibration files


def save_params(path: str | Path, result: CalibrationResult) -> None:
    """Write ``result`` as a calibration file (atomic)."""
    extra = {
        "captures": list(result.captures),
        "rmse_raw": _fin(result.rmse_raw),
        "rmse_cal": _fin(result.rmse_cal),
        "uut_source": result.settings.uut_source,
        "component": result.settings.component,
    }
    text = dumps({result.settings.port: result.calibration()}, {result.settings.port: extra})
    write_atomic(Path(path), text.encode("utf-8"))


def load_params(path: str | Path) -> tuple[Calibration, dict[str, Any]]:
    """Read a calibration file written by ``calibrate --save`` (its first UUT).

    Raises:
        OfflineError: unreadable, wrong kind or schema, or malformed (names the file).
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise OfflineError(f"{path}: cannot read the calibration file: {exc}") from None
    try:
        cals, extras = loads(text)
    except CalibrationFileError as exc:
        raise OfflineError(f"{path}: {exc}") from None
    if not cals:
        raise OfflineError(f"{path}: no calibration in the file")
    uut = next(iter(cals))
    return cals[uut], extras.get(uut, {})


# ------------------------------------------------------------------ evaluate


@dataclass(frozen=True, slots=True)
class EvaluationRow:
    """A frozen calibration applied to one capture."""

    capture: str
    n_samples: int
    rmse_raw: float
    rmse_cal: float
    imo_raw: ImoVerdict | None = None
    """The IMO A.824(19) verdict of the raw reading (None: no sample)."""
    imo_cal: ImoVerdict | None = None
    """The IMO A.824(19) verdict of the calibrated reading."""

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
            "imo": imo_doc(self.imo_raw, self.imo_cal),
        }


def evaluate(
    recs: Sequence[Recording], params: Params, settings: UutSettings, lag_s: float
) -> list[EvaluationRow]:
    """RMSE raw and calibrated per capture, with frozen ``params``, and the IMO
    A.824(19) verdicts against the same water speed.

    With current states the comparison is in the water frame
    (:func:`calib.metrics.water_scores`: the current of each window of the capture, for
    the raw reading and the corrected one alike).
    """
    rows = []
    for r in recs:
        pair = r.aligned(lag_s)
        ok = pair.usable(heading=settings.current)
        if not ok.any():
            rows.append(EvaluationRow(r.path, 0, math.nan, math.nan))
            continue
        raw, ref = pair.raw[ok], pair.ref[ok]
        cal = correct_array(params, raw)
        hd = pair.heading[ok] if settings.current else None
        targets = water_targets(pair.t[ok], ref, raw, cal, hd, params)
        rmse_raw, rmse_cal = water_scores(targets)
        imo_raw, imo_cal = water_imo(targets)
        rows.append(EvaluationRow(r.path, int(raw.size), rmse_raw, rmse_cal, imo_raw, imo_cal))
    return rows


# ------------------------------------------------------------------ cross-validation


def crossval(
    recs: Sequence[Recording],
    settings: UutSettings,
    *,
    lag: float | None = None,
    estimators: Sequence[str] = ESTIMATORS,
    kf_config: KfConfig | None = None,
    workers: int | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> tuple[CrossValResult, LagReport]:
    """Every estimator trained on every capture, evaluated on every other one.

    Segments are named after the captures (file stem). ``workers`` defaults to the
    CPU count when there is enough work to pay for the processes, and is at most the
    CPU count and one per job (:func:`calib.crossval.cross_validate`).

    Raises:
        OfflineError: fewer than two captures, duplicate names, or a capture with fewer
            than two samples paired with the reference.
    """
    if len(recs) < 2:
        raise OfflineError("cross-validation needs at least two captures")
    lag_report = find_lag(recs, settings, lag)
    pairs = [r.aligned(lag_report.lag_s) for r in recs]
    segs = [
        Segment(r.name, p.t, p.raw, p.ref, p.heading if settings.current else None)
        for r, p in zip(recs, pairs, strict=True)
    ]
    if len({s.name for s in segs}) != len(segs):
        raise OfflineError("captures must have distinct file names (they name the segments)")
    for r, p in zip(recs, pairs, strict=True):
        if len(p) < 2 or int(np.count_nonzero(np.isfinite(p.raw) & np.isfinite(p.ref))) < 2:
            raise OfflineError(
                f"{r.path}: fewer than 2 {settings.port} samples with a valid "
                f"{settings.reference_port} reference: no segment to cross-validate "
                "(leave the capture out)"
            )
    n = sum(len(p) for p in pairs)
    cores = os.cpu_count() or 1
    if workers is None:
        workers = min(cores, 4) if n > 20_000 else 1
    workers = min(workers, cores)  # CPU-bound: a process more than the cores adds none
    result = cross_validate(
        segs,
        estimators,
        kf_config=kf_config if kf_config is not None else settings.kf,
        progress=progress,
        workers=workers,
        current=settings.current,
    )
    return result, lag_report
