"""Shared fixtures for the application tests: a small simulated trial on disk."""

from __future__ import annotations

from pathlib import Path

import pytest

from emlogd.offline.simulate import SimulationResult, simulate


@pytest.fixture(scope="session")
def trial(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """The five trajectories at 20 % of the paper's durations (seed 1), written once."""
    return simulate(tmp_path_factory.mktemp("trial"), seed=1, scale=0.2)


@pytest.fixture(scope="session")
def trial_files(trial: SimulationResult) -> dict[str, Path]:
    """Capture path by trajectory name (transit, figure-8, straight, circles, return)."""
    return {t.name: p for t, p in zip(trial.trajectories, trial.files, strict=True)}


@pytest.fixture
def two_port_config(tmp_path: Path) -> Path:
    """``tmp_path/c.yaml``: an EMlog (emlog1, NMEA) calibrated against a DVL (dvl, PD6) with
    a 3.3 s lag, both ports on /dev/null."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n"
        "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: dvl, lag: 3.3}\n"
    )
    return cfg
