"""The offline commands on both axes: a misaligned two-axis log in a simulated trial."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from emlogd.offline.jobs import OfflineError
from emlogd.offline.simtruth import read_truth
from emlogd.offline.simulate import SimulationResult
from emlogd.offline.twoaxis import (
    TwoAxisRecording,
    TwoAxisResult,
    calibrate_two_axis,
    crossval_two_axis,
    evaluate_two_axis,
    load_two_axis,
    record_two_axis,
    save_two_axis,
    truth_scores,
)

LAG_S = 0.46
"""emlog2's latency (0.45 s) and its VBW's transmission."""


@pytest.fixture(scope="module")
def misaligned(misaligned_trial: SimulationResult) -> SimulationResult:
    """A fifth of the trial with emlog2 turned 3° to starboard, its transverse axis
    8 % low and 0.04 m/s to starboard; its noise 0.01 m/s, so five minutes of figure-8
    determine the misalignment (the session's ``misaligned_trial``)."""
    return misaligned_trial


@pytest.fixture(scope="module")
def recs(misaligned: SimulationResult) -> dict[str, TwoAxisRecording]:
    """Every capture decoded once, by name."""
    return {p.name.split(".")[0]: record_two_axis(p, "emlog2", "dvl") for p in misaligned.files}


@pytest.fixture(scope="module")
def figure8(recs: dict[str, TwoAxisRecording]) -> TwoAxisResult:
    """Least squares on the figure-8, fitted once."""
    return calibrate_two_axis([recs["2-figure8"]], "EM3", "ls", LAG_S)


def test_record_reads_both_axes(
    misaligned: SimulationResult, recs: dict[str, TwoAxisRecording]
) -> None:
    """Both axes of the log's VBW and of the DVL's bottom track, and its heading."""
    rec = recs["2-figure8"]
    assert rec.t_read.size > 2000 and rec.raw_t.size == rec.t_read.size
    assert rec.ref_stb.size == rec.t_ref.size
    a = rec.aligned(LAG_S)
    assert 0 < len(a) <= rec.t_read.size
    with pytest.raises(OfflineError, match="no port gps"):
        record_two_axis(misaligned.files[1], "emlog2", "gps")
    with pytest.raises(OfflineError, match="no VBW"):
        record_two_axis(misaligned.files[1], "emlog1", "dvl")


def test_figure8_determines_misalignment(
    misaligned: SimulationResult, recs: dict[str, TwoAxisRecording], figure8: TwoAxisResult
) -> None:
    """Trained on the figure-8: α within 0.3° of 3°, the corrected athwart speed within
    1.1× of its floor on every trajectory and the forward one too."""
    res = figure8
    assert res.fit.misalign_deg == pytest.approx(3.0, abs=0.3)
    assert res.fit.misalign_std_deg is not None
    doc = res.to_dict()
    assert doc["misalign_deg"] == res.fit.misalign_deg and doc["axes"] == 2
    truth = read_truth(misaligned.outdir)
    for name, rec in recs.items():
        s = truth_scores(rec, res.fit.params, truth, LAG_S)
        assert s.rmse_t_cal <= 1.1 * s.rmse_t_floor, name
        assert s.rmse_t_cal < s.rmse_t_raw, name


def test_straight_run_refuses_misalignment(recs: dict[str, TwoAxisRecording]) -> None:
    res = calibrate_two_axis([recs["3-straight"]], "EM3", "ls", LAG_S)
    assert "alpha" in res.fit.ident.unidentifiable
    assert "misalignment not separable from the transverse bias" in res.fit.ident.reason
    assert res.fit.to_dict()["misalign_std_deg"] is None


def test_save_load_and_evaluate(
    recs: dict[str, TwoAxisRecording], figure8: TwoAxisResult, tmp_path: Path
) -> None:
    """The saved calibration reads back and scores each capture on both axes; a
    misalignment beyond the envelope is refused at load."""
    res = figure8
    path = tmp_path / "two.yaml"
    save_two_axis(path, res)
    params, doc = load_two_axis(path)
    assert doc["axes"] == 2
    assert params.misalign_deg == pytest.approx(res.fit.misalign_deg)
    assert params.m_t == pytest.approx(res.fit.params.m_t)
    rows = evaluate_two_axis(list(recs.values()), params, LAG_S)
    assert len(rows) == 5
    for r in rows:  # manoeuvres tell them apart; on a steady heading the current takes
        s = r.scores  # each axis's offset for raw and calibration alike
        turning = "straight" not in r.capture and "return" not in r.capture
        assert s.rmse_t_cal < (1.0 if turning else 1.2) * s.rmse_t_raw, r.capture
        assert s.rmse_l_cal < (1.0 if turning else 1.2) * s.rmse_l_raw, r.capture
    bad = path.read_text().replace(f"misalign_deg: {res.fit.misalign_deg}", "misalign_deg: 25.0", 1)
    path.write_text(bad)
    with pytest.raises(OfflineError, match="misalignment"):
        load_two_axis(path)
    path.write_text("kind: other\n")
    with pytest.raises(OfflineError, match="not a two-axis calibration file"):
        load_two_axis(path)


def test_crossval_rows(recs: dict[str, TwoAxisRecording]) -> None:
    rows = crossval_two_axis([recs["2-figure8"], recs["3-straight"]], "EM3", LAG_S)
    assert [(r.train, r.test) for r in rows] == [
        ("2-figure8", "3-straight"),
        ("3-straight", "2-figure8"),
    ]
    assert math.isfinite(rows[0].misalign_deg) and rows[1].misalign_std_deg is None
    with pytest.raises(OfflineError, match="at least two"):
        crossval_two_axis([recs["2-figure8"]], "EM3", LAG_S)
