"""Reading the declared keys from YAML nodes: each section's mapping checked against the
keys its dataclass declares (:mod:`emlogd.pipeline.keys`), errors naming the file and line.

:mod:`emlogd.config` reads a config file's sections through these; the keys themselves are
declared once, on the dataclasses.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from drivers.errors import ConfigError
from emlogd.configyaml import YAML_FAILURES, yaml_why
from emlogd.pipeline.keys import Entry, InvalidValueError, build, entries

RENAMED: dict[str, str] = {
    "status_interval_s": "status_log_interval_s",
    "outputs.status_interval_s": "outputs.status_sentence_interval_s",
}
"""Keys of earlier versions, refused with their new names."""


class Loader(yaml.SafeLoader):
    """SafeLoader that keeps nodes (for line numbers)."""


class Ctx:
    """The file being read: its name for messages, its loader, and the directory relative
    paths are taken from (None: left as written)."""

    def __init__(self, path: str, loader: Loader, base: Path | None) -> None:
        self.path = path
        self.loader = loader
        self.base = base

    def fail(self, node: yaml.Node | None, where: str, msg: str) -> ConfigError:
        line = node.start_mark.line + 1 if node is not None else 1
        return ConfigError(
            f"{self.path}:{line}: {where}: {msg}" if where else f"{self.path}:{line}: {msg}"
        )

    def mapping(self, node: yaml.Node, where: str) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, where, "expected a mapping (key: value)")
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for k, v in node.value:
            if not isinstance(k, yaml.ScalarNode) or not isinstance(k.value, str):
                raise self.fail(k, where, "keys must be strings")
            if k.value in out:
                raise self.fail(k, f"{where}.{k.value}" if where else k.value, "duplicate key")
            out[k.value] = (k, v)
        return out

    def sequence(self, node: yaml.Node, where: str) -> list[yaml.Node]:
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(node, where, "expected a list")
        return list(node.value)

    def value(self, node: yaml.Node, where: str, e: Entry) -> Any:
        """The checked value of key ``e`` at ``node``."""
        sub: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        if e.key.check.mapping:
            sub = self.mapping(node, where)
        elif not isinstance(node, yaml.ScalarNode):
            raise self.fail(node, where, "expected a single value")
        try:
            raw = self.loader.construct_object(node, deep=True)
        except YAML_FAILURES as exc:
            raise self.fail(node, where, f"not a valid value ({yaml_why(exc)})") from None
        try:
            v = e.key.check(raw)
        except InvalidValueError as exc:
            if exc.sub is not None:
                raise self.fail(sub[exc.sub][0], f"{where}.{exc.sub}", str(exc)) from None
            raise self.fail(node, where, str(exc)) from None
        if e.key.path and isinstance(v, str) and "\0" in v:
            # no file name holds one: the open or bind raised ValueError, which ended
            # the daemon at a reload (the output pty, the control and status sockets)
            raise self.fail(node, where, f"{v!r}: a path cannot hold a NUL character")
        if (
            e.key.path
            and self.base is not None
            and isinstance(v, str)
            and "://" not in v
            and not v.startswith("/")
        ):
            v = str(self.base / v)
        return v


def refuse_unknown(ctx: Ctx, kn: yaml.Node, where: str, full: str, valid: list[str]) -> None:
    """Refuse a key that is not in ``valid`` (a renamed one with its new name)."""
    if full in RENAMED:
        raise ctx.fail(kn, where, f"renamed: use {RENAMED[full]}")
    raise ctx.fail(kn, where, f"unknown key (valid: {', '.join(valid)})")


def section(
    ctx: Ctx, node: yaml.Node, where: str, cls: type, prefix: str
) -> tuple[dict[str, Any], dict[str, yaml.Node]]:
    """Check a mapping against the keys ``cls`` declares: the values by key name (a key
    absent whose config default is not the field's included) and the value nodes."""
    m = ctx.mapping(node, where)
    by_name = {e.name: e for e in entries(cls)}
    for k, (kn, _) in m.items():
        if k not in by_name:
            refuse_unknown(ctx, kn, f"{where}.{k}" if where else k, prefix + k, list(by_name))
    for e in by_name.values():
        if e.required and e.name not in m:
            raise ctx.fail(node, where, f"missing required key {e.name!r}")
    kw = {k: ctx.value(vn, f"{where}.{k}" if where else k, by_name[k]) for k, (_, vn) in m.items()}
    for e in by_name.values():
        if e.name not in kw and e.key.absent:
            kw[e.name] = e.key.absent[0]
    return kw, {k: vn for k, (_, vn) in m.items()}


def build_section(
    cls: type, kw: Mapping[str, Any], extra: Mapping[tuple[str, ...], Any] | None = None
) -> Any:
    """``cls`` from checked values by key name, and fields that are no keys by attribute
    path in ``extra``."""
    attrs = {e.name: e.attrs for e in entries(cls)}
    return build(cls, {**{attrs[k]: v for k, v in kw.items()}, **(extra or {})})
