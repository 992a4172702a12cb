"""A reloaded config loaded in a thread: its config, or its failure, handed over."""

from __future__ import annotations

from pathlib import Path

from drivers.errors import ConfigError
from emlogd.config import Config
from emlogd.daemon.configload import ConfigLoad
from tests.emlogd.daemon.harness import PD0_CONFIG


def test_a_config_is_loaded_beside_the_caller(tmp_path: Path) -> None:
    """The thread sets ``done`` with the config as ``result``."""
    path = tmp_path / "emlogd.yaml"
    path.write_text(PD0_CONFIG)
    load = ConfigLoad(path)
    assert load.done.wait(10.0)
    assert isinstance(load.result, Config)
    assert [p.name for p in load.result.ports] == ["emlog1", "dvl"]


def test_a_config_that_does_not_load_is_its_error(tmp_path: Path) -> None:
    """A missing file: ``result`` is the ``ConfigError`` naming it, raised in no thread."""
    load = ConfigLoad(tmp_path / "absent.yaml")
    assert load.done.wait(10.0)
    assert isinstance(load.result, ConfigError)
    assert "absent.yaml" in str(load.result)
