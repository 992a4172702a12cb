"""``emlogd replay --truth`` of a log that learns two axes: its VBW scored on both axes
against the truth, the learnt figures in the JSON."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from calib.models import Params
from drivers.records import KNOT_MPS
from emlogd.cli import main
from emlogd.daemon.statefile import StateStore
from emlogd.offline.replay_twoaxis import AthwartScorer, _worst_windows, as_sent
from emlogd.offline.simfaults import WINDOW_S
from emlogd.offline.simtruth import read_truth
from emlogd.offline.simulate import SimulationResult
from emlogd.offline.twoaxis_forward import ForwardRule
from emlogd.pipeline.core import Emit, Pipeline
from emlogd.pipeline.sentences import encode_vbw
from emlogd.pipeline.settings import PortSettings, UutSettings

CFG = """\
ports:
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
calibration:
  - {uut: emlog1, reference: dvl, lag: 3.3, current: true}
  - {uut: emlog2, reference: dvl, lag: 0.46, current: true, talker: VM, uut_source: VBW, axes: 2}
"""


@pytest.fixture(scope="module")
def trial(misaligned_trial: SimulationResult) -> SimulationResult:
    """The session's fifth of the trial with emlog2 turned 3° to starboard (noise
    0.01 m/s: ``tests/emlogd/conftest.py``)."""
    return misaligned_trial


@pytest.fixture(scope="module")
def replayed(
    trial: SimulationResult, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, object]:
    """The trial's figure-8 and circles replayed with emlog2 learning two axes, then the
    straight run and the return after a restart from the state file."""
    out = tmp_path_factory.mktemp("replay2")
    cfg = out / "replay.yaml"
    cfg.write_text(CFG)
    caps = [str(trial.files[1]), str(trial.files[3])]
    argv = ["replay", *caps, "--config", str(cfg), "--truth", str(trial.outdir), "--json"]
    argv += ["--state", str(out / "state.yaml")]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*argv, "--out", str(out / "out.nmea")]) == 0
    doc = json.loads(buf.getvalue())
    assert isinstance(doc, dict)
    doc["saved"] = StateStore(out / "state.yaml").load()[0]
    after = ["replay", str(trial.files[2]), str(trial.files[4]), *argv[3:]]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*after, "--out", str(out / "after.nmea")]) == 0
    doc["after"] = json.loads(buf.getvalue())
    return doc


def test_two_axis_learnt_applied_and_scored(replayed: dict[str, object]) -> None:
    """The figures learnt within 0.3° of 3° and applied; once applied the corrected
    athwart speed is within 1.1 times its floor where raw is four times it; the
    forward speed of the VBW no worse than the one-axis calibration's, its worst
    5-minute window against the one-axis calibration's scored over the replay and per
    trajectory; a one-axis UUT's entry has no two-axis keys."""
    uuts = replayed["uuts"]
    assert isinstance(uuts, dict)
    two = uuts["emlog2"]["two_axis"]
    assert two["state"] == "applied"
    assert two["applied"]["misalign_deg"] == pytest.approx(3.0, abs=0.3)
    scores = uuts["emlog2"]["two_axis_truth"]
    on = scores["applied"]
    assert on["n_samples"] > 100
    assert on["rmse_t_corrected"] <= 1.1 * on["rmse_t_floor"]
    assert on["rmse_t_raw"] > 3.0 * on["rmse_t_floor"]
    assert on["rmse_l_corrected"] <= on["rmse_l_one_axis"] + 0.002
    assert set(scores["by_trajectory"]) == {"2", "4"}
    eight, circles = scores["by_trajectory"]["2"], scores["by_trajectory"]["4"]
    assert eight["windows"] >= 1 and circles["windows"] >= 1  # each from its first reading
    assert circles["worst_window_raw"]["t0"] > eight["worst_window_raw"]["t0"]
    assert circles["worst_window_raw"]["ratio"] <= 1.05  # never worse than raw there
    assert scores["windows"] >= 4
    assert scores["worst_window_raw"]["ratio"] <= 1.0 + 1e-9
    assert (
        scores["worst_window_raw"]["rmse_t_corrected"] <= scores["worst_window_raw"]["rmse_t_raw"]
    )
    for sc in (scores, eight, circles):
        fw = sc["forward_worst_window_one_axis"]
        assert fw["n_samples"] > 100
        assert fw["ratio"] == pytest.approx(fw["rmse_l_corrected"] / fw["rmse_l_one_axis"], 1e-3)
    assert "two_axis" not in uuts["emlog1"] and "two_axis_truth" not in uuts["emlog1"]


def test_the_validated_figures_are_persisted(replayed: dict[str, object]) -> None:
    """The state file holds the figures applied, with their σ; a one-axis UUT's record
    has none."""
    saved = replayed["saved"]
    assert isinstance(saved, dict)
    uuts = replayed["uuts"]
    assert isinstance(uuts, dict)
    assert saved["emlog2"].two_axis == pytest.approx(uuts["emlog2"]["two_axis"]["applied"])
    assert saved["emlog1"].two_axis is None


