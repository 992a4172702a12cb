"""Shared fixtures for the application tests: the simulated trials on disk, each
simulated once per test run (shared by the run's workers)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from emlogd.offline.simulate import EMLOG1, EMLOG2, SimulationResult, simulate, with_sensor
from tests.once import once_per_run


def shared_simulation(
    factory: pytest.TempPathFactory, name: str, **kwargs: Any
) -> SimulationResult:
    """``simulate(**kwargs)`` once per test run, shared by its workers
    (:func:`tests.once.once_per_run`)."""
    return once_per_run(
        factory, f"sim-{name}", lambda folder: simulate(folder, **kwargs), SimulationResult
    )


@pytest.fixture(scope="session")
def trial(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """The five trajectories at 20 % of the paper's durations (seed 1)."""
    return shared_simulation(tmp_path_factory, "trial", seed=1, scale=0.2)


@pytest.fixture(scope="session")
def trial_files(trial: SimulationResult) -> dict[str, Path]:
    """Capture path by trajectory name (transit, figure-8, straight, circles, return)."""
    return {t.name: p for t, p in zip(trial.trajectories, trial.files, strict=True)}


@pytest.fixture(scope="session")
def misaligned_trial(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """A fifth of the trial (seed 3) with emlog2 turned 3° to starboard, its transverse
    axis 8 % low and 0.04 m/s to starboard, its noise 0.01 m/s."""
    sensor = with_sensor(EMLOG2, {"misalign": 3.0, "mt": -0.08, "bt": 0.04, "noise": 0.01})
    return shared_simulation(
        tmp_path_factory, "misaligned", seed=3, scale=0.2, emlogs=(EMLOG1, sensor)
    )


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
