"""Combinatorial cross-validation."""

from __future__ import annotations

import json
from concurrent.futures import Executor, Future
from typing import Any

import numpy as np
import pytest

from calib.crossval import ESTIMATORS, Segment, cross_validate, split_estimator
from calib.errors import DataError, ModelError
from calib.models import Params
from tests.synth import TrajectoryKind, simulate_segment, water_frame_segment

TRUTH = Params("EM3", m=0.08, b_mps=0.1)
KINDS = ("transit", "figure-8", "straight", "circles", "return")


def _segments(seed: int = 0, minutes: float = 4.0) -> list[Segment]:
    rng = np.random.default_rng(seed)
    return [simulate_segment(k, k, minutes * 60.0, 1.0, TRUTH, rng) for k in KINDS]  # type: ignore[arg-type]


class TestCrossValidate:
    """The full train × test × estimator matrix."""

    def test_160_evaluations(self) -> None:
        """5 segments and 8 estimators give 160 out-of-sample evaluations plus 40 in-sample."""
        res = cross_validate(_segments())
        assert res.n_out_of_sample == 160
        assert len(res.evaluations) == 200 and len(res.trained) == 40
        assert sum(e.in_sample for e in res.evaluations) == 40

    def test_calibration_improves_on_dynamic_training(self) -> None:
        """LS-EM3 and KF-EM3 trained on the figure-8 improve every other segment."""
        res = cross_validate(_segments(), ["LS-EM3", "KF-EM3"])
        for est in ("LS-EM3", "KF-EM3"):
            for e in res.matrix(est)[1]:
                assert e.improvement_pct > 50.0
            p = res.params(est, "figure-8")
            assert p.m == pytest.approx(0.08, abs=0.02)

    def test_matrix_and_overall_layout(self) -> None:
        """matrix() is train × test; overall() pools the test segments by sample count."""
        res = cross_validate(_segments(), ["LS-EM1"])
        mat = res.matrix("LS-EM1")
        assert [row[0].train for row in mat] == list(KINDS)
        assert [e.test for e in mat[0]] == list(KINDS)
        assert all(mat[i][i].in_sample for i in range(5))
        row = res.overall("LS-EM1")[0]
        others = mat[0][1:]
        n = sum(e.n_samples for e in others)
        pooled = np.sqrt(sum(e.n_samples * e.rmse_cal_mps**2 for e in others) / n)
        assert row.rmse_cal_mps == pytest.approx(pooled)
        assert res.overall("LS-EM1", include_training=True)[0].n_samples == n + mat[0][0].n_samples

    def test_table2_layout(self) -> None:
        """table2() lists every estimator for one (train, test) pair."""
        res = cross_validate(_segments(minutes=2.0))
        rows = res.table2("figure-8", "straight")
        assert [r.estimator for r in rows] == list(ESTIMATORS)

    def test_to_dict_is_json(self) -> None:
        """to_dict() serialises to strict JSON with stable keys."""
        res = cross_validate(_segments(minutes=2.0), ["LS-EM3", "KF-EM2"])
        doc = json.loads(json.dumps(res.to_dict(), allow_nan=False))
        assert set(doc) == {
            "segments",
            "estimators",
            "trained",
            "evaluations",
            "overall",
            "n_out_of_sample",
        }
        assert doc["trained"][0]["params"].keys() == {"m", "b"}
        assert len(res.csv_rows()) == 50

    def test_progress_callback(self) -> None:
        """progress is called once per trained estimator with a running count."""
        calls: list[tuple[int, int, str]] = []
        cross_validate(
            _segments(minutes=2.0), ["LS-EM1", "KF-EM1"], progress=lambda *a: calls.append(a)
        )
        assert [c[0] for c in calls] == list(range(1, 11))
        assert all(c[1] == 10 for c in calls)
        assert calls[0][2] == "LS-EM1 on transit"

    def test_process_pool_gives_same_result(self) -> None:
        """workers=2 returns exactly the single-process result."""
        segs = _segments(minutes=2.0)
        a = cross_validate(segs, ["LS-EM3", "KF-EM3"])
        b = cross_validate(segs, ["LS-EM3", "KF-EM3"], workers=2)
        assert a.evaluations == b.evaluations
        assert a.trained == b.trained

    def test_never_more_processes_than_jobs(self, monkeypatch: pytest.MonkeyPatch) -> None:
        """workers=100 000 for 2 estimators on the segments: a pool of one process per
        job, the same result. The pool forked every process asked for at once (160
        processes for 16 jobs with ``crossval --workers 200``). The pool here forks
        nothing (it runs the jobs in this process), so a regression costs no processes."""
        import calib.crossval as cv

        asked: list[int] = []

        class Inline(Executor):
            def __init__(self, max_workers: int, initializer: Any, initargs: Any) -> None:
                asked.append(max_workers)
                initializer(*initargs)

            def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future[Any]:
                fut: Future[Any] = Future()
                fut.set_result(fn(*args, **kwargs))
                return fut

        monkeypatch.setattr(cv, "ProcessPoolExecutor", Inline)
        segs = _segments(minutes=2.0)
        a = cross_validate(segs, ["LS-EM3", "KF-EM3"])
        b = cross_validate(segs, ["LS-EM3", "KF-EM3"], workers=100_000)
        assert asked == [2 * len(segs)]
        assert a.evaluations == b.evaluations

    def test_outages_in_training_segment(self) -> None:
        """nan reference samples are outages for KF and dropped for LS."""
        segs = _segments(minutes=2.0)
        ref = np.array(segs[1].ref_mps)
        ref[30:60] = np.nan
        segs[1] = segs[1]._replace(ref_mps=ref)
        res = cross_validate(segs, ["LS-EM3", "KF-EM3"])
        assert res.evaluation("KF-EM3", "figure-8", "figure-8").n_samples == 90

    def test_rejects_bad_input(self) -> None:
        """Duplicate names, unknown estimators and empty input raise."""
        segs = _segments(minutes=1.0)
        with pytest.raises(DataError, match="unique"):
            cross_validate([segs[0], segs[0]])
        with pytest.raises(ModelError):
            cross_validate(segs, ["LS-EM5"])
        with pytest.raises(DataError):
            cross_validate([])
        with pytest.raises(ValueError, match="workers"):
            cross_validate(segs, workers=0)

    def test_split_estimator(self) -> None:
        """Estimator names split into method and model."""
        assert split_estimator("KF-EM4") == ("KF", "EM4")


