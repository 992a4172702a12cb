"""Config validation: the example loads; ≥ 30 invalid configs each name the key and line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from drivers.errors import ConfigError
from emlogd.config import (
    SECTIONS,
    UutConfig,
    load_config,
    parse_config,
)
from emlogd.configdump import dump_config
from emlogd.pipeline.keys import entries

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "emlogd.yaml"
README = Path(__file__).resolve().parents[2] / "README.md"

BASE = """\
ports:
  - {name: emlog1, url: /dev/emlog1, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
"""


def test_example_config_loads() -> None:
    """examples/emlogd.yaml loads with its three ports, two EM3 calibrations with automatic lag, the
    pty path and mode, and the state path."""
    cfg = load_config(EXAMPLE)
    assert [p.name for p in cfg.ports] == ["emlog1", "emlog2", "dvl"]
    assert [(u.uut, u.settings.model, u.settings.lag_s) for u in cfg.calibration] == [
        ("emlog1", "EM3", None),
        ("emlog2", "EM3", None),
    ]
    assert cfg.port("dvl").protocol == "pd6"
    assert cfg.outputs.pty == "/run/emlogd/emlog0" and cfg.outputs.pty_mode == 0o660
    assert cfg.state_path == "/var/lib/emlogd/state.yaml"


def test_defaults_and_relative_paths(tmp_path: Path) -> None:
    """Device, pty and state paths resolve against the config file's directory, socket URLs are
    kept, and checksum and baud default to required and 9600."""
    f = tmp_path / "c.yaml"
    f.write_text(
        "ports:\n  - {name: a, url: links/a, protocol: nmea0183, role: uut}\n"
        "  - {name: b, url: socket://10.0.0.5:1, protocol: pd0, role: reference}\n"
        "calibration:\n  - {uut: a, reference: b, lag: 3.2}\n"
        "outputs: {pty: out/emlog0}\nstate_file: state.yaml\n"
    )
    cfg = load_config(f)
    assert cfg.ports[0].url == str(tmp_path / "links" / "a")
    assert cfg.ports[1].url == "socket://10.0.0.5:1"
    assert cfg.outputs.pty == str(tmp_path / "out" / "emlog0")
    assert cfg.state_path == str(tmp_path / "state.yaml")
    assert cfg.calibration[0].settings.lag_s == 3.2
    assert cfg.ports[0].settings.checksum == "required" and cfg.ports[0].baud == 9600


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
    ("socket host name", BASE.replace("/dev/dvl", "socket://dvl.local:10110"), "ports[1].url: 'socket://dvl.local:10110': a socket:// input needs an IP address"),
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
    ("rest negative", BASE.replace("role: reference", "role: reference, rest_s: -0.01"), "ports[1].rest_s"),
    ("rest too long", BASE.replace("role: reference", "role: reference, rest_s: 2"), "ports[1].rest_s"),
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
    ("status log interval", BASE + "status_log_interval_s: 0\n", "status_log_interval_s: 0 is out of range"),
    ("status sentence interval", BASE + "outputs: {status_sentence_interval_s: -1}\n", "outputs.status_sentence_interval_s: -1 is out of range"),
    ("param std not a map", BASE.replace("reference: dvl}", "reference: dvl, max_param_std: 0.1}"), "calibration[0].max_param_std: expected a mapping"),
    ("param std too large", BASE.replace("reference: dvl}", "reference: dvl, max_param_std: {m: 11}}"), "calibration[0].max_param_std.m: 11 is out of range"),
    ("scalar given a list", BASE.replace("reference: dvl}", "reference: dvl, gate_nis: [1]}"), "calibration[0].gate_nis: expected a single value"),
    ("numeric key", BASE + "1: 2\n", "1: unknown key"),
    ("list key", BASE + "? [a, b]\n: 2\n", "keys must be strings"),
    ("negative lag", BASE.replace("reference: dvl}", "reference: dvl, lag: -1.5}"), "calibration[0].lag: expected auto or seconds in [0, 30]"),
    ("lag beyond max_lag_s", BASE.replace("reference: dvl}", "reference: dvl, lag: 12, max_lag_s: 5}"), "calibration[0].lag: 12.0 s is beyond max_lag_s"),
    ("reference with role aux", BASE.replace("role: reference", "role: aux"), "calibration[0].reference: port 'dvl' has role aux, not reference"),
    ("DVL reference with role uut", BASE.replace("role: reference", "role: uut"), "calibration[0].reference: port 'dvl' has role uut, not reference"),
    ("water from an EMlog", BASE.replace("protocol: pd6", "protocol: nmea0183").replace("reference: dvl}", "reference: dvl, reference_field: water}"), "calibration[0].reference_field: water track (:WS) needs a pd6/pd13 reference, 'dvl' is nmea0183"),
    ("reference is the uut", BASE.replace("reference: dvl}", "reference: emlog1}"), "calibration[0].reference: the reference must be another port"),
    ("tcp non-ascii digits", BASE + "outputs: {tcp: ':\u0661\u0660'}\n", "outputs.tcp"),
    ("pty_mode too wide", BASE + "outputs: {pty_mode: 01777}\n", "outputs.pty_mode: 1023 is out of range"),
    ("rate infinite", BASE.replace("role: uut}", "role: uut, rate_hz: .inf}"), "ports[0].rate_hz: inf is out of range"),
    ("calibration not a list", BASE.replace("calibration:\n  - {uut: emlog1, reference: dvl}\n", "calibration: {uut: emlog1}\n"), "calibration: expected a list"),
    ("outputs a list", BASE + "outputs: [a]\n", "outputs: expected a mapping"),
    ("url a number", BASE.replace("url: /dev/dvl", "url: 7"), "ports[1].url: expected a non-empty string"),
    ("yaml merge key", BASE + "x: &d {talker: VW}\noutputs: {<<: *d}\n", "x: unknown key"),
    ("pty path with a NUL", BASE + 'outputs: {pty: "out/e\\0"}\n', "outputs.pty: 'out/e\\x00': a path cannot hold a NUL character"),
    ("control socket with a NUL", BASE + 'control_socket: "run/c\\0.sock"\n', "control_socket: 'run/c\\x00.sock': a path cannot hold a NUL character"),
    ("url of no pyserial scheme", BASE.replace("/dev/dvl", "socet://10.0.0.5:1"), "ports[1].url: invalid URL 'socet://10.0.0.5:1': invalid URL, protocol 'socet' not known"),
    ("rfc2217 url", BASE.replace("/dev/dvl", "rfc2217://10.0.0.5:2217"), "ports[1].url: 'rfc2217://10.0.0.5:2217': pyserial opens a rfc2217:// input in the daemon's one thread"),
    ("socket host name in capitals", BASE.replace("/dev/dvl", "SOCKET://dvl.local:10110"), "ports[1].url: 'SOCKET://dvl.local:10110': a socket:// input needs an IP address"),
    ("state file a directory", BASE + "state_file: /var/lib/emlogd/\n", "state_file: '/var/lib/emlogd/' is not a file's path"),
    ("state file a dot", BASE + "state_file: state/.\n", "state_file: 'state/.' is not a file's path"),
    ("status socket at the control socket", BASE + "control_socket: run/c.sock\nstatus_socket: run/./c.sock\n", "status_socket: the same path as control_socket"),
    ("pty at the state file", BASE + "state_file: /var/lib/emlogd/s\noutputs: {pty: /var/lib/emlogd/s}\n", "outputs.pty: the same path as state_file"),
    ("a log's pty the shared one", BASE.replace("reference: dvl}", "reference: dvl, pty: /run/e0}") + "outputs: {pty: /run/e0}\n", "calibration[0].pty: the same path as outputs.pty"),
    ("a port reading the output pty", BASE.replace("/dev/dvl", "/run/e0") + "outputs: {pty: /run/e0}\n", "ports[1].url: the same place as outputs.pty (/run/e0): a port cannot read the daemon's own output"),
    ("a log's tcp the shared one", BASE.replace("reference: dvl}", "reference: dvl, tcp: '127.0.0.1:10110'}") + "outputs: {tcp: '127.0.0.1:10110'}\n", "outputs.tcp: each TCP output must listen on its own port"),
    ("a log's tcp on a wildcard's port", BASE.replace("reference: dvl}", "reference: dvl, tcp: '127.0.0.1:10110'}") + "outputs: {tcp: ':10110'}\n", "outputs.tcp: each TCP output must listen on its own port"),
    ("udp host name", BASE + "outputs: {udp: 'display.local:10110'}\n", "outputs.udp: 'display.local:10110': needs an IPv4 address, not a host name"),
    ("tcp host name", BASE + "outputs: {tcp: 'bridge.local:10110'}\n", "outputs.tcp: 'bridge.local:10110': needs an IPv4 address, not a host name"),
    ("a log's tcp host name", BASE.replace("reference: dvl}", "reference: dvl, tcp: 'localhost:10111'}"), "calibration[0].tcp: 'localhost:10111': needs an IPv4 address"),
    ("a log's udp host name", BASE.replace("reference: dvl}", "reference: dvl, udp: 'localhost:10110'}"), "calibration[0].udp: 'localhost:10110': needs an IPv4 address"),
]  # fmt: skip


def test_at_least_thirty_invalid_configs() -> None:
    """The table of invalid configs keeps at least thirty cases."""
    assert len(INVALID) >= 30


@pytest.mark.parametrize(("what", "text", "expected"), INVALID, ids=[c[0] for c in INVALID])
def test_invalid_config_names_file_line_and_key(what: str, text: str, expected: str) -> None:
    """Each invalid config raises a ConfigError that starts with file:line: and names the key and
    its problem."""
    with pytest.raises(ConfigError) as exc:
        parse_config(text, "bad.yaml")
    msg = str(exc.value)
    assert msg.startswith("bad.yaml:"), msg
    assert msg.split(":")[1].isdigit(), msg
    assert expected in msg, msg


def test_line_numbers_point_at_the_problem() -> None:
    """An error in the second calibration entry gives the line of the offending key."""
    text = BASE + "  - uut: emlog1\n    reference: dvl\n    model: EM7\n"
    with pytest.raises(ConfigError, match=r"^bad.yaml:8: calibration\[1\].model"):
        parse_config(text, "bad.yaml")


def test_unreadable_file(tmp_path: Path) -> None:
    """A missing config file is a ConfigError saying it cannot be read."""
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")


BLOCK = """\
ports:
  - name: emlog1
    url: /dev/emlog1
    protocol: nmea0183
    role: uut
  - name: emlog2
    url: /dev/emlog2
    protocol: nmea0183
    role: uut
  - name: dvl
    url: /dev/dvl
    protocol: pd6
    role: reference
calibration:
  - model: EM3
    uut: emlog1
    reference: dvl
"""


@pytest.mark.parametrize(
    ("old", "new", "line", "key"),
    [
        ("    reference: dvl\n", "    reference: gps\n", 17, "calibration[0].reference"),
        ("    uut: emlog1\n", "    uut: dvl\n", 16, "calibration[0].uut"),
        ("protocol: pd6", "protocol: pd9", 12, "ports[2].protocol"),
        ("name: emlog2", "name: emlog1", 6, "ports[1].name"),
        ("    reference: dvl\n", "    reference: dvl\n    lag: 20\n", 18, "calibration[0].lag"),
        (
            "    reference: dvl\n",
            "    reference: dvl\n    reference_field: speed\n",
            18,
            "calibration[0].reference_field",
        ),
    ],
)
def test_cross_check_errors_point_at_the_value(old: str, new: str, line: int, key: str) -> None:
    """A cross-check error gives the line of the offending value, not of its entry."""
    assert old in BLOCK
    with pytest.raises(ConfigError) as exc:
        parse_config(BLOCK.replace(old, new, 1), "bad.yaml")
    assert str(exc.value).startswith(f"bad.yaml:{line}: {key}:"), str(exc.value)


def test_an_emlog_with_role_uut_may_be_the_speed_reference() -> None:
    """EMlog2 calibrated against EMlog1 (reference_field speed) is a valid setup."""
    cfg = parse_config(
        BLOCK
        + "  - {uut: emlog2, reference: emlog1, reference_field: speed, lag: 0.4, max_lag_s: 2,\n"
        "     talker: VM}\n"
    )
    assert [(u.uut, u.reference, u.settings.reference_field) for u in cfg.calibration] == [
        ("emlog1", "dvl", "bottom"),
        ("emlog2", "emlog1", "speed"),
    ]


@pytest.mark.parametrize(
    ("protocol", "field", "current"),
    [
        ("pd6", "bottom", True),
        ("pd13", "water", True),
        ("pd0", "bottom", True),
        ("pd5", "bottom", True),
        ("pd4", "bottom", False),
        ("nmea0183", "bottom", False),
        ("nmea0183", "speed", False),
        ("nmea0183", "gnss", True),
    ],
)
def test_current_auto_follows_whether_the_reference_carries_a_heading(
    protocol: str, field: str, current: bool
) -> None:
    """With no heading port, ``current: auto`` estimates the current when the reference's
    protocol carries the heading with its track (PD6/PD13, PD0, PD5: not PD4, not Rowe PRTI01
    nor an EMlog) or the reference is GNSS."""
    text = BASE.replace("protocol: pd6", f"protocol: {protocol}").replace(
        "reference: dvl}", f"reference: dvl, reference_field: {field}}}"
    )
    (uut,) = parse_config(text).calibration
    assert uut.settings.current is current


def test_dump_round_trips_non_defaults(tmp_path: Path) -> None:
    """Every non-default value survives dump and reload (lag in seconds, nulls, maps)."""
    text = (
        BLOCK.replace("role: uut\n", "role: uut\n    checksum: optional\n    rate_hz: 2.5\n", 1)
        + "    lag: 3.2\n    learn: false\n    max_param_std: {m: 0.1}\n    q_params: 1.0e-9\n"
        + "outputs: {pty: null, pty_group: nmea, tcp: ':10110', udp: '10.0.0.255:10110', talker: II}\n"
        + "log_format: json\nstate_file: s/state.yaml\nstatus_socket: run/status.sock\n"
    )
    f = tmp_path / "c.yaml"
    f.write_text(text)
    cfg = load_config(f)
    assert cfg.calibration[0].settings.lag_s == 3.2 and cfg.outputs.pty is None
    assert cfg.state_path == str(tmp_path / "s" / "state.yaml")
    assert cfg.status_socket == str(tmp_path / "run" / "status.sock")
    assert parse_config(dump_config(cfg), cfg.path) == cfg


def test_the_gnss_example_takes_a_sailing_yachts_speeds() -> None:
    """examples/emlogd-gnss.yaml (a yacht's instrument bus against its GNSS) reads logs to
    29 kn: a racing yacht's 20 kn is in its range, where the default range (8 m/s, a
    survey vehicle's) would refuse those readings and leave the autopilot silent."""
    cfg = load_config(EXAMPLE.with_name("emlogd-gnss.yaml"))
    (uut,) = cfg.calibration
    assert uut.settings.envelope.max_speed_mps >= 20 * 0.514444
    assert uut.settings.current and uut.settings.reference_field == "gnss"


def test_every_calibration_key_is_shown_in_the_example() -> None:
    """examples/emlogd.yaml shows every calibration key."""
    text = EXAMPLE.read_text()
    names = [e.name for e in entries(UutConfig)]
    missing = [k for k in names if f"    {k}:" not in text and f"  - {k}:" not in text]
    assert missing == []


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            BASE + "status_interval_s: 10\n",
            "bad.yaml:6: status_interval_s: renamed: use status_log_interval_s",
        ),
        (
            BASE + "outputs:\n  status_interval_s: 1\n",
            "bad.yaml:7: outputs.status_interval_s: renamed: use "
            "outputs.status_sentence_interval_s",
        ),
    ],
)
def test_renamed_keys_name_the_new_key(text: str, expected: str) -> None:
    """The two keys once both called status_interval_s are refused with a one-line error that
    names the new key."""
    with pytest.raises(ConfigError) as exc:
        parse_config(text, "bad.yaml")
    assert str(exc.value) == expected


