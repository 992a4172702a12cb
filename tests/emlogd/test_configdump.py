"""The configuration written out: the dump loads back equal, the README's table is the
key table."""

from __future__ import annotations

from pathlib import Path

import yaml

from emlogd.config import Config, OutputConfig, PortConfig, UutConfig, load_config, parse_config
from emlogd.configdump import dump_config, key_table
from emlogd.pipeline.keys import entries

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "emlogd.yaml"
README = ROOT / "README.md"


def test_dump_round_trips_the_example() -> None:
    """The dumped effective config loads back to an equal Config."""
    cfg = load_config(EXAMPLE)
    text = dump_config(cfg)
    assert "lag: auto" in text
    assert parse_config(text, cfg.path) == cfg


def test_readme_reference_is_the_key_table() -> None:
    """README's "Configuration reference" is exactly key_table() (regenerate it with
    ``python -m emlogd.configdump``)."""
    text = README.read_text(encoding="utf-8")
    begin, end = "<!-- key-table: begin -->\n", "<!-- key-table: end -->"
    assert begin in text and end in text
    table = text.split(begin, 1)[1].split(end, 1)[0]
    assert table == key_table()


def test_dump_writes_every_key() -> None:
    """The dump has each section's every key, in the declarations' order."""
    dumped = yaml.safe_load(dump_config(load_config(EXAMPLE)))
    top = [e.name for e in entries(Config)]
    assert list(dumped) == ["ports", "calibration", "outputs", *top]
    assert list(dumped["ports"][0]) == [e.name for e in entries(PortConfig)]
    assert list(dumped["calibration"][1]) == [e.name for e in entries(UutConfig)]
    assert list(dumped["outputs"]) == [e.name for e in entries(OutputConfig)]