class TestWaterFrameCrossval:
    """Cross-validation with the current estimated and scored in the water frame."""

    def test_current_aware_estimators_generalise_where_the_papers_do_not(self) -> None:
        """Trained on circles in a current, LS-EM3 with current beats the paper's LS-EM3 on a figure-8."""
        truth = Params("EM3", m=0.09, b_mps=0.08)
        segs = []
        runs: tuple[tuple[TrajectoryKind, int], ...] = (("circles", 1), ("figure-8", 2))
        for kind, seed in runs:
            s = water_frame_segment(
                kind, 1200.0, 1.0, truth, np.random.default_rng(seed), current_mps=(0.25, -0.2)
            )
            segs.append(Segment(kind, s.t_s, s.raw_mps, s.ref_mps, s.heading_deg))
        plain = cross_validate(segs, ["LS-EM3"])
        water = cross_validate(segs, ["LS-EM3"], current=True)
        e_plain = plain.evaluation("LS-EM3", "circles", "figure-8")
        e_water = water.evaluation("LS-EM3", "circles", "figure-8")
        assert e_water.rmse_cal_mps < 0.06 < e_plain.rmse_cal_mps
        trained = next(t for t in water.trained if t.train == "circles")
        assert trained.current_mps == pytest.approx((0.25, -0.2), abs=0.03)
        assert json.loads(json.dumps(water.to_dict()))["trained"][0]["current"] is not None

    def test_kf_learns_only_what_its_training_segment_determines(self) -> None:
        """KF-EM3 trained on a straight run in a current holds the scale and the bias
        (not separable there) instead of bending them, and is not worse than raw."""
        truth = Params("EM3", m=0.09, b_mps=0.08)
        segs = []
        runs: tuple[tuple[TrajectoryKind, int], ...] = (("transit", 1), ("figure-8", 2))
        for kind, seed in runs:
            s = water_frame_segment(
                kind, 900.0, 1.0, truth, np.random.default_rng(seed), current_mps=(0.3, 0.2)
            )
            segs.append(Segment(kind, s.t_s, s.raw_mps, s.ref_mps, s.heading_deg))
        res = cross_validate(segs, ["KF-EM3"], current=True)
        trained = next(t for t in res.trained if t.train == "transit")
        assert "b" in trained.unidentifiable and trained.params.b_mps == 0.0
        assert trained.param_std["b"] is None
        e = res.evaluation("KF-EM3", "transit", "figure-8")
        assert e.rmse_cal_mps <= e.rmse_raw_mps

    def test_current_without_heading_is_an_error(self) -> None:
        """Segments without headings cannot be cross-validated with the current."""
        seg = simulate_segment("a", "figure-8", 300.0, 1.0, Params("EM3"), np.random.default_rng(1))
        with pytest.raises(DataError, match="heading"):
            cross_validate([seg, seg._replace(name="b")], ["LS-EM3"], current=True)