def test_every_key_has_a_doc_and_a_check() -> None:
    """Each key's declaration carries a sentence of doc and words for its values."""
    for prefix, cls in SECTIONS:
        for e in entries(cls):
            assert e.key.doc.endswith(".") and e.key.check.text, prefix + e.name
            assert "|" not in e.key.doc + e.key.check.text, prefix + e.name


TWO_LOGS = """\
ports:
  - {name: e1, url: /dev/e1, protocol: nmea0183, role: uut}
  - {name: e2, url: /dev/e2, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: e1, reference: dvl}
  - {uut: e2, reference: dvl%s}
outputs: {pty: /run/emlogd/emlog0%s}
"""


@pytest.mark.parametrize(
    ("log2", "outputs", "clash"),
    [
        ("", "", "log 'e1' and log 'e2' both send talker 'VW' to pty /run/emlogd/emlog0"),
        (", talker: VM", "", None),
        (", pty: /run/emlogd/e2", "", None),
        ("", ", speed: fused", None),
        (", tcp: ':10111'", ", speed: both", None),
        (", udp: '10.0.0.255:10110'", ", udp: '10.0.0.255:10110'", "to udp 10.0.0.255:10110"),
    ],
)
def test_two_speeds_under_one_talker_on_one_output_are_refused(
    tmp_path: Path, log2: str, outputs: str, clash: str | None
) -> None:
    """Two logs' corrected sentences under one talker on one output are refused, naming
    both and the way out; distinct talkers, a log's own output, or the fused speed alone
    load."""
    f = tmp_path / "c.yaml"
    f.write_text(TWO_LOGS % (log2, outputs))
    if clash is None:
        load_config(f)
        return
    with pytest.raises(ConfigError) as info:
        load_config(f)
    msg = str(info.value)
    assert clash in msg and "outputs.speed" in msg and "own talker and output" in msg


