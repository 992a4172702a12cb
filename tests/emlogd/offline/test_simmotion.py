"""Trials whose motion the simulator's trajectories do not fly: moored in a current, then
under way; minutes astern. The acceptance of the fault soak (``test_simfaults.py``):
every 5-min window's RMSE of the emitted speed against the truth at most raw's × 1.05,
and no log silenced for the rest of the trial (``soak``: a simulation and a replay
each, a minute or two)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import emlogd.offline.simulate as simulate_module
from calib.models import FloatArray
from emlogd.config import parse_config
from emlogd.offline.replay import replay
from emlogd.offline.simkinematics import Kinematics, TrajectorySpec, kinematics
from emlogd.offline.simulate import read_truth, simulate
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

RATIO = 1.05
"""The acceptance: emitted over raw RMSE against the truth, per window."""

SCALE = 0.3
"""The trial's duration factor: the transit 37.5 min, the return 9 min."""

CFG = """\
ports: [{name: emlog1, url: /dev/null, protocol: nmea0183, role: uut},
  {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut},
  {name: dvl, url: /dev/null, protocol: pd6, role: reference}]
calibration: [{uut: emlog1, reference: dvl, current: true}, {uut: emlog2, reference: dvl, current: true}]
"""

Motion = Callable[[Kinematics], Kinematics]


def _ramp(t: FloatArray, t0: float, t1: float) -> FloatArray:
    return np.asarray(np.clip((t - t0) / (t1 - t0), 0.0, 1.0), dtype=np.float64)


def moored_in_the_current(k: Kinematics) -> Kinematics:
    """Moored for 15 min, heading fixed, the current passing the hull (its speed through
    the water the current's, backwards or forwards along the hull), then under way
    within a minute."""
    w = _ramp(k.t, 900.0, 960.0)
    heading = np.where(k.t < 960.0, k.heading[int(np.searchsorted(k.t, 960.0))], k.heading)
    s, c = np.sin(heading), np.cos(heading)
    surge0 = -(k.current_e * s + k.current_n * c)
    sway0 = -(k.current_e * c - k.current_n * s)
    return dataclasses.replace(
        k, surge=k.surge * w + surge0 * (1 - w), sway=k.sway * w + sway0 * (1 - w), heading=heading
    )


def astern(k: Kinematics) -> Kinematics:
    """5 min astern at 1 m/s from 20 min in, 30 s to stop and to get under way again."""
    w = _ramp(k.t, 1200.0, 1230.0) - _ramp(k.t, 1500.0, 1530.0)
    return dataclasses.replace(k, surge=k.surge * (1 - w) - w, sway=k.sway * (1 - w))


def _trial(tmp: Path, motion: Motion, monkeypatch: pytest.MonkeyPatch) -> dict[str, list[float]]:
    """The per-window ratios of each EMlog, the transit flown with ``motion``."""

    def flown(
        spec: TrajectorySpec, duration_s: float, rng: np.random.Generator, **kw: object
    ) -> Kinematics:
        k = kinematics(spec, duration_s, rng, **kw)  # type: ignore[arg-type]
        return motion(k) if spec.kind == "transit" else k

    monkeypatch.setattr(simulate_module, "kinematics", flown)
    sim = simulate(tmp, seed=1, scale=SCALE)
    ports, uuts = pipeline_from_config(parse_config(CFG))
    res = replay(Pipeline(ports, uuts, {}), list(sim.files), truth=read_truth(sim.outdir))
    return {u: [w.ratio for w in ws] for u, ws in res.truth_windows.items()}


@pytest.mark.soak
@pytest.mark.parametrize("motion", [moored_in_the_current, astern], ids=["moored", "astern"])
def test_no_window_worse_than_raw_and_no_log_silenced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, motion: Motion
) -> None:
    """Moored: the log at rest reads the current passing the hull, backwards too; it
    went out held at 0 (worst windows 1.26 and 2.03 on the full trial). Astern: the
    log's sternway went out at 0, and emlog1's readings below -1 m/s, skipped before
    the rate check, taught it a 4-s interval, so the 1-Hz log back under way was
    babbling and silenced for the rest of the trial (worst windows 4.19 and 9.81)."""
    ratios = _trial(tmp_path, motion, monkeypatch)
    assert max(max(r) for r in ratios.values()) <= RATIO, ratios
    counts = [len(r) for r in ratios.values()]
    assert min(counts) >= max(counts) - 1, ratios
