"""Layering rules of docs/ARCHITECTURE.md, checked mechanically on the source tree."""

from __future__ import annotations

import ast
import dataclasses
import re
import sys
from pathlib import Path

import pytest

import drivers
from drivers.base import Decoder
from emlogd.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("emlogd", "drivers", "calib")

FORBIDDEN_IN_PURE = {"serial", "os", "time", "threading", "socket", "selectors", "select"}
"""What a pure module (bytes or data in, values out: no I/O, no clock) never imports."""

APPLICATION = ("emlogd.daemon", "emlogd.offline", "emlogd.cli")


@dataclasses.dataclass(frozen=True)
class Rule:
    """What the modules of a folder may not import.

    Attributes:
        top: top-level modules (``os``, ``emlogd``...) none of the folder's modules imports.
        within: packages or modules (``emlogd.cli``...) none of them imports, nor anything
            inside them.
        only: if not None, the only top-level modules besides the standard library's that
            the folder's modules import (a new dependency breaks the rule without a list
            naming it).
        why: the rule in words (docs/ARCHITECTURE.md).
    """

    top: frozenset[str] = frozenset()
    within: tuple[str, ...] = ()
    only: frozenset[str] | None = None
    why: str = ""

    def forbidden(self, top: set[str]) -> set[str]:
        """The top-level modules of ``top`` this rule forbids."""
        bad = top & self.top
        if self.only is not None:
            bad |= {m for m in top if m not in self.only and m not in sys.stdlib_module_names}
        return bad


FOLDER_RULES = {
    "calib": Rule(
        top=frozenset(
            {"drivers", "emlogd", "serial", "yaml", "structlog", "pynmea2", "matplotlib"}
            | {"socket", "selectors"}
        ),
        only=frozenset({"numpy", "calib"}),
        why="the mathematics: numpy and the stdlib only, no I/O",
    ),
    "drivers": Rule(
        top=frozenset({"calib", "emlogd"} | FORBIDDEN_IN_PURE),
        why="protocol decoders and framers are pure: bytes in, records out",
    ),
    "drivers/io": Rule(
        top=frozenset({"calib", "emlogd"}), why="the impure drivers: no calib, no emlogd"
    ),
    "emlogd": Rule(
        within=APPLICATION,
        why="the modules at the top of emlogd/ are shared by daemon, offline and cli",
    ),
    "emlogd/pipeline": Rule(
        top=frozenset(FORBIDDEN_IN_PURE),
        within=(*APPLICATION, "drivers.io"),
        why="the pipeline has no I/O and no clock, and imports no other application folder",
    ),
    "emlogd/daemon": Rule(
        within=("emlogd.offline", "emlogd.cli"), why="daemon imports neither offline nor cli"
    ),
    "emlogd/offline": Rule(
        within=("emlogd.daemon", "emlogd.cli"), why="offline imports neither daemon nor cli"
    ),
    "emlogd/cli": Rule(why="the CLI may import every other folder"),
}
"""Each folder's import rule. A module obeys the rule of the nearest folder above it
that has one (``drivers/nmea0183/x.py``: ``drivers``; ``drivers/io/port.py``:
``drivers/io``), so a new module or subfolder is covered as soon as it exists."""

EXEMPT = {
    "emlogd/__main__.py": "python -m emlogd: the CLI's entry point",
    "emlogd/entry.py": "the console script's entry point: the daemon's signals held before "
    "the CLI's imports (emlogd.cli imports them all)",
}
"""Modules outside their folder's rule, and why."""


def _rule_folder(path: Path) -> str:
    """The folder whose rule ``path`` obeys (the nearest one above it with a rule)."""
    rel = path.relative_to(ROOT).parent
    for folder in (rel, *rel.parents):
        if folder.as_posix() in FOLDER_RULES:
            return folder.as_posix()
    raise AssertionError(f"{path} is under no folder with an import rule")


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _imports(path: Path) -> set[str]:
    """Top-level names of every module imported by ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def _modules(path: Path) -> set[str]:
    """Full names of every module imported by ``path`` (absolute imports)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _within(mod: str, packages: tuple[str, ...]) -> bool:
    """Whether module ``mod`` is one of ``packages`` or inside one (emlogd.client is not
    inside emlogd.cli)."""
    return any(mod == p or mod.startswith(p + ".") for p in packages)


def _stray_strings(node: ast.AST) -> list[int]:
    """The lines of the string statements in ``node``'s bodies that are neither its
    docstring nor right under an assignment (an attribute's docstring)."""
    defines = isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
    lines = []
    for name in ("body", "orelse", "finalbody"):
        body = getattr(node, name, None)
        if not isinstance(body, list):
            continue
        for i, stmt in enumerate(body):
            if not (
                isinstance(stmt, ast.Expr)
                and isinstance(stmt.value, ast.Constant)
                and isinstance(stmt.value.value, str)
            ):
                continue
            if i == 0 and name == "body" and defines:
                continue
            if i > 0 and isinstance(body[i - 1], ast.Assign | ast.AnnAssign):
                continue
            lines.append(stmt.lineno)
    return lines


