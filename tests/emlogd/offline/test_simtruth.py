"""The simulated trial's truth: the truth per sample, read back and scored against."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from emlogd.offline.simtruth import TRUTH_RATE_HZ, TruthError, read_truth
from emlogd.offline.simulate import SimulationResult


def test_truth_csv_matches_the_trial(trial: SimulationResult) -> None:
    """truth.csv.gz holds every trajectory at TRUTH_RATE_HZ with the truth.yaml summary figures."""
    truth = read_truth(trial.outdir)
    with gzip.open(trial.outdir / "truth.csv.gz", "rt") as f:
        assert f.readline().strip() == (
            "t,trajectory,stw_mps,heading_deg,current_n_mps,current_e_mps,bottom_lock,stw_trans_mps"
        )
    for i, tr in enumerate(trial.trajectories, start=1):
        on = truth.trajectory == i
        assert on.sum() == pytest.approx(tr.duration_s * TRUTH_RATE_HZ, abs=1)
        assert truth.t[on][0] == pytest.approx(tr.t_start)
        assert truth.stw_mps[on].mean() == pytest.approx(tr.mean_stw_mps, abs=2e-3)
        assert truth.bottom_lock[on].mean() == pytest.approx(tr.bottom_lock_fraction, abs=0.01)
        assert np.hypot(truth.current_n_mps[on], truth.current_e_mps[on]).max() == pytest.approx(
            tr.max_current_mps, abs=1e-3
        )
    assert np.all((truth.heading_deg >= 0.0) & (truth.heading_deg < 360.0))


def test_truth_is_interpolated_within_trajectories_only(trial: SimulationResult) -> None:
    """stw_at interpolates inside a trajectory and gives nan in the idle time between two."""
    truth = read_truth(trial.outdir)
    t1 = truth.t[truth.trajectory == 1]
    mid = 0.5 * (t1[10] + t1[11])
    expected = 0.5 * (truth.stw_mps[10] + truth.stw_mps[11])
    gap = t1[-1] + 10.0
    got = truth.stw_at([mid, gap, truth.t[0] - 1.0, truth.t[-1] + 1.0])
    assert got[0] == pytest.approx(expected)
    assert np.isnan(got[1:]).all()


def test_readings_are_paired_at_the_true_latency(trial: SimulationResult) -> None:
    """paired() gives each reading the true speed at its time minus the EMlog's latency,
    and leaves out a reading in the idle time, a non-finite reading and a non-finite
    corrected speed, keeping the others in order."""
    truth = read_truth(trial.outdir)
    _, latency = truth.emlog("emlog1")
    t1 = truth.t[truth.trajectory == 1]
    a, b, c3, d = (t1[t1.size * k // 5] for k in (1, 2, 3, 4))
    t = np.array([a, t1[-1] + 10.0 + latency, b, c3, d])
    raw = np.array([1.0, 1.0, np.nan, 1.0, 1.5])
    cor = np.array([1.1, 1.1, 1.1, np.inf, 1.6])
    tt, r, c, stw = truth.paired("emlog1", t, raw, cor)
    assert tt.tolist() == [a, d]
    assert (r.tolist(), c.tolist()) == ([1.0, 1.5], [1.1, 1.6])
    assert stw == pytest.approx(truth.stw_at(tt - latency))
    with pytest.raises(TruthError):
        truth.paired("dvl", t, raw, cor)


def test_read_truth_errors(tmp_path: Path, trial: SimulationResult) -> None:
    """A missing or malformed truth is one TruthError naming the file."""
    with pytest.raises(TruthError, match=r"truth\.csv\.gz: no such file"):
        read_truth(tmp_path)
    (tmp_path / "truth.yaml").write_text(trial.truth_path.read_text())
    with gzip.open(tmp_path / "truth.csv.gz", "wt") as f:
        f.write("t,speed\n1,2\n")
    with pytest.raises(TruthError, match="columns"):
        read_truth(tmp_path)
