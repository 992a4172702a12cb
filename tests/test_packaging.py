"""The wheel holds exactly the three import packages, their py.typed markers and the CLI."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    """Build the project's wheel once for this module."""
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (path,) = out.glob("emlogd-*.whl")
    return zipfile.ZipFile(path)


class TestWheel:
    """Contents of the built wheel."""

    def test_three_packages_and_markers(self, wheel: zipfile.ZipFile) -> None:
        """emlogd, drivers and calib are packaged, each with py.typed."""
        names = set(wheel.namelist())
        for package in ("emlogd", "drivers", "calib"):
            assert f"{package}/__init__.py" in names
            assert f"{package}/py.typed" in names

    def test_every_source_module_ships(self, wheel: zipfile.ZipFile) -> None:
        """Every module of the three packages, subpackages included, is in the wheel."""
        names = set(wheel.namelist())
        source = {
            p.relative_to(ROOT).as_posix()
            for package in ("emlogd", "drivers", "calib")
            for p in (ROOT / package).rglob("*.py")
        }
        assert source, "no source found"
        assert sorted(source - names) == []

    def test_no_tests_or_tooling_in_wheel(self, wheel: zipfile.ZipFile) -> None:
        """Only the three packages (and metadata) are top-level entries."""
        tops = {n.split("/")[0] for n in wheel.namelist()}
        tops = {t for t in tops if not t.endswith(".dist-info")}
        assert tops == {"emlogd", "drivers", "calib"}

    def test_console_script_and_dependencies(self, wheel: zipfile.ZipFile) -> None:
        """The emlogd console script and the five runtime dependencies are declared; pynmea2
        (the tests' oracle, the bench's anchor) only under an extra."""
        meta = next(n for n in wheel.namelist() if n.endswith(".dist-info/entry_points.txt"))
        assert "emlogd = emlogd.entry:main" in wheel.read(meta).decode()
        metadata = next(n for n in wheel.namelist() if n.endswith(".dist-info/METADATA"))
        text = wheel.read(metadata).decode()
        for dep in ("pyserial", "numpy", "pyyaml", "structlog", "pyIGRF14"):
            assert f"Requires-Dist: {dep}" in text.replace("PyYAML", "pyyaml")
        pynmea2 = [line for line in text.splitlines() if line.startswith("Requires-Dist: pynmea2")]
        assert pynmea2 and all("extra ==" in line for line in pynmea2)
