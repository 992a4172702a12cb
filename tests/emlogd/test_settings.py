"""Config → pipeline settings: every key declared once reaches the object that uses it."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from calib.estimate import Estimate
from drivers.errors import ConfigError
from emlogd.config import SECTIONS, Config, load_config, parse_config
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.keys import entries
from emlogd.pipeline.settings import REF_NOISE_MPS, UutSettings
from emlogd.settings import fusion_from_config, pipeline_from_config

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
    assert u.ref_stale_s == 3 and u.status_sentence_interval_s == 1


def test_the_pipeline_gets_the_configs_own_objects() -> None:
    """No copying layer: the pipeline's settings are the objects the config holds."""
    cfg = load_config(EXAMPLE)
    ports, uuts = pipeline_from_config(cfg)
    assert all(p is c.settings for p, c in zip(ports, cfg.ports, strict=True))
    assert all(u is c.settings for u, c in zip(uuts, cfg.calibration, strict=True))


# Every key of every section off its default: section -> key -> (value, where it must
# arrive, what must be there). Where: a root (below) and an attribute path. The first
# log ("log") sets every calibration key; the second ("log2") none, so that it shows the
# outputs keys every log inherits.
SAME = object()
OFF_DEFAULT: dict[str, dict[str, tuple[Any, str, Any]]] = {
    "ports[].": {
        "name": ("log", "port.name", SAME),
        "protocol": ("nmea0183", "port.protocol", SAME),
        "checksum": ("optional", "port.checksum", SAME),
        "max_length": (100, "port.max_length", SAME),
        "stale_timeout_s": (7.0, "log.ref_stale_s", SAME),
        "url": ("dev/log", "portcfg.url", "TMP/dev/log"),
        "role": ("uut", "portcfg.role", SAME),
        "baud": (4800, "portcfg.baud", SAME),
        "rate_hz": (2.0, "portcfg.rate_hz", SAME),
        "rest_s": (0.1, "portcfg.rest_s", SAME),
    },
    "calibration[].": {
        "uut": ("log", "log.port", SAME),
        "reference": ("log", "log.reference_port", SAME),
        "model": ("EM2", "log.model", SAME),
        "reference_field": ("gnss", "log.reference_field", SAME),
        "uut_source": ("VBW", "log.uut_source", SAME),
        "talker": ("VD", "log.talker", SAME),
        "misalign_deg": (2.5, "log.misalign_deg", SAME),
        "transverse_scale": (0.05, "log.transverse_scale", SAME),
        "transverse_bias_mps": (0.1, "log.transverse_bias_mps", SAME),
        "axes": (2, "log.axes", SAME),
        "component": ("magnitude", "log.component", SAME),
        "current": (False, "log.current", SAME),
        "heading": ("log2", "log.heading", SAME),
        "magnetic_variation_deg": (-3.5, "log.magnetic_variation_deg", SAME),
        "lag": (2.5, "log.lag_s", SAME),
        "lag_window_s": (100.0, "log.lag_window_s", SAME),
        "max_lag_s": (5.0, "log.max_lag_s", SAME),
        "learn": (False, "log.learn", SAME),
        "apply": (False, "log.apply", SAME),
        "min_ref_speed_mps": (0.7, "log.min_ref_speed_mps", SAME),
        "min_sog_mps": (1.1, "log.min_sog_mps", SAME),
        "max_param_std": ({"a": 0.5, "m": 0.5, "b": 0.5}, "log.max_param_std", SAME),
        "excitation_half_life_samples": (99.0, "log.excitation_half_life_samples", SAME),
        "r_raw_mps": (0.2, "log.kf.r_raw_mps2", 0.2**2),
        "r_ref_mps": (0.4, "log.kf.r_ref_mps2", 0.4**2),
        "q_params": (1e-9, "log.kf.q_params", SAME),
        "p0": (0.5, "log.kf.p0", SAME),
        "current_psd_m2ps3": (1e-6, "log.kf.current_psd_m2ps3", SAME),
        "persist_interval_s": (7.0, "log.persist_interval_s", SAME),
        "persist_min_change_sigma": (3.0, "log.persist_min_change_sigma", SAME),
        "persist_min_change_abs": (0.01, "log.persist_min_change_abs", SAME),
        "validation_s": (33.0, "log.validation_s", SAME),
        "average_s": (5.0, "log.average_s", SAME),
        "recheck_s": (44.0, "log.recheck_s", SAME),
        "gate_nis": (9.0, "log.gate_nis", SAME),
        "relearn_gates": (7, "log.relearn_gates", SAME),
        "low_speed_mps": (0.5, "log.low_speed_mps", SAME),
        "max_speed_mps": (12.0, "log.envelope.max_speed_mps", SAME),
        "stuck_s": (30.0, "log.stuck_s", SAME),
        "zero_s": (20.0, "log.zero_s", SAME),
        "max_accel_mps2": (3.0, "log.max_accel_mps2", SAME),
        "max_turn_rate_dps": (20.0, "log.max_turn_rate_dps", SAME),
        "max_reading_accel_mps2": (0.5, "log.limits.max_reading_accel_mps2", SAME),
        "max_rate_hz": (5.0, "log.limits.max_rate_hz", SAME),
        "pty": ("out/log", "logcfg.outputs.pty", "TMP/out/log"),
        "tcp": (":10111", "logcfg.outputs.tcp", SAME),
        "udp": ("10.0.0.255:10111", "logcfg.outputs.udp", SAME),
    },
    "outputs.": {
        "pty": ("out/all", "cfg.outputs.pty", "TMP/out/all"),
        "pty_mode": (0o600, "cfg.outputs.pty_mode", SAME),
        "pty_group": ("nmea", "cfg.outputs.pty_group", SAME),
        "tcp": (":10110", "cfg.outputs.tcp", SAME),
        "tcp_max_clients": (5, "cfg.outputs.tcp_max_clients", SAME),
        "tcp_max_pending_bytes": (4096, "cfg.outputs.tcp_max_pending_bytes", SAME),
        "tcp_stall_s": (2.5, "cfg.outputs.tcp_stall_s", SAME),
        "udp": ("10.0.0.255:10110", "cfg.outputs.udp", SAME),
        "stdout": (True, "cfg.outputs.stdout", SAME),
        "talker": ("II", "log2.talker", SAME),
        "maker": ("ABC", "log2.maker", SAME),
        "status_sentence_interval_s": (2.5, "log2.status_sentence_interval_s", SAME),
        "speed": ("both", "fusion.only", False),
        "fused_talker": ("VW", "fusion.talker", SAME),
        "fused_gate_chi2": (9.0, "fusion.gate_chi2", SAME),
        "fused_hold_s": (5.0, "fusion.hold_s", SAME),
        "fused_rejoin_s": (60.0, "fusion.rejoin_s", SAME),
        "fused_max_current_mps": (2.5, "fusion.max_current_mps", SAME),
    },
    "": {
        "state_file": ("s/state.yaml", "cfg.state_path", "TMP/s/state.yaml"),
        "control_socket": ("run/c.sock", "cfg.control_socket", "TMP/run/c.sock"),
        "status_socket": ("run/s.sock", "cfg.status_socket", "TMP/run/s.sock"),
        "log_format": ("json", "cfg.log_format", SAME),
        "log_level": ("debug", "cfg.log_level", SAME),
        "status_log_interval_s": (3.0, "cfg.status_log_interval_s", SAME),
    },
}
FIRST = {"": "", "ports[].": "ports", "calibration[].": "calibration", "outputs.": "outputs"}


