"""The forward speed of ``--axes 2`` by the daemon's rule: the one-axis calibration kept
beside the two-axis one, each reading by the correction of the smaller expected
error, the one-axis calibration's where α is refused."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from calib.models import Params, forward_array
from calib.twoaxis import TwoAxisParams
from emlogd.cli import main
from emlogd.offline.simulate import EMLOG1, EMLOG2, SimulationResult, simulate, with_sensor
from emlogd.offline.twoaxis_forward import (
    NO_ONE_AXIS,
    ONE_AXIS,
    TWO_AXIS,
    ForwardRule,
    forward_speed,
    noise_var,
    one_axis_forward,
)

LAG = "0.46"
OWN = TwoAxisParams(Params("EM3", m=-0.2, b_mps=0.1), math.radians(3.0), -0.08, 0.04)


def _readings(u: float, n: int = 600, seed: int = 1) -> tuple[np.ndarray, ...]:
    """10-Hz readings of a log at ``u`` m/s forward (none athwart) by :data:`OWN`, with
    0.05 m/s of noise on the forward one."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    a = OWN.misalign_rad
    us = np.full(n, u * math.cos(a))
    raw_l = forward_array(OWN.longitudinal, us) + rng.normal(0.0, 0.05, n)
    raw_t = (1.0 + OWN.m_t) * np.full(n, -u * math.sin(a)) + OWN.b_t_mps
    return t, raw_l, raw_t


def test_noise_is_the_scatter_inside_one_second_blocks() -> None:
    """The reading's noise is measured as the daemon's learner measures it: the scatter
    about each 1-s block's mean (a speed ramp inside the blocks adds little); too few
    readings measure none."""
    t, raw_l, _ = _readings(2.0, n=3000)
    var = noise_var(t, raw_l + 0.01 * t)
    assert var is not None and math.sqrt(var) == pytest.approx(0.05, rel=0.05)
    assert noise_var(t[:50], raw_l[:50]) is None


def test_each_reading_by_the_correction_of_the_smaller_expected_error() -> None:
    """A one-axis calibration of a scale nearer 0 that agrees with the two-axis one at
    this speed (an offset of 1 cm/s, under the 2.1 cm/s of noise its gain spares) gives
    every reading's forward speed; one 5 cm/s off gives none; without
    one the two-axis calibration's own; α refused, the one-axis calibration's
    throughout, turned back by the α held."""
    t, raw_l, raw_t = _readings(2.0)
    own = OWN.correct(raw_l, raw_t)[0]
    ca = math.cos(OWN.misalign_rad)
    v = (float(np.mean(own)) + 0.01) / ca

    def one_at(offset: float) -> Params:
        return Params("EM3", m=-0.15, b_mps=float(np.mean(raw_l)) - 0.85 * (v + offset / ca))

    agree, off = one_at(0.0), one_at(0.04)
    got = forward_speed(t, raw_l, raw_t, OWN, ForwardRule(agree))
    one = one_axis_forward(raw_l, raw_t, OWN, agree)
    assert np.array_equal(got, one)
    assert np.array_equal(forward_speed(t, raw_l, raw_t, OWN, ForwardRule(off)), own)
    assert np.array_equal(forward_speed(t, raw_l, raw_t, OWN, NO_ONE_AXIS), own)
    refused = ForwardRule(off, "speed through water nearly constant")
    assert refused.forward == ONE_AXIS and ForwardRule(off).forward == TWO_AXIS
    assert refused.reason is not None and "nearly constant" in refused.reason
    held = TwoAxisParams(OWN.longitudinal)
    assert np.array_equal(
        forward_speed(t, raw_l, raw_t, held, refused), one_axis_forward(raw_l, raw_t, held, off)
    )
    assert refused.to_dict()["one_axis"] == {"model": "EM3", **off.as_dict()}


@pytest.fixture(scope="module")
def trial(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """Half the trial with emlog2 turned 3° to starboard, its noise the simulator's
    0.05 m/s (under which a one-axis calibration of a scale nearer 0 may spare some)."""
    sensor = with_sensor(EMLOG2, {"misalign": 3.0, "mt": -0.08, "bt": 0.04})
    return simulate(tmp_path_factory.mktemp("fwd"), seed=4, scale=0.5, emlogs=(EMLOG1, sensor))


def _json(argv: list[str]) -> dict[str, object]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    doc = json.loads(buf.getvalue())
    assert isinstance(doc, dict)
    return doc


def _evaluated(trial: SimulationResult, train: Path, save: Path) -> dict[str, object]:
    """``calibrate --axes 2`` on ``train`` saved, then ``evaluate --axes 2 --truth``."""
    common = ["--uut", "emlog2", "--ref", "dvl", "--axes", "2", "--lag", LAG]
    cal = _json(["calibrate", str(train), *common, "--save", str(save), "--json"])
    caps = [str(p) for p in trial.files]
    scored = ["--truth", str(trial.outdir), "--json"]
    ev = _json(["evaluate", *caps, "--params", str(save), "--axes", "2", *scored])
    ev["calibrated"] = cal
    return ev


def test_offline_forward_not_worse_than_the_one_axis_calibration(
    trial: SimulationResult, tmp_path: Path
) -> None:
    """Trained on the figure-8, the result keeps the one-axis calibration beside the
    two-axis one, and the forward speed evaluated against the truth is not worse than
    the one-axis calibration's on any trajectory (the straight run included, where the
    one-axis calibration's scale held at 0 divides the noise by less)."""
    ev = _evaluated(trial, trial.files[1], tmp_path / "two.yaml")
    cal = ev["calibrated"]
    assert isinstance(cal, dict) and cal["misalign_std_deg"] is not None
    assert cal["forward"] == TWO_AXIS and cal["forward_reason"] is None
    assert isinstance(cal["one_axis"], dict) and cal["one_axis"]["model"] == "EM3"
    rows = ev["rows"]
    assert isinstance(rows, list) and len(rows) == 5
    for r in rows:
        tr = r["truth"]
        assert tr["rmse_l_cal"] <= tr["rmse_l_one_axis"] + 1e-9, r["capture"]


@pytest.mark.parametrize(("train", "why"), [(0, "not determinable"), (2, "nearly constant")])
def test_alpha_refused_the_forward_speed_is_the_one_axis_calibrations(
    misaligned_trial: SimulationResult, tmp_path: Path, train: int, why: str
) -> None:
    """Trained where α is refused on the run's misaligned trial (a fifth of the trial:
    the transit, the transverse scale not determined; the straight run, the speed nearly
    constant), the forward speed reported is the
    one-axis calibration's on every trajectory, with the reason, in calibrate's and
    evaluate's JSON alike."""
    ev = _evaluated(misaligned_trial, misaligned_trial.files[train], tmp_path / "two.yaml")
    cal = ev["calibrated"]
    assert isinstance(cal, dict) and "alpha" in cal["unidentifiable"]
    for doc in (cal, ev):
        assert doc["forward"] == ONE_AXIS
        assert "misalignment is refused" in str(doc["forward_reason"])
        assert why in str(doc["forward_reason"])
    assert cal["scores"]["rmse_l_cal"] == cal["scores"]["rmse_l_one_axis"]
    rows = ev["rows"]
    assert isinstance(rows, list)
    for r in rows:
        assert r["truth"]["rmse_l_cal"] == r["truth"]["rmse_l_one_axis"], r["capture"]
