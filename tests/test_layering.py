"""Layering rules of docs/ARCHITECTURE.md, checked mechanically on the source tree."""

from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path

import pytest

import drivers
from drivers.base import Decoder
from emlogd.cli import build_parser

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("emlogd", "drivers", "calib")

# Modules of drivers/ that are pure: bytes in, records out.
PURE_DRIVER_MODULES = (
    "base",
    "errors",
    "records",
    "framing",
    "nmea0183",
    "rdi_ascii",
    "rdi_pd0",
    "rdi_pd45",
)
FORBIDDEN_IN_PURE = {"serial", "os", "time", "threading", "socket", "selectors", "select"}


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


class TestImportDirection:
    """Imports go one way: emlogd -> drivers, calib."""

    @pytest.mark.parametrize("path", _sources("calib"), ids=lambda p: p.name)
    def test_calib_imports_only_numpy_and_stdlib(self, path: Path) -> None:
        """calib/ imports neither drivers nor emlogd nor any I/O or third-party module but numpy."""
        bad = _imports(path) & {
            "drivers",
            "emlogd",
            "serial",
            "yaml",
            "structlog",
            "pynmea2",
            "matplotlib",
            "socket",
            "selectors",
        }
        assert not bad, f"{path} imports {bad}"

    @pytest.mark.parametrize("path", _sources("drivers"), ids=lambda p: p.name)
    def test_drivers_never_import_calib_or_emlogd(self, path: Path) -> None:
        """drivers/ never imports calib or emlogd."""
        assert not _imports(path) & {"calib", "emlogd"}

    @pytest.mark.parametrize("name", PURE_DRIVER_MODULES)
    def test_protocol_modules_are_pure(self, name: str) -> None:
        """Protocol modules import no serial, os, time, threading or socket module."""
        path = ROOT / "drivers" / f"{name}.py"
        if not path.exists():
            pytest.fail(f"{path} is missing")
        bad = _imports(path) & FORBIDDEN_IN_PURE
        assert not bad, f"{path} imports {bad}"

    @pytest.mark.parametrize(
        "path", sorted((ROOT / "emlogd" / "pipeline").glob("*.py")), ids=lambda p: p.name
    )
    def test_the_pipeline_is_pure(self, path: Path) -> None:
        """emlogd/pipeline/ has no I/O and no clock, and depends on no other application
        folder: run, replay and the offline commands drive it with the data's own times."""
        assert not (_imports(path) & FORBIDDEN_IN_PURE), path
        for mod in _modules(path):
            assert not _within(mod, ("emlogd.daemon", "emlogd.offline", "emlogd.cli")), mod
            assert not _within(mod, ("drivers.io",)), mod

    def test_folders_depend_one_way(self) -> None:
        """daemon and offline never import each other or the CLI, without exception (the
        demo runs the daemon through the shared emlogd.launch); only the CLI prints."""
        rules = {
            "daemon": ("emlogd.offline", "emlogd.cli"),
            "offline": ("emlogd.daemon", "emlogd.cli"),
        }
        for folder, banned in rules.items():
            for path in sorted((ROOT / "emlogd" / folder).glob("*.py")):
                for mod in _modules(path):
                    assert not _within(mod, banned), (path, mod)
        for path in _sources("emlogd"):
            if "cli" in path.parts:
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            calls = [
                n for n in ast.walk(tree)
                if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "print"
            ]  # fmt: skip
            assert not calls, path

    def test_shared_modules_import_no_application_folder(self) -> None:
        """The modules at the top of emlogd/ (config, settings, the control-socket client,
        the daemon launcher...) import neither daemon, offline nor cli: both sides use them,
        so the demo (offline) reaches the daemon through them without importing it."""
        for path in sorted((ROOT / "emlogd").glob("*.py")):
            if path.name == "__main__.py":  # python -m emlogd: the CLI's entry point
                continue
            for mod in _modules(path):
                banned = ("emlogd.daemon", "emlogd.offline", "emlogd.cli")
                assert not _within(mod, banned), (path, mod)

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
