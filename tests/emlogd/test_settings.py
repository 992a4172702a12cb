"""Config → pipeline settings."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.config import load_config
from emlogd.settings import pipeline_from_config

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "emlogd.yaml"


def test_pipeline_settings_from_the_example() -> None:
    """The example config gives the expected ports and UUT settings."""
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
