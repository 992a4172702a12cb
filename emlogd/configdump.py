"""The configuration written out: the effective config as YAML (:func:`dump_config`)
and every key as README's "Configuration reference" table (:func:`key_table`; ``python
-m emlogd.configdump`` prints it), both from the keys' declarations
(:mod:`emlogd.config`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

from emlogd.config import SECTIONS, Config, OutputConfig, PortConfig, UutConfig
from emlogd.pipeline.keys import Entry, entries, get


def _shown(e: Entry, value: Any) -> Any:
    if e.key.show is not None:
        value = e.key.show(value)
    return dict(value) if isinstance(value, Mapping) else value


def _dump_section(obj: Any, cls: type) -> dict[str, Any]:
    return {e.name: _shown(e, get(obj, e.attrs)) for e in entries(cls)}


def dump_config(config: Config) -> str:
    """The effective configuration (every key, defaults filled in) as YAML.

    Paths are written as loaded (already resolved), ``current: auto`` and a log's
    ``talker`` as they were resolved, so ``parse_config(dump_config(c), c.path) == c``.
    """
    doc: dict[str, Any] = {
        "ports": [_dump_section(p, PortConfig) for p in config.ports],
        "calibration": [_dump_section(u, UutConfig) for u in config.calibration],
        "outputs": _dump_section(config.outputs, OutputConfig),
        **_dump_section(config, Config),
    }
    name = " ".join(config.path.splitlines())
    return f"# emlogd effective configuration of {name}\n" + yaml.safe_dump(doc, sort_keys=False)


def _cell(value: Any) -> str:
    """A value as a config would write it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {_cell(v)}" for k, v in value.items()) + "}"
    return str(value)


def key_table() -> str:
    """Every config key as a Markdown table (README's "Configuration reference")."""
    rows = [
        "| Key | Values | Default | Unit | Meaning |",
        "| --- | --- | --- | --- | --- |",
    ]
    for prefix, cls in SECTIONS:
        for e in entries(cls):
            shown = e.key.text or f"`{_cell(_shown(e, e.absent))}`"
            default = "required" if e.required else shown
            rows.append(
                f"| `{prefix}{e.name}` | {e.key.check.text} | {default} | {e.key.unit} "
                f"| {e.key.doc} |"
            )
    return "\n".join(rows) + "\n"


if __name__ == "__main__":  # python -m emlogd.configdump: the table README's reference holds
    import sys

    sys.stdout.write(key_table())