class TestImportDirection:
    """Imports go one way: emlogd -> drivers, calib."""

    @pytest.mark.parametrize(
        "path",
        [p for pkg in PACKAGES for p in _sources(pkg)],
        ids=lambda p: p.relative_to(ROOT).as_posix(),
    )
    def test_every_module_obeys_its_folders_rule(self, path: Path) -> None:
        """Every module of the three packages imports nothing its folder's rule forbids
        (:data:`FOLDER_RULES`; imports for type checking count too)."""
        rel = path.relative_to(ROOT).as_posix()
        if rel in EXEMPT:
            return
        folder = _rule_folder(path)
        rule = FOLDER_RULES[folder]
        bad = sorted(rule.forbidden(_imports(path))) + sorted(
            m for m in _modules(path) if _within(m, rule.within)
        )
        assert not bad, f"{rel} imports {bad}: {folder}/ rule: {rule.why}"

    def test_the_folder_rules_reach_every_module(self) -> None:
        """Each rule names a folder that exists, and a module is held to the nearest
        folder's rule: binframe.py to the pure drivers', port.py to drivers/io's, a
        module of calib/kalman/ to calib's."""
        for folder in FOLDER_RULES:
            assert (ROOT / folder).is_dir(), folder
        assert _rule_folder(ROOT / "drivers" / "binframe.py") == "drivers"
        assert _rule_folder(ROOT / "drivers" / "io" / "port.py") == "drivers/io"
        assert _rule_folder(ROOT / "calib" / "kalman" / "filters.py") == "calib"
        assert _rule_folder(ROOT / "emlogd" / "pipeline" / "core.py") == "emlogd/pipeline"
        assert _rule_folder(ROOT / "emlogd" / "config.py") == "emlogd"

    def test_calib_imports_only_numpy_and_the_stdlib(self) -> None:
        """calib's rule admits numpy, calib and the standard library and nothing else, so a
        new third-party import (scipy) breaks it though no list names it."""
        rule = FOLDER_RULES["calib"]
        assert rule.forbidden({"numpy", "calib", "math", "dataclasses"}) == set()
        assert rule.forbidden({"numpy", "scipy", "drivers", "os"}) == {"scipy", "drivers"}

    def test_only_the_cli_prints(self) -> None:
        """No module of emlogd/ but the CLI's calls print."""
        for path in _sources("emlogd"):
            if "cli" in path.parts:
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            calls = [
                n for n in ast.walk(tree)
                if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "print"
            ]  # fmt: skip
            assert not calls, path

    def test_the_pipelines_modules_import_one_way(self) -> None:
        """No import cycle among the modules of emlogd/pipeline (imports for type checking
        only count too): the settings live apart from the classes that read them."""
        folder = ROOT / "emlogd" / "pipeline"
        graph = {
            f"emlogd.pipeline.{path.stem}": {
                mod for mod in _modules(path) if _within(mod, ("emlogd.pipeline",))
            }
            for path in sorted(folder.glob("*.py"))
            if path.name != "__init__.py"
        }
        assert graph["emlogd.pipeline.core"]  # the graph is read (core imports its parts)
        done: set[str] = set()

        def visit(mod: str, path: tuple[str, ...]) -> None:
            if mod in path:
                raise AssertionError(f"import cycle: {' -> '.join((*path, mod))}")
            if mod in done:
                return
            for dep in sorted(graph.get(mod, ())):
                visit(dep, (*path, mod))
            done.add(mod)

        for mod in sorted(graph):
            visit(mod, ())

    def test_daemon_never_imports_matplotlib(self) -> None:
        """Plots are an optional extra: only the report module may import matplotlib."""
        for path in _sources("emlogd"):
            if path.name == "report.py":
                continue
            assert "matplotlib" not in _imports(path), path


class TestConventions:
    """Grep-level conventions (docs/ARCHITECTURE.md)."""

    def test_serial_opened_only_in_port_module(self) -> None:
        """Only drivers/io/port.py opens serial ports (always through serial_for_url)."""
        for package in PACKAGES:
            for path in _sources(package):
                if path == ROOT / "drivers" / "io" / "port.py":
                    continue
                text = path.read_text(encoding="utf-8")
                assert not re.search(r"serial\.(Serial|serial_for_url)\(", text), path

    def test_no_unsafe_yaml_load(self) -> None:
        """YAML is only read with safe functions."""
        for package in PACKAGES:
            for path in _sources(package):
                assert "yaml.load(" not in path.read_text(encoding="utf-8"), path

    def test_no_base_exception_subclass(self) -> None:
        """No error class derives from BaseException."""
        for package in PACKAGES:
            for path in _sources(package):
                tree = ast.parse(path.read_text(encoding="utf-8"))
                for node in ast.walk(tree):
                    if isinstance(node, ast.ClassDef):
                        bases = {ast.unparse(b) for b in node.bases}
                        assert "BaseException" not in bases, f"{path}:{node.name}"

    def test_every_docstring_sits_on_its_definition(self) -> None:
        """A string statement is a module's, class's or function's first statement or an
        attribute's docstring right under its assignment: one anywhere else documents
        nothing (two in a row, the second meant for an attribute whose own sits above)."""
        stray = []
        for package in PACKAGES:
            for path in _sources(package):
                for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                    stray += [f"{path.relative_to(ROOT)}:{line}" for line in _stray_strings(node)]
        assert not stray, stray

    def test_no_logging_basicconfig(self) -> None:
        """Library code never configures the stdlib root logger."""
        for package in PACKAGES:
            for path in _sources(package):
                assert "basicConfig" not in path.read_text(encoding="utf-8"), path


