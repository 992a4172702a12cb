"""Simulated faults and the per-window truth score, and the supervisor against them.

The fast tests pin the fault injection and the window score; the trials (``soak``: a
simulated trial and a replay each, tens of seconds) hold the acceptance: over every
5-min window the emitted speed's RMSE against the true speed through the water is at
most raw's × 1.05.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.config import parse_config
from emlogd.offline.replay import replay
from emlogd.offline.simfaults import (
    MIN_WINDOW_SAMPLES,
    SensorFault,
    SwitchingCurrent,
    score_windows,
    with_fault,
)
from emlogd.offline.simulate import EMLOG1, EMLOG2, Truth, read_truth, simulate
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

RATIO = 1.05
"""The acceptance: emitted over raw RMSE against the truth, per window."""

CFG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 3.3, current: true}
"""


class TestFaults:
    """What the simulator injects."""

    def test_gain_schedules(self) -> None:
        """Step, periodic dip and linear drift multiply the reading from their start."""
        t = np.array([0.0, 99.0, 100.0, 150.0, 200.0, 250.0, 300.0])
        step = SensorFault("step", 100.0, factor=0.8).gain(t)
        assert step.tolist() == [1.0, 1.0, 0.8, 0.8, 0.8, 0.8, 0.8]
        dip = SensorFault("dip", 100.0, factor=0.5, duration_s=60.0, period_s=100.0).gain(t)
        assert dip.tolist() == [1.0, 1.0, 0.5, 0.5, 0.5, 0.5, 0.5]
        drift = SensorFault("drift", 100.0, factor=0.6, duration_s=200.0).gain(t)
        assert drift[1] == 1.0 and drift[4] == pytest.approx(0.8) and drift[6] == pytest.approx(0.6)

    def test_a_dip_ends_and_comes_back(self) -> None:
        """A 60-s dip every 100 s: off between dips."""
        f = SensorFault("dip", 0.0, factor=0.5, duration_s=60.0, period_s=100.0)
        g = f.gain(np.array([10.0, 70.0, 110.0, 170.0]))
        assert g.tolist() == [0.5, 1.0, 0.5, 1.0]

    def test_stuck_and_stalled_readings(self) -> None:
        """Stuck: the value plus noise during the spell; stalled: within [0, value]."""
        t = np.arange(0.0, 100.0)
        raw = np.full(t.size, 2.0)
        stuck = SensorFault("stuck", 50.0, value_mps=3.0, noise_mps=0.03, duration_s=20.0)
        out = stuck.apply(t, raw, 1)
        assert np.all(out[:50] == 2.0) and np.all(out[70:] == 2.0)
        assert abs(float(np.mean(out[50:70])) - 3.0) < 0.05 and np.std(out[50:70]) > 0.0
        stall = SensorFault("stall", 50.0, value_mps=0.2).apply(t, raw, 1)
        assert np.all((stall[50:] >= 0.0) & (stall[50:] <= 0.2))

    def test_switching_current(self) -> None:
        """Zero first, then the vector, every period."""
        n, e = SwitchingCurrent(0.5, -0.1, 600.0).at(np.array([0.0, 599.0, 600.0, 1300.0]))
        assert n.tolist() == [0.0, 0.0, 0.5, 0.0] and e.tolist() == [0.0, 0.0, -0.1, 0.0]


def _truth(n: int = 1200) -> Truth:
    t = 1_000.0 + np.arange(n, dtype=np.float64)
    return Truth(
        t=t,
        trajectory=np.ones(n, dtype=np.int64),
        stw_mps=np.full(n, 2.0),
        heading_deg=np.zeros(n),
        current_n_mps=np.zeros(n),
        current_e_mps=np.zeros(n),
        bottom_lock=np.ones(n, dtype=bool),
        sensors={"log": {"model": "EM3", "a_spm": 0.0, "m": 0.0, "b_mps": 0.0, "latency_s": 0.0}},
    )


def test_score_windows_per_five_minutes() -> None:
    """A spell of bad output shows in its own window, not diluted over the run."""
    truth = _truth()
    t = truth.t.copy()
    raw = np.full(t.size, 2.1)
    cor = np.full(t.size, 2.0)
    cor[400:420] = 3.0  # 20 s of 1 m/s error in the second window
    ws = score_windows(truth, "log", t, raw, cor)
    assert [w.n for w in ws] == [300, 300, 300, 300]
    assert ws[0].ratio == 0.0 and ws[0].rmse_raw == pytest.approx(0.1)
    assert ws[1].ratio == pytest.approx(math.sqrt(20 / 300) / 0.1)
    cor[:] = np.nan
    cor[: MIN_WINDOW_SAMPLES - 1] = 2.0
    assert score_windows(truth, "log", t, raw, cor) == []


def _worst(
    tmp: Path,
    *,
    fault: SensorFault | None = None,
    current: SwitchingCurrent | None = None,
    prior: Params | None = None,
    scale: float = 0.2,
) -> float:
    e1 = EMLOG1 if fault is None else with_fault(EMLOG1, fault)
    sim = simulate(tmp, seed=1, scale=scale, emlogs=(e1, EMLOG2), current_switch=current)
    ports, uuts = pipeline_from_config(parse_config(CFG))
    cals = {}
    if prior is not None:
        cals["emlog1"] = Calibration("emlog1", Estimate(prior, {"m": 0.01, "b": 0.01}), 3.3)
    res = replay(Pipeline(ports, uuts, cals), list(sim.files), truth=read_truth(sim.outdir))
    return max(w.ratio for w in res.truth_windows["emlog1"])


@pytest.mark.soak
class TestTrials:
    """Every 5-min window at most raw's × 1.05 against the truth (scale 0.2 trials)."""

    def test_a_gain_step(self, tmp_path: Path) -> None:
        """The gain drops to 0.65 for good during the figure-8."""
        assert _worst(tmp_path, fault=SensorFault("step", 1700.0, factor=0.65)) <= RATIO

    def test_a_gain_dip_under_a_switching_current(self, tmp_path: Path) -> None:
        """0.8 for 10 min every 20, the current jumping 0 / 0.5 m/s every 10 min."""
        fault = SensorFault("dip", 900.0, factor=0.8, duration_s=600.0, period_s=1200.0)
        cur = SwitchingCurrent(0.5, 0.0, 600.0)
        assert _worst(tmp_path, fault=fault, current=cur) <= RATIO

    def test_fouling(self, tmp_path: Path) -> None:
        """The gain falls linearly to 0.7 over 30 min."""
        fault = SensorFault("drift", 1000.0, factor=0.7, duration_s=1800.0)
        assert _worst(tmp_path, fault=fault) <= RATIO

    def test_a_poisoned_state_file(self, tmp_path: Path) -> None:
        """m = -0.5, b = +1.0 restored (inside the envelope), a DVL present."""
        assert _worst(tmp_path, prior=Params("EM3", m=-0.5, b_mps=1.0)) <= RATIO
