"""Config validation: the example loads; ≥ 30 invalid configs each name the key and line."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.errors import ConfigError
from emlogd.config import load_config, parse_config

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "emlogd.yaml"

BASE = """\
ports:
  - {name: emlog1, url: /dev/emlog1, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
"""


def test_example_config_loads() -> None:
    cfg = load_config(EXAMPLE)
    assert [p.name for p in cfg.ports] == ["emlog1", "emlog2", "dvl"]
    assert [(u.uut, u.model, u.lag_s) for u in cfg.calibration] == [
        ("emlog1", "EM3", None),
        ("emlog2", "EM3", None),
    ]
    assert cfg.port("dvl").protocol == "pd6"
    assert cfg.outputs.pty == "/run/emlogd/emlog0" and cfg.outputs.pty_mode == 0o660
    assert cfg.state_path == "/var/lib/emlogd/state.yaml"


def test_defaults_and_relative_paths(tmp_path: Path) -> None:
    f = tmp_path / "c.yaml"
    f.write_text(
        "ports:\n  - {name: a, url: links/a, protocol: nmea0183, role: uut}\n"
        "  - {name: b, url: socket://h:1, protocol: pd0, role: reference}\n"
        "calibration:\n  - {uut: a, reference: b, lag: 3.2}\n"
        "outputs: {pty: out/emlog0}\nstate_file: state.yaml\n"
    )
    cfg = load_config(f)
    assert cfg.ports[0].url == str(tmp_path / "links" / "a")
    assert cfg.ports[1].url == "socket://h:1"
    assert cfg.outputs.pty == str(tmp_path / "out" / "emlog0")
    assert cfg.state_path == str(tmp_path / "state.yaml")
    assert cfg.calibration[0].lag_s == 3.2
    assert cfg.ports[0].checksum == "required" and cfg.ports[0].baud == 9600


INVALID: list[tuple[str, str, str]] = [
    # (description, yaml text, expected fragment: the key and its problem)
    ("empty file", "", "empty"),
    ("not yaml", "ports: [", "not valid YAML"),
    ("top not a mapping", "- 1\n- 2\n", "expected a mapping"),
    ("unknown top key", BASE + "colour: red\n", "colour: unknown key"),
    ("no ports", "calibration: []\n", "missing required key 'ports'"),
    ("ports empty", "ports: []\n", "at least one port"),
    ("ports not a list", "ports: {a: 1}\n", "ports: expected a list"),
    ("port missing url", "ports:\n  - {name: a, protocol: pd6, role: uut}\n", "ports[0]: missing required key 'url'"),
    ("unknown port key", "ports:\n  - {name: a, url: x, protocol: pd6, role: aux, speed: 1}\n", "ports[0].speed: unknown key"),
    ("bad protocol", BASE.replace("pd6", "pd9"), "ports[1].protocol: 'pd9'"),
    ("bad role", BASE.replace("role: reference", "role: boss"), "ports[1].role: 'boss'"),
    ("baud not int", BASE.replace("role: uut}", "role: uut, baud: fast}"), "ports[0].baud: expected a number"),
    ("baud float", BASE.replace("role: uut}", "role: uut, baud: 4800.5}"), "ports[0].baud: expected an integer"),
    ("baud too low", BASE.replace("role: uut}", "role: uut, baud: 1}"), "ports[0].baud: 1 is out of range"),
    ("checksum policy", BASE.replace("role: uut}", "role: uut, checksum: maybe}"), "ports[0].checksum: 'maybe'"),
    ("max_length", BASE.replace("role: uut}", "role: uut, max_length: 5000}"), "ports[0].max_length"),
    ("stale timeout", BASE.replace("role: uut}", "role: uut, stale_timeout_s: 0}"), "ports[0].stale_timeout_s"),
    ("rate", BASE.replace("role: uut}", "role: uut, rate_hz: -1}"), "ports[0].rate_hz"),
    ("bad port name", BASE.replace("name: emlog1", "name: 'em log'").replace("uut: emlog1", "uut: x"), "ports[0].name"),
    ("duplicate port", BASE.replace("name: dvl", "name: emlog1").replace("reference: dvl", "reference: emlog1"), "duplicate port name"),
    ("duplicate key", "ports:\n  - name: a\n    name: b\n", "ports[0].name: duplicate key"),
    ("uut unknown", BASE.replace("uut: emlog1, reference", "uut: emlog9, reference"), "calibration[0].uut: no port named 'emlog9'"),
    ("reference unknown", BASE.replace("reference: dvl}", "reference: gps}"), "calibration[0].reference: no port named 'gps'"),
    ("uut with wrong role", BASE.replace("role: uut", "role: aux"), "calibration[0].uut: port 'emlog1' has role aux"),
    ("model", BASE.replace("reference: dvl}", "reference: dvl, model: EM5}"), "calibration[0].model: 'EM5'"),
    ("lag text", BASE.replace("reference: dvl}", "reference: dvl, lag: soon}"), "calibration[0].lag: expected auto or seconds"),
    ("lag too large", BASE.replace("reference: dvl}", "reference: dvl, lag: 99}"), "calibration[0].lag"),
    ("learn not bool", BASE.replace("reference: dvl}", "reference: dvl, learn: maybe}"), "calibration[0].learn: expected true or false"),
    ("reference field", BASE.replace("reference: dvl}", "reference: dvl, reference_field: gps}"), "calibration[0].reference_field"),
    ("speed from a DVL", BASE.replace("reference: dvl}", "reference: dvl, reference_field: speed}"), "speed needs an EMlog"),
    ("water from pd0", BASE.replace("pd6", "pd0").replace("reference: dvl}", "reference: dvl, reference_field: water}"), "water track (:WS) needs a pd6/pd13"),
    ("unknown param std", BASE.replace("reference: dvl}", "reference: dvl, max_param_std: {z: 1}}"), "max_param_std.z: unknown parameter"),
    ("negative q", BASE.replace("reference: dvl}", "reference: dvl, q_params: -1}"), "calibration[0].q_params"),
    ("calibrated twice", BASE + "  - {uut: emlog1, reference: dvl}\n", "calibration[1].uut: 'emlog1' is calibrated twice"),
    ("uut not nmea", BASE.replace("protocol: nmea0183, role: uut", "protocol: pd0, role: uut"), "must speak nmea0183"),
    ("talker", BASE + "outputs: {talker: vw}\n", "outputs.talker: 'vw' is not two uppercase letters"),
    ("maker", BASE + "outputs: {maker: EMLOG}\n", "outputs.maker"),
    ("tcp address", BASE + "outputs: {tcp: 'nowhere'}\n", "outputs.tcp: 'nowhere' is not HOST:PORT"),
    ("udp port", BASE + "outputs: {udp: 'host:70000'}\n", "outputs.udp"),
    ("unknown output key", BASE + "outputs: {serial: /dev/x}\n", "outputs.serial: unknown key"),
    ("log level", BASE + "log_level: loud\n", "log_level: 'loud'"),
    ("status interval", BASE + "status_interval_s: 0\n", "status_interval_s"),
    ("numeric key", BASE + "1: 2\n", "1: unknown key"),
    ("list key", BASE + "? [a, b]\n: 2\n", "keys must be strings"),
]  # fmt: skip


def test_at_least_thirty_invalid_configs() -> None:
    assert len(INVALID) >= 30


@pytest.mark.parametrize(("what", "text", "expected"), INVALID, ids=[c[0] for c in INVALID])
def test_invalid_config_names_file_line_and_key(what: str, text: str, expected: str) -> None:
    with pytest.raises(ConfigError) as exc:
        parse_config(text, "bad.yaml")
    msg = str(exc.value)
    assert msg.startswith("bad.yaml:"), msg
    assert msg.split(":")[1].isdigit(), msg
    assert expected in msg, msg


def test_line_numbers_point_at_the_problem() -> None:
    text = BASE + "  - uut: emlog1\n    reference: dvl\n    model: EM7\n"
    with pytest.raises(ConfigError, match=r"^bad.yaml:8: calibration\[1\].model"):
        parse_config(text, "bad.yaml")


def test_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")