class TestRegistry:
    """The explicit protocol registry."""

    @pytest.mark.parametrize("name", sorted(drivers.PROTOCOLS))
    def test_every_entry_imports_a_decoder(self, name: str) -> None:
        """Every registry entry imports and subclasses drivers.base.Decoder."""
        cls = drivers.get_decoder(name)
        assert issubclass(cls, Decoder)
        assert isinstance(cls.binary, bool)

    def test_unknown_protocol_lists_valid_names(self) -> None:
        """An unknown protocol raises UnknownProtocolError naming the valid ones."""
        with pytest.raises(drivers.UnknownProtocolError, match="nmea0183"):
            drivers.get_decoder("nmea2000")

    def test_cli_protocol_choices_match_registry(self) -> None:
        """The CLI's --protocol choices equal the registry names."""
        parser = build_parser()
        sub = next(a for a in parser._actions if a.dest == "command")
        dump = sub.choices["dump"]  # type: ignore[index]
        proto = next(a for a in dump._actions if a.dest == "protocol")
        assert list(proto.choices) == sorted(drivers.PROTOCOLS)

    def test_records_are_frozen_and_slotted(self) -> None:
        """Every record type is a frozen dataclass with __slots__."""
        for cls in drivers.record_types():
            assert dataclasses.is_dataclass(cls), cls
            params = cls.__dataclass_params__  # type: ignore[attr-defined]
            assert params.frozen, cls
            assert "__slots__" in cls.__dict__, cls


class TestTestsMirrorTree:
    """tests/ mirrors the package tree."""

    @pytest.mark.parametrize("package", PACKAGES)
    def test_every_module_has_a_test_file(self, package: str) -> None:
        """Each module pkg/x.py has tests/pkg/test_x.py."""
        missing = []
        for path in _sources(package):
            if path.name in ("__init__.py", "__main__.py"):
                continue
            rel = path.relative_to(ROOT / package)
            test = ROOT / "tests" / package / rel.parent / f"test_{path.stem}.py"
            if not test.exists():
                missing.append(str(test.relative_to(ROOT)))
        assert not missing, f"missing test files: {missing}"


MAX_MODULE_LINES = 700
"""No module of the packages, the scripts in docs/ and bench/, or the tests is longer:
past it, a module is split along what it holds."""

DUPLICATE_WINDOW = 6
"""Consecutive significant lines that may not appear twice in the files of
:data:`NO_DUPLICATES`."""

NO_DUPLICATES = ("calib", "drivers", "emlogd", "bench", "docs", "tests")
"""The folders whose .py files (all of them, together) are checked for repeated blocks."""


def _significant_lines(path: Path) -> list[tuple[int, str]]:
    """Stripped lines, without blank lines, imports and function signatures (functions
    taking the same series spell out the same parameters: that is their interface)."""
    text = path.read_text(encoding="utf-8")
    skip: set[int] = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Import | ast.ImportFrom):
            skip.update(range(node.lineno, (node.end_lineno or node.lineno) + 1))
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            skip.update(range(node.lineno, node.body[0].lineno))
    return [
        (i, line.strip())
        for i, line in enumerate(text.splitlines(), 1)
        if line.strip() and i not in skip
    ]


class TestModuleSize:
    """Modules stay small enough to read, and blocks are written once."""

    def test_no_module_over_the_limit(self) -> None:
        sizes = {
            str(p.relative_to(ROOT)): len(p.read_text(encoding="utf-8").splitlines())
            for folder in NO_DUPLICATES
            for p in (ROOT / folder).rglob("*.py")
        }
        long = {path: n for path, n in sizes.items() if n > MAX_MODULE_LINES}
        assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"

    def test_no_repeated_blocks(self) -> None:
        seen: dict[tuple[str, ...], str] = {}
        repeated = []
        for path in (p for folder in NO_DUPLICATES for p in sorted((ROOT / folder).rglob("*.py"))):
            rel = path.relative_to(ROOT)
            lines = _significant_lines(path)
            for k in range(len(lines) - DUPLICATE_WINDOW + 1):
                block = tuple(s for _, s in lines[k : k + DUPLICATE_WINDOW])
                where = f"{rel}:{lines[k][0]}"
                if block in seen:
                    repeated.append(f"{where} repeats {seen[block]}")
                else:
                    seen[block] = where
        assert not repeated, "\n".join(repeated)