def test_the_local_recipe_config_is_the_example_at_ten_times_real_time(tmp_path: Path) -> None:
    """examples/emlogd-local.yaml (the fake-device recipe, `fake --speed 10`): each log's
    lag is the simulator's latency / 10, its windows and timers the defaults / 10, a
    reading's acceleration limit the default x 10², its rate ceiling 20 Hz x 10, and the
    two logs' speeds under their own talkers on their own outputs."""
    from emlogd.offline.demo import LATENCIES_S
    from emlogd.pipeline.readings import DEFAULT_MAX_RATE_HZ

    k = 10.0
    local = yaml.safe_load(dump_config(load_config(EXAMPLE.with_name("emlogd-local.yaml"))))
    plain = tmp_path / "c.yaml"
    plain.write_text(BLOCK)
    (default,) = yaml.safe_load(dump_config(load_config(plain)))["calibration"]
    for c in local["calibration"]:
        assert c["lag"] == pytest.approx(LATENCIES_S[c["uut"]] / k)
        for name in ("lag_window_s", "validation_s", "recheck_s", "stuck_s", "zero_s"):
            assert c[name] == pytest.approx(default[name] / k), name
        accel = default["max_reading_accel_mps2"] * k * k
        assert c["max_reading_accel_mps2"] == pytest.approx(accel)
        assert c["max_rate_hz"] == pytest.approx(DEFAULT_MAX_RATE_HZ * k)
    assert {c["talker"] for c in local["calibration"]} == {"VW", "VM"}


