"""``emlogd replay --truth`` of a log that learns two axes: its VBW scored on both axes
against the truth, the learnt figures in the JSON."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from emlogd.cli import main
from emlogd.daemon.statefile import StateStore
from emlogd.offline.simulate import EMLOG1, EMLOG2, SimulationResult, simulate, with_sensor

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
def replayed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A fifth of the trial with emlog2 turned 3° to starboard (noise 0.01 m/s): the
    figure-8 and the circles replayed with emlog2 learning two axes."""
    out = tmp_path_factory.mktemp("replay2")
    sensor = with_sensor(EMLOG2, {"misalign": 3.0, "mt": -0.08, "bt": 0.04, "noise": 0.01})
    trial: SimulationResult = simulate(out, seed=3, scale=0.2, emlogs=(EMLOG1, sensor))
    cfg = out / "replay.yaml"
    cfg.write_text(CFG)
    caps = [str(trial.files[1]), str(trial.files[3])]
    argv = ["replay", *caps, "--config", str(cfg), "--truth", str(out), "--json"]
    argv += ["--state", str(out / "state.yaml")]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([*argv, "--out", str(out / "out.nmea")]) == 0
    doc = json.loads(buf.getvalue())
    assert isinstance(doc, dict)
    doc["saved"] = StateStore(out / "state.yaml").load()[0]
    return doc


def test_two_axis_learnt_applied_and_scored(replayed: dict[str, object]) -> None:
    """The figures learnt within 0.3° of 3° and applied; once applied the corrected
    athwart speed is within 1.1 times its floor where raw is four times it; the
    forward speed of the VBW no worse than the one-axis calibration's; a one-axis
    UUT's entry has no two-axis keys."""
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