def _document() -> dict[str, Any]:
    """The config with every key off its default, as a YAML document."""
    doc: dict[str, Any] = {k: v for k, (v, _, _) in OFF_DEFAULT[""].items()}
    doc["ports"] = [
        {k: v for k, (v, _, _) in OFF_DEFAULT["ports[]."].items()},
        {"name": "log2", "url": "/dev/log2", "protocol": "nmea0183", "role": "uut"},
    ]
    doc["calibration"] = [
        {k: v for k, (v, _, _) in OFF_DEFAULT["calibration[]."].items()},
        {"uut": "log2", "reference": "log2", "reference_field": "gnss"},
    ]
    doc["outputs"] = {k: v for k, (v, _, _) in OFF_DEFAULT["outputs."].items()}
    return doc


def _roots(cfg: Config) -> dict[str, Any]:
    """Where the keys arrive: the pipeline built from ``cfg``, and the config (the daemon's)."""
    pipeline = Pipeline(*pipeline_from_config(cfg), fusion=fusion_from_config(cfg))
    return {
        "port": pipeline.ports["log"],
        "log": pipeline.uuts["log"].s,
        "log2": pipeline.uuts["log2"].s,
        "fusion": pipeline.fusion.s if pipeline.fusion is not None else None,
        "portcfg": cfg.ports[0],
        "logcfg": cfg.calibration[0],
        "cfg": cfg,
    }


