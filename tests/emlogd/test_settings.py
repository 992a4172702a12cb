"""Config → pipeline settings, and snapshot ↔ persisted state."""

from __future__ import annotations

from pathlib import Path

import pytest

from calib.models import Params
from emlogd.config import load_config
from emlogd.pipeline.core import Snapshot
from emlogd.settings import pipeline_from_config, snapshot_to_state, state_to_snapshot

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "emlogd.yaml"


def test_pipeline_settings_from_the_example() -> None:
    ports, uuts = pipeline_from_config(load_config(EXAMPLE))
    assert [(p.name, p.protocol) for p in ports] == [
        ("emlog1", "nmea0183"),
        ("emlog2", "nmea0183"),
        ("dvl", "pd6"),
    ]
    u = uuts[0]
    assert (u.port, u.reference_port, u.model, u.lag_s) == ("emlog1", "dvl", "EM3", None)
    assert u.kf.r_raw_mps2 == pytest.approx(0.0514**2)
    assert u.kf.q_params == 1e-7 and u.kf.p0 == 0.25
    assert u.talker == "VW" and u.maker == "EML"


def test_snapshot_state_round_trip() -> None:
    snap = Snapshot(
        uut="emlog1",
        model="EM4",
        params=Params("EM4", 0.01, 0.1, 0.05),
        param_std={"a": 0.001, "m": 0.002, "b": 0.003},
        covariance=((1.0, 0.0, 0.0, 0.0),) * 4,
        t=1.0,
        n_samples=5,
        lag_s=3.2,
        excitation={"condition_number": 10.0},
        nis_mean=1.0,
    )
    back = state_to_snapshot(snapshot_to_state(snap))
    assert back == snap