def test_two_logs_under_one_talker_without_declared_outputs_load(tmp_path: Path) -> None:
    """A config with no outputs section (written for replay and the offline commands)
    is not refused for its two logs' shared talker; the same with the outputs declared is."""
    f = tmp_path / "c.yaml"
    text = TWO_LOGS % ("", "")
    f.write_text(text.split("outputs:", 1)[0])
    assert len(load_config(f).calibration) == 2
    f.write_text(text)
    with pytest.raises(ConfigError):
        load_config(f)


def _laughs(levels: int) -> str:
    """A YAML flow list of ``levels`` anchors, each nine aliases of the one before:
    9**levels strings if the aliases were expanded ("billion laughs")."""
    names = "abcdefghijklmnop"
    items = ['&a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    for k in range(1, levels):
        items.append(f"&{names[k]} [{', '.join(['*' + names[k - 1]] * 9)}]")
    return "[" + ", ".join([*items, "*" + names[levels - 1]]) + "]"


@pytest.mark.parametrize(
    "text",
    [
        "ports: {laughs}\n",
        "ports:\n  - {{name: {laughs}, url: a, protocol: nmea0183, role: uut}}\n",
        "ports:\n  - {{name: e, url: a, protocol: nmea0183, role: uut, baud: {laughs}}}\n",
    ],
)
def test_a_config_of_aliases_expanding_exponentially_is_refused_at_once(
    tmp_path: Path, text: str
) -> None:
    """A config whose aliases would expand to 9**9 strings where a port list, a name or
    a number is wanted: refused in milliseconds naming the key, nothing expanded (the
    checks read the YAML nodes, an alias one node)."""
    path = tmp_path / "c.yaml"
    path.write_text(text.format(laughs=_laughs(9)))
    with pytest.raises(ConfigError, match=r"c\.yaml:\d+: ports\[0\]"):
        load_config(path)


def test_a_config_path_in_a_symlink_loop_is_refused(tmp_path: Path) -> None:
    """The config a symlink in a loop (``a -> b -> a``): a ConfigError saying it cannot
    be read (``Too many levels of symbolic links``)."""
    (tmp_path / "a.yaml").symlink_to(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").symlink_to(tmp_path / "a.yaml")
    with pytest.raises(ConfigError, match=r"cannot read.*symbolic links"):
        load_config(tmp_path / "a.yaml")
