"""Combinatorial cross-validation of the estimators (paper section IV-C-3, Tables II–III).

Every segment is a training set for every estimator (LS-EM1..4, KF-EM1..4); the
trained parameters are frozen and evaluated on every segment: the RMSE of the
reference minus the raw reading, of the reference minus the corrected reading,
and the improvement. The evaluations of a segment against itself are kept
(``in_sample=True``: Table III shows that diagonal) but not counted as
out-of-sample: 5 segments × 4 other segments × 8 estimators = 160 evaluations
(the paper's 140 without KF-EM4).

Training: LS-EMx fits the finite (ref, raw) pairs of the segment
(:func:`calib.lsq.fit_ls`); KF-EMx runs the whole segment through
:class:`calib.kalman.KfCalibrator` (nan reference = outage) and freezes its final
state, as the paper does, learning only the unknowns the segment determines (the
identifiability judged as for least squares; the others stay at the ideal sensor).
Evaluation applies the inverse model
(:func:`calib.models.correct_array`).

In the water frame (``current=True``, segments carrying headings) the estimators also
estimate the sea current. The current is the sea's, not the sensor's: a frozen
calibration is scored on a test segment against the reference minus the current
that segment shows (:func:`calib.metrics.water_scores`, the definition every command
uses: the current of each window, fitted for the raw reading and for the corrected one
alike); where the test segment's heading covers too few sectors to tell the current
from a bias, against the reference itself.

Per training segment, :meth:`CrossValResult.overall` pools the test segments
sample-weighted (the RMSE over their concatenation), excluding the training
segment by default; ``include_training=True`` gives Table III's "overall" column.

A segment is ``(name, t_s, raw_mps, ref_mps)`` with the reference already aligned
to the raw samples (lag applied by the caller). ``workers > 1`` trains in a
process pool (:mod:`concurrent.futures`); results do not depend on ``workers``.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from typing import ClassVar, Literal, NamedTuple

import numpy as np
import numpy.typing as npt

from calib.errors import DataError, ModelError
from calib.estimate import Estimate, Estimated
from calib.kalman import KfConfig, run_kf
from calib.lsq import fit_ls
from calib.metrics import improvement_pct, water_scores, water_targets
from calib.models import (
    CURRENT,
    FloatArray,
    ModelName,
    Params,
    check_model,
    correct_array,
    zero_params,
)

EstimatorName = Literal[
    "LS-EM1", "LS-EM2", "LS-EM3", "LS-EM4", "KF-EM1", "KF-EM2", "KF-EM3", "KF-EM4"
]
"""The eight estimators (the paper's seven plus KF-EM4)."""

ESTIMATORS: tuple[EstimatorName, ...] = (
    "LS-EM1",
    "LS-EM2",
    "LS-EM3",
    "LS-EM4",
    "KF-EM1",
    "KF-EM2",
    "KF-EM3",
    "KF-EM4",
)

ProgressCallback = Callable[[int, int, str], None]
"""``progress(done, total, label)`` called after each trained estimator."""


def split_estimator(name: str) -> tuple[Literal["LS", "KF"], ModelName]:
    """Split ``"KF-EM3"`` into ``("KF", "EM3")``.

    Raises:
        ModelError: not one of :data:`ESTIMATORS`.
    """
    if name not in ESTIMATORS:
        raise ModelError(f"unknown estimator {name!r}; expected one of {', '.join(ESTIMATORS)}")
    method: Literal["LS", "KF"] = "LS" if name.startswith("LS") else "KF"
    return method, check_model(name[3:])


class Segment(NamedTuple):
    """One trajectory segment, reference aligned to the raw samples.

    Attributes:
        name: label (e.g. ``"figure-8"``), unique within a cross-validation.
        t_s: sample times in s, shape (N,), non-decreasing.
        raw_mps: raw EMlog speeds in m/s, shape (N,) (nan = missing).
        ref_mps: reference speeds at the same times in m/s, shape (N,) (nan = outage).
        heading_deg: heading at the reference's time, degrees, shape (N,) (nan =
            unknown), or None; needed for the current.
    """

    name: str
    t_s: npt.ArrayLike
    raw_mps: npt.ArrayLike
    ref_mps: npt.ArrayLike
    heading_deg: npt.ArrayLike | None = None


class _Arrays(NamedTuple):
    """A validated segment as float64 arrays."""

    name: str
    t: FloatArray
    raw: FloatArray
    ref: FloatArray
    heading: FloatArray | None


@dataclass(frozen=True, slots=True)
class SegmentInfo:
    """Summary of one segment (the left columns of Table III).

    Attributes:
        name: segment label.
        n_samples: finite (raw, ref) pairs.
        duration_s: last minus first time, s.
        mean_speed_mps: mean reference speed, m/s.
        rmse_raw_mps: RMSE of the raw readings (:func:`calib.metrics.water_scores`: in
            the water frame with ``current``), m/s — the raw RMSE of every cell tested
            on this segment.
    """

    name: str
    n_samples: int
    duration_s: float
    mean_speed_mps: float
    rmse_raw_mps: float


@dataclass(frozen=True, slots=True)
class TrainedEstimator(Estimated):
    """Parameters one estimator learnt on one segment (then frozen).

    Attributes:
        estimator: e.g. ``"LS-EM3"``.
        train: training segment name.
        estimate: the frozen parameters with their standard errors (LS; None where not
            determined) or σ from P (KF), by short name, and the current learnt on the
            training segment (north, east), m/s, None when not estimated or not
            determined.
        identifiable: the identifiability verdict on the training segment.
        unidentifiable: the unknowns the segment does not determine (held).
        cond_info: the condition number of the information matrix.
    """

    estimator: str
    train: str
    estimate: Estimate
    identifiable: bool | None
    unidentifiable: tuple[str, ...]
    cond_info: float | None


@dataclass(frozen=True, slots=True)
class Evaluation:
    """One estimator, trained on one segment, evaluated on one segment.

    Attributes:
        estimator: estimator name.
        train: training segment name.
        test: evaluated segment name.
        n_samples: finite (raw, ref) pairs evaluated.
        rmse_raw_mps: RMSE of raw vs reference, m/s.
        rmse_cal_mps: RMSE of corrected vs reference, m/s.
        improvement_pct: ``100·(1 − cal/raw)``, %.
        in_sample: ``train == test``.
    """

    estimator: str
    train: str
    test: str
    n_samples: int
    rmse_raw_mps: float
    rmse_cal_mps: float
    improvement_pct: float
    in_sample: bool


@dataclass(frozen=True, slots=True)
class OverallRow:
    """Pooled out-of-sample result of one estimator trained on one segment.

    Attributes:
        estimator: estimator name.
        train: training segment name.
        n_samples: pooled sample count.
        rmse_raw_mps: pooled raw RMSE, m/s.
        rmse_cal_mps: pooled calibrated RMSE, m/s.
        improvement_pct: pooled improvement, %.
    """

    estimator: str
    train: str
    n_samples: int
    rmse_raw_mps: float
    rmse_cal_mps: float
    improvement_pct: float


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class CrossValResult:
    """All trained estimators and evaluations of one cross-validation.

    Attributes:
        segments: per-segment summaries, in input order.
        estimators: estimator names, in run order.
        trained: one entry per (estimator, training segment).
        evaluations: one entry per (estimator, training segment, test segment),
            including the in-sample diagonal.
    """

    segments: tuple[SegmentInfo, ...]
    estimators: tuple[str, ...]
    trained: tuple[TrainedEstimator, ...]
    evaluations: tuple[Evaluation, ...]

    @property
    def n_out_of_sample(self) -> int:
        """Number of out-of-sample evaluations (160 for 5 segments and 8 estimators)."""
        return sum(1 for e in self.evaluations if not e.in_sample)

    def evaluation(self, estimator: str, train: str, test: str) -> Evaluation:
        """One evaluation.

        Raises:
            KeyError: no such combination.
        """
        for e in self.evaluations:
            if (e.estimator, e.train, e.test) == (estimator, train, test):
                return e
        raise KeyError((estimator, train, test))

    def params(self, estimator: str, train: str) -> Params:
        """The parameters ``estimator`` learnt on ``train``.

        Raises:
            KeyError: no such combination.
        """
        for t in self.trained:
            if (t.estimator, t.train) == (estimator, train):
                return t.params
        raise KeyError((estimator, train))

    def matrix(self, estimator: str) -> list[list[Evaluation]]:
        """Table III body for one estimator: rows = training, columns = test segments."""
        names = [s.name for s in self.segments]
        return [[self.evaluation(estimator, tr, te) for te in names] for tr in names]

    def overall(self, estimator: str, *, include_training: bool = False) -> list[OverallRow]:
        """Per training segment, the sample-weighted pooled result over the test segments.

        Args:
            estimator: estimator name.
            include_training: also pool the in-sample evaluation (Table III "overall").

        Returns:
            One row per training segment, in segment order.
        """
        rows = []
        for train_row in self.matrix(estimator):
            use = [e for e in train_row if include_training or not e.in_sample]
            n = sum(e.n_samples for e in use)
            if n == 0:
                raw = cal = math.nan
            else:
                raw = math.sqrt(sum(e.n_samples * e.rmse_raw_mps**2 for e in use) / n)
                cal = math.sqrt(sum(e.n_samples * e.rmse_cal_mps**2 for e in use) / n)
            rows.append(
                OverallRow(estimator, train_row[0].train, n, raw, cal, improvement_pct(raw, cal))
            )
        return rows

    def table2(self, train: str, test: str) -> list[Evaluation]:
        """Table II layout: every estimator trained on ``train`` and evaluated on ``test``."""
        return [self.evaluation(est, train, test) for est in self.estimators]

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready document with stable keys (non-finite floats become None)."""

        def clean(d: dict[str, object]) -> dict[str, object]:
            return {k: _finite(v) if isinstance(v, float) else v for k, v in d.items()}

        return {
            "segments": [clean(asdict(s)) for s in self.segments],
            "estimators": list(self.estimators),
            "trained": [
                {
                    "estimator": t.estimator,
                    "train": t.train,
                    "model": t.params.model,
                    "params": t.params.as_dict(),
                    "stderr": {
                        k: None if v is None else _finite(v) for k, v in t.param_std.items()
                    },
                    "current": None
                    if t.current_mps is None
                    else {"north_mps": t.current_mps[0], "east_mps": t.current_mps[1]},
                    "identifiable": t.identifiable,
                    "unidentifiable": list(t.unidentifiable),
                    "condition_number": None if t.cond_info is None else _finite(t.cond_info),
                }
                for t in self.trained
            ],
            "evaluations": [clean(asdict(e)) for e in self.evaluations],
            "overall": [clean(asdict(r)) for est in self.estimators for r in self.overall(est)],
            "n_out_of_sample": self.n_out_of_sample,
        }

    def csv_rows(self) -> list[dict[str, object]]:
        """The evaluations as flat dicts (one CSV row each, header = keys)."""
        return [asdict(e) for e in self.evaluations]


def _check_segment(seg: Segment | tuple[str, object, object, object]) -> _Arrays:
    """Validate one segment."""
    name, t_s, raw_mps, ref_mps = seg[:4]
    heading = seg[4] if len(seg) > 4 else None
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw_mps, dtype=np.float64).reshape(-1)
    ref = np.asarray(ref_mps, dtype=np.float64).reshape(-1)
    if not t.shape == raw.shape == ref.shape:
        raise DataError(f"segment {name!r}: t, raw, ref differ in length")
    if t.size < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) >= 0.0):
        raise DataError(f"segment {name!r}: need ≥ 2 finite, non-decreasing times")
    if int(np.count_nonzero(np.isfinite(raw) & np.isfinite(ref))) < 2:
        raise DataError(f"segment {name!r}: fewer than 2 finite (raw, ref) pairs")
    hd = None
    if heading is not None:
        hd = np.asarray(heading, dtype=np.float64).reshape(-1)
        if hd.shape != t.shape:
            raise DataError(f"segment {name!r}: heading and t differ in length")
    return _Arrays(str(name), t, raw, ref, hd)


def _usable(seg: _Arrays, current: bool) -> npt.NDArray[np.bool_]:
    ok = np.isfinite(seg.raw) & np.isfinite(seg.ref)
    if current and seg.heading is not None:
        ok &= np.isfinite(seg.heading)
    return ok


def _info(seg: _Arrays, current: bool) -> SegmentInfo:
    ok = _usable(seg, current)
    hd = seg.heading[ok] if current and seg.heading is not None else None
    raw = seg.raw[ok]
    # the raw RMSE of the cells (:func:`_evaluate`): the same samples, the same frame
    r_raw, _ = water_scores(water_targets(seg.t[ok], seg.ref[ok], raw, raw, hd, zero_params("EM3")))
    return SegmentInfo(
        name=seg.name,
        n_samples=int(np.count_nonzero(ok)),
        duration_s=float(seg.t[-1] - seg.t[0]),
        mean_speed_mps=float(np.mean(seg.ref[ok])),
        rmse_raw_mps=r_raw,
    )


def _train(
    estimator: str, seg: _Arrays, kf_config: KfConfig, *, current: bool = False
) -> TrainedEstimator:
    """Train one estimator on one validated segment (see the module docstring).

    Args:
        estimator: estimator name.
        seg: the segment arrays.
        kf_config: tuning of the KF estimators.
        current: estimate the current too (the segment must carry headings).

    Returns:
        The frozen parameters.

    Raises:
        DataError: a current without headings.
    """
    method, model = split_estimator(estimator)
    if current and seg.heading is None:
        raise DataError(f"segment {seg.name!r} has no heading: the current cannot be estimated")
    ok = _usable(seg, current)
    fit = fit_ls(
        model,
        seg.ref[ok],
        seg.raw[ok],
        heading_deg=None if seg.heading is None or not current else seg.heading[ok],
        current=current,
    )
    if method == "LS":
        return TrainedEstimator(
            estimator,
            seg.name,
            fit.estimate,
            fit.identifiable,
            fit.unidentifiable,
            fit.cond_info,
        )
    # The filter learns only what the segment determines (the least-squares verdict);
    # the rest stays at the ideal sensor. With a current the current always learns: where
    # it is not separable from the bias it takes their sum (the bias is held).
    ident = fit.ident
    learn = set(ident.determined) | ({CURRENT} if current else set())
    run = run_kf(
        model,
        seg.t,
        seg.raw,
        seg.ref,
        kf_config,
        heading_deg=seg.heading if current else None,
        current=current,
        history=False,
        learn=frozenset(learn),
    )
    std: dict[str, float | None] = {
        k: (v if k in ident.determined else None) for k, v in run.param_std.items()
    }
    determined = CURRENT in ident.determined
    return TrainedEstimator(
        estimator,
        seg.name,
        Estimate(
            run.params,
            std,
            run.current_mps if determined else None,
            run.current_std_mps if determined else None,
        ),
        ident.identifiable,
        ident.unidentifiable,
        ident.cond_info,
    )


def _evaluate(trained: TrainedEstimator, seg: _Arrays, *, current: bool = False) -> Evaluation:
    """Apply frozen parameters to a validated segment.

    Args:
        trained: the trained estimator.
        seg: the segment arrays.
        current: score against the reference minus the segment's own current.

    Returns:
        Raw and calibrated RMSE and the improvement.
    """
    cal = correct_array(trained.params, seg.raw)
    ok = np.isfinite(cal) & _usable(seg, current)
    n = int(np.count_nonzero(ok))
    if n == 0:
        r_raw = r_cal = math.nan
    else:
        hd = seg.heading[ok] if current and seg.heading is not None else None
        r_raw, r_cal = water_scores(
            water_targets(seg.t[ok], seg.ref[ok], seg.raw[ok], cal[ok], hd, trained.params)
        )
    return Evaluation(
        estimator=trained.estimator,
        train=trained.train,
        test=seg.name,
        n_samples=n,
        rmse_raw_mps=r_raw,
        rmse_cal_mps=r_cal,
        improvement_pct=improvement_pct(r_raw, r_cal),
        in_sample=trained.train == seg.name,
    )


def _job(
    estimator: str, i_train: int, segs: Sequence[_Arrays], kf_config: KfConfig, current: bool
) -> tuple[TrainedEstimator, list[Evaluation]]:
    trained = _train(estimator, segs[i_train], kf_config, current=current)
    return trained, [_evaluate(trained, s, current=current) for s in segs]


class _WorkerData:
    """Per-process data of a pool worker, set once by :func:`_init_worker`."""

    segs: ClassVar[list[_Arrays]] = []
    cfg: ClassVar[KfConfig] = KfConfig()
    current: ClassVar[bool] = False


def _init_worker(segs: list[_Arrays], kf_config: KfConfig, current: bool) -> None:
    _WorkerData.segs = segs
    _WorkerData.cfg = kf_config
    _WorkerData.current = current


def _worker_job(estimator: str, i_train: int) -> tuple[TrainedEstimator, list[Evaluation]]:
    return _job(estimator, i_train, _WorkerData.segs, _WorkerData.cfg, _WorkerData.current)


def cross_validate(
    segments: Sequence[Segment | tuple[str, npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]],
    estimators: Sequence[str] = ESTIMATORS,
    *,
    kf_config: KfConfig | None = None,
    progress: ProgressCallback | None = None,
    workers: int = 1,
    current: bool = False,
) -> CrossValResult:
    """Train every estimator on every segment and evaluate it on every segment.

    Args:
        segments: ``(name, t_s, raw_mps, ref_mps)`` per segment, names unique.
        estimators: estimator names (default all eight).
        kf_config: tuning of the KF estimators.
        progress: called as ``progress(done, total, "KF-EM3 on figure-8")``.
        workers: processes to use (1: run in this process), at most one per job
            (estimator and segment).
        current: estimate the current too and score in the water frame (segments
            must carry headings).

    Returns:
        The result object (tables, JSON, CSV views).

    Raises:
        DataError: no segment, duplicate names, malformed series.
        ModelError: unknown estimator.
        ValueError: workers < 1.
    """
    if workers < 1:
        raise ValueError("workers must be at least 1")
    segs = [_check_segment(s) for s in segments]
    if not segs:
        raise DataError("no segment to cross-validate")
    names = [s.name for s in segs]
    if len(set(names)) != len(names):
        raise DataError(f"segment names must be unique: {names}")
    ests = tuple(estimators)
    for est in ests:
        split_estimator(est)
    cfg = kf_config if kf_config is not None else KfConfig()
    jobs = [(est, i) for est in ests for i in range(len(segs))]
    results: dict[tuple[str, int], tuple[TrainedEstimator, list[Evaluation]]] = {}
    total = len(jobs)
    if workers == 1:
        for done, (est, i) in enumerate(jobs, start=1):
            results[(est, i)] = _job(est, i, segs, cfg, current)
            if progress is not None:
                progress(done, total, f"{est} on {names[i]}")
    else:
        with ProcessPoolExecutor(  # never more processes than jobs: the pool forks them all
            max_workers=min(workers, total), initializer=_init_worker, initargs=(segs, cfg, current)
        ) as pool:
            futures = {pool.submit(_worker_job, est, i): (est, i) for est, i in jobs}
            for done, fut in enumerate(as_completed(futures), start=1):
                est, i = futures[fut]
                results[(est, i)] = fut.result()
                if progress is not None:
                    progress(done, total, f"{est} on {names[i]}")
    trained = tuple(results[job][0] for job in jobs)
    evaluations = tuple(e for job in jobs for e in results[job][1])
    return CrossValResult(tuple(_info(s, current) for s in segs), ests, trained, evaluations)
