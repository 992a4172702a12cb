"""Config → pipeline settings."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from emlogd.config import UUT_SPEC, load_config, parse_config
from emlogd.pipeline.core import REF_NOISE_MPS, UutSettings
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


# every calibration key off its default: (yaml key, value, where it must arrive)
OFF_DEFAULT: dict[str, tuple[str, object]] = {
    "model": ("EM2", "model"),
    "reference_field": ("gnss", "reference_field"),
    "uut_source": ("VBW", "uut_source"),
    "talker": ("VD", "talker"),
    "component": ("magnitude", "component"),
    "current": (True, "current"),
    "heading": ("log", "heading"),
    "magnetic_variation_deg": (-3.5, "magnetic_variation_deg"),
    "lag": (2.5, "lag_s"),
    "lag_window_s": (100.0, "lag_window_s"),
    "max_lag_s": (5.0, "max_lag_s"),
    "learn": (False, "learn"),
    "apply": (False, "apply"),
    "min_ref_speed_mps": (0.7, "min_ref_speed_mps"),
    "min_sog_mps": (1.1, "min_sog_mps"),
    "max_param_std": ({"a": 0.5, "m": 0.5, "b": 0.5}, "max_param_std"),
    "excitation_half_life_samples": (99.0, "excitation_half_life_samples"),
    "r_raw_mps": (0.2, "kf.r_raw_mps2"),
    "r_ref_mps": (0.4, "kf.r_ref_mps2"),
    "q_params": (1e-9, "kf.q_params"),
    "p0": (0.5, "kf.p0"),
    "current_psd_m2ps3": (1e-6, "kf.current_psd_m2ps3"),
    "persist_interval_s": (7.0, "persist_interval_s"),
    "persist_min_change_sigma": (3.0, "persist_min_change_sigma"),
    "persist_min_change_abs": (0.01, "persist_min_change_abs"),
    "validation_s": (33.0, "validation_s"),
    "average_s": (5.0, "average_s"),
    "recheck_s": (44.0, "recheck_s"),
    "gate_nis": (9.0, "gate_nis"),
    "relearn_gates": (7, "relearn_gates"),
    "low_speed_mps": (0.5, "low_speed_mps"),
    "max_speed_mps": (12.0, "envelope.max_speed_mps"),
    "stuck_s": (30.0, "stuck_s"),
    "zero_s": (20.0, "zero_s"),
    "max_accel_mps2": (3.0, "max_accel_mps2"),
    "max_turn_rate_dps": (20.0, "max_turn_rate_dps"),
}
SQUARED = {"kf.r_raw_mps2", "kf.r_ref_mps2"}


def _get(obj: object, path: str) -> object:
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def test_every_calibration_key_reaches_the_pipeline(tmp_path: Path) -> None:
    """Each calibration key, set off its default, arrives in the pipeline's settings."""
    daemon_only = {"pty", "tcp", "udp"}  # a log's own outputs: the daemon's, not the pipeline's
    assert set(OFF_DEFAULT) == set(UUT_SPEC) - {"uut", "reference"} - daemon_only, (
        "a key has no case here"
    )
    default = UutSettings(port="", reference_port="")
    lines = [
        "ports:",
        "  - {name: log, url: /dev/log, protocol: nmea0183, role: uut}",
        "calibration:",
        "  - uut: log",
        "    reference: log",
    ]
    for key, (value, where) in OFF_DEFAULT.items():
        before = _get(default, where)
        expected = value**2 if where in SQUARED else value  # type: ignore[operator]
        assert before != expected, f"{key}: the test value is the default"
        lines.append(
            f"    {key}: {yaml.safe_dump(value, default_flow_style=True).split(chr(10))[0]}"
        )
    f = tmp_path / "c.yaml"
    f.write_text("\n".join(lines) + "\n")
    _, (u,) = pipeline_from_config(load_config(f))
    for key, (value, where) in OFF_DEFAULT.items():
        expected = value**2 if where in SQUARED else value  # type: ignore[operator]
        got = _get(u, where)
        assert got == pytest.approx(expected) if isinstance(expected, float) else got == expected, (
            key
        )


def test_defaults_are_the_pipelines() -> None:
    """A config that sets nothing gives the pipeline's own defaults (one declaration)."""
    text = (
        "ports:\n  - {name: log, url: /dev/log, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}\n"
        "calibration:\n  - {uut: log, reference: dvl}\n"
    )
    _, (u,) = pipeline_from_config(parse_config(text))
    default = UutSettings(port="log", reference_port="dvl")
    for f in dataclasses.fields(UutSettings):
        if f.name in ("talker", "maker", "status_interval_s", "kf_config", "current"):
            continue
        assert getattr(u, f.name) == getattr(default, f.name), f.name
    assert u.kf == default.kf


def test_gnss_reference_noise_default() -> None:
    """Without r_ref_mps a GNSS reference gets its own noise, a DVL its own."""
    text = (
        "ports:\n  - {name: bus, url: /dev/bus, protocol: nmea0183, role: uut}\n"
        "calibration:\n  - {uut: bus, reference: bus, reference_field: gnss, current: true}\n"
    )
    _, (u,) = pipeline_from_config(parse_config(text))
    assert u.kf.r_ref_mps2 == pytest.approx(REF_NOISE_MPS["gnss"] ** 2)
    assert UutSettings(port="a", reference_port="b").kf.r_ref_mps2 == pytest.approx(0.01**2)


@pytest.mark.parametrize(
    ("protocol", "extra", "expected"),
    [
        ("pd6", "", True),
        ("pd0", "", True),
        ("pd4", "", False),
        ("pd4", ", heading: hdg", True),
        ("nmea0183", "", False),
        ("pd6", ", current: false", False),
        ("pd4", ", current: true", True),
    ],
)
def test_current_auto_follows_the_heading(protocol: str, extra: str, expected: bool) -> None:
    """current: auto estimates the current where a heading is known to come: a DVL output
    that carries one (PD6, PD0), or a named heading port; not from PD4 or $PRTI01 alone."""
    text = (
        "ports:\n  - {name: log, url: /dev/log, protocol: nmea0183, role: uut}\n"
        f"  - {{name: dvl, url: /dev/dvl, protocol: {protocol}, role: reference}}\n"
        "  - {name: hdg, url: /dev/hdg, protocol: nmea0183, role: aux}\n"
        f"calibration:\n  - {{uut: log, reference: dvl{extra}}}\n"
    )
    _, (u,) = pipeline_from_config(parse_config(text))
    assert u.current is expected