def test_the_forward_speed_after_a_restart_is_the_two_axis_fits(
    replayed: dict[str, object],
) -> None:
    """The figures persisted carry the two-axis fit's longitudinal parameters; after a
    restart (the straight run and the return from the state file) they validate again
    and the VBW's forward speed is theirs, not the one-axis calibration's, which the
    current traded with its scale: within 1.05 of the floor, and better than the
    one-axis calibration's by at least 10 %."""
    saved = replayed["saved"]
    assert isinstance(saved, dict)
    assert {"lon_m", "lon_b_mps"} <= set(saved["emlog2"].two_axis)
    after = replayed["after"]
    assert isinstance(after, dict)
    two = after["uuts"]["emlog2"]["two_axis"]
    assert two["state"] == "applied" and two["forward"] == "two_axis"
    on = after["uuts"]["emlog2"]["two_axis_truth"]["applied"]
    assert on["rmse_l_corrected"] <= 1.05 * on["rmse_l_floor"]
    assert on["rmse_l_corrected"] <= 0.9 * on["rmse_l_one_axis"]


def test_a_straight_run_says_why_the_forward_speed_is_the_one_axis_calibrations(
    trial: SimulationResult, tmp_path: Path
) -> None:
    """The straight run alone: α refused, and the UUT's status (the JSON, the text
    summary's two-axis line) says the forward speed is the one-axis calibration's
    because of it, in the words of the offline ``forward_reason``; the VBW's forward
    speed is then the very sentence ``axes: 1`` sends, and scores exactly as the
    one-axis calibration's (both in the VBW's hundredths of a knot)."""
    cfg = tmp_path / "straight.yaml"
    cfg.write_text(CFG)
    argv = ["replay", str(trial.files[2]), "--config", str(cfg), "--out", str(tmp_path / "st.nmea")]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*argv, "--json", "--truth", str(trial.outdir)]) == 0
    uut = json.loads(buf.getvalue())["uuts"]["emlog2"]
    scores, two = uut["two_axis_truth"], uut["two_axis"]
    assert scores["n_samples"] > 1000
    assert scores["rmse_l_corrected"] == scores["rmse_l_one_axis"]
    refused = two["refused"]
    assert "speed through water nearly constant" in refused
    assert two["state"] == "learning" and two["forward"] == "one_axis"
    offline = ForwardRule(Params("EM3"), refused).reason
    assert two["forward_reason"] == offline
    assert offline == f"the one-axis calibration's: the misalignment is refused ({refused})"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    line = next(x for x in buf.getvalue().splitlines() if x.startswith("emlog2 two axes"))
    assert line == f"emlog2 two axes: learning; forward speed: {offline}"


def test_the_one_axis_forward_speed_is_scored_as_axes_1_sends_it(
    trial: SimulationResult,
) -> None:
    """The one-axis calibration's forward speed is scored in the VBW's hundredths of a
    knot, as ``axes: 1`` sends it: a VBW that carries exactly that speed scores exactly
    as it, though the unrounded speed (here 3 mm/s above the truth, under the 5 mm/s of a
    hundredth of a knot) is nearer the truth."""
    truth = read_truth(trial.files[0].parent)
    _, latency = truth.emlog("emlog2")
    s = UutSettings(port="emlog2", reference_port="dvl", uut_source="VBW", axes=2)
    pipeline = Pipeline([PortSettings("emlog2", "nmea0183"), PortSettings("dvl", "pd6")], [s])
    scorer = AthwartScorer(pipeline)
    tap = pipeline.two_axis["emlog2"].tap
    assert tap is not None
    sel = np.flatnonzero(truth.trajectory == 2)[1:-1:10]
    for t, u in zip(truth.t[sel] + latency, truth.stw_at(truth.t[sel]) + 0.003, strict=True):
        tap(float(t), float(u), float(u), 0.0, False)
        scorer.emitted([Emit(float(t), "emlog2", encode_vbw(float(u), 0.0, "VM"))])
    got = scorer.scores(truth)["emlog2"]
    assert got["n_samples"] == sel.size
    assert got["rmse_l_one_axis"] == got["rmse_l_corrected"]
    one = got["rmse_l_one_axis"]
    assert isinstance(one, float) and abs(one - 0.003) > 0.0002  # the rounding counted
    assert as_sent(np.array([1.0, np.nan]))[0] == pytest.approx(1.94 * KNOT_MPS, abs=1e-12)


def test_athwart_worst_windows() -> None:
    """Per 5-minute window: the one where the emitted athwart speed is furthest above
    raw (here the second, where it is twice raw) and the one furthest above the floor;
    a window with too few readings is left out; nothing scored, None."""
    n = 300
    t = np.arange(3 * n + 10, dtype=np.float64) * (WINDOW_S / n)
    raw = np.full(t.size, 0.1)
    cor = np.where((t >= WINDOW_S) & (t < 2 * WINDOW_S), 0.2, 0.05)
    floor = np.where(t < WINDOW_S, 0.01, 0.05)
    got = _worst_windows(t, raw, cor, floor)
    assert got["windows"] == 3
    worst_raw, worst_floor = got["worst_window_raw"], got["worst_window_floor"]
    assert isinstance(worst_raw, dict) and isinstance(worst_floor, dict)
    assert worst_raw["t0"] == pytest.approx(WINDOW_S) and worst_raw["ratio"] == pytest.approx(2.0)
    assert worst_floor["t0"] == pytest.approx(0.0) and worst_floor["ratio"] == pytest.approx(5.0)
    nan = np.full(t.size, np.nan)
    assert _worst_windows(t, nan, cor, floor) == {
        "windows": 0,
        "worst_window_raw": None,
        "worst_window_floor": None,
    }