def _at(roots: dict[str, Any], where: str) -> Any:
    root, *attrs = where.split(".")
    obj = roots[root]
    for a in attrs:
        obj = getattr(obj, a) if obj is not None else None
    return obj


def _load(tmp_path: Path, doc: dict[str, Any]) -> Config:
    f = tmp_path / "c.yaml"
    f.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_config(f)


def test_the_table_has_every_key() -> None:
    """Each declared key has a case in OFF_DEFAULT (a new key needs one)."""
    declared = {(prefix, e.name) for prefix, cls in SECTIONS for e in entries(cls)}
    cased = {(prefix, k) for prefix, keys in OFF_DEFAULT.items() for k in keys}
    assert cased == declared


def test_every_key_reaches_the_pipeline_or_the_daemon(tmp_path: Path) -> None:
    """A config with every key off its default builds a pipeline in which each key's value
    arrived where it is used; without the key the value there is another one."""
    doc = _document()
    roots = _roots(_load(tmp_path, doc))
    for prefix, keys in OFF_DEFAULT.items():
        for k, (value, where, expected) in keys.items():
            want = value if expected is SAME else expected
            if isinstance(want, str) and want.startswith("TMP/"):
                want = str(tmp_path / want[4:])
            got = _at(roots, where)
            assert got == (pytest.approx(want) if isinstance(want, float) else want), prefix + k
            required = {e.name for _, c in SECTIONS for e in entries(c) if e.required}
            if k in required:
                continue
            without = copy.deepcopy(doc)
            section = without if prefix == "" else without[FIRST[prefix]]
            del (section[0] if isinstance(section, list) else section)[k]
            try:
                other = _at(_roots(_load(tmp_path, without)), where)
            except ConfigError as exc:
                # gnss is what lets a log be its own reference
                assert k == "reference_field", (prefix + k, exc)
                continue
            assert other != want, f"{prefix}{k}: the test value is the default"


def test_defaults_are_the_pipelines() -> None:
    """A config that sets nothing gives the pipeline's own defaults (one declaration)."""
    text = (
        "ports:\n  - {name: log, url: /dev/log, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}\n"
        "calibration:\n  - {uut: log, reference: dvl, current: false}\n"
    )
    _, (u,) = pipeline_from_config(parse_config(text))
    assert u == UutSettings(port="log", reference_port="dvl")
    assert u.kf == UutSettings(port="log", reference_port="dvl").kf


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


def test_one_builder_for_run_reload_and_replay() -> None:
    """build_pipeline gives the config's pipeline started from a state: the calibration
    of each UUT's model (another model's kept aside), replay's learning switch, and the
    fused output as the config asks."""
    from calib.models import Params
    from emlogd.pipeline.calibration import Calibration
    from emlogd.settings import build_pipeline

    cfg = load_config(EXAMPLE)
    em3 = Calibration(
        "emlog1", Estimate(Params("EM3", m=0.05, b_mps=0.1), {"m": 0.01, "b": 0.01}), 3.2
    )
    em4 = Calibration("emlog1", Estimate(Params("EM4", a_spm=0.01, m=0.05, b_mps=0.1), {}), 3.0)
    p = build_pipeline(cfg, {"emlog1": em4}, [em3], learn=False)
    status = p.status()["uuts"]
    assert isinstance(status, dict)
    # the model's own calibration is the one kept (applied once it re-validates)
    assert status["emlog1"]["kept"] == {"m": 0.05, "b": 0.1}
    assert status["emlog1"]["lag_s"] == 3.2
    assert [c.params.model for c in p.other_calibrations()] == ["EM4"]
    assert all(not u.cal.learn_on for u in p.uuts.values())
    assert (p.fusion is None) == (cfg.outputs.speed == "each")
    assert list(p.decoders) == [port.name for port in cfg.ports]
