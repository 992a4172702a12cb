"""Reading a section's keys from YAML nodes: unknown, renamed, missing and bad keys refused
with the file and line, relative paths taken from the config's directory."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from drivers.errors import ConfigError
from emlogd.confignodes import Ctx, Loader, build_section, section
from emlogd.pipeline.keys import key, number, string


@dataclass(frozen=True, slots=True)
class _Section:
    """A section of two keys, one a path."""

    name: str = key(check=string(what="name"), doc="A name.")
    log: str = key("x.log", check=string(what="path"), path=True, doc="A path.")
    rate_hz: float = key(1.0, check=number(0.0, 10.0), unit="Hz", doc="A rate.")


def _read(text: str, base: Path | None = None) -> _Section:
    loader = Loader(text)
    node = loader.get_single_node()
    assert node is not None
    ctx = Ctx("cfg.yaml", loader, base)
    kw, _ = section(ctx, node, "", _Section, "")
    result: _Section = build_section(_Section, kw)
    return result


def test_a_section_is_read_by_its_declared_keys() -> None:
    """Each declared key's checked value lands on its field; an absent one keeps its default."""
    assert _read("name: a\nrate_hz: 2.5\n") == _Section(name="a", rate_hz=2.5)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("name: a\nrate: 1\n", r"cfg.yaml:2: rate: unknown key \(valid: name, log, rate_hz\)"),
        ("name: a\nstatus_interval_s: 1\n", "cfg.yaml:2: .*renamed: use status_log_interval_s"),
        ("rate_hz: 1\n", "cfg.yaml:1: missing required key 'name'"),
        ("name: a\nrate_hz: 11\n", "cfg.yaml:2: rate_hz: "),
        ("name: a\nname: b\n", "cfg.yaml:2: name: duplicate key"),
        ("name: [a]\n", "cfg.yaml:1: name: expected a single value"),
    ],
)
def test_a_bad_key_is_refused_at_its_line(text: str, message: str) -> None:
    """An unknown key names the valid ones, a renamed one its new name, a missing required
    one, a value out of range, a duplicate and a list for a value are each refused with the
    file and the line."""
    with pytest.raises(ConfigError, match=message):
        _read(text)


def test_a_relative_path_is_the_configs_directorys() -> None:
    """A path key's relative value is taken from the config's directory; an absolute one and
    one read without a directory are left as written."""
    assert _read("name: a\nlog: run/x.log\n", Path("/etc/emlogd")).log == "/etc/emlogd/run/x.log"
    assert _read("name: a\nlog: /var/x.log\n", Path("/etc/emlogd")).log == "/var/x.log"
    assert _read("name: a\nlog: run/x.log\n").log == "run/x.log"


def test_a_nul_in_a_path_is_refused() -> None:
    """A path holding a NUL character is refused (no file name holds one)."""
    with pytest.raises(ConfigError, match="cannot hold a NUL"):
        _read('name: a\nlog: "a\\0b"\n')
    assert yaml.safe_load('log: "a\\0b"') == {"log": "a\0b"}
