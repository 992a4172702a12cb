"""Fixtures of the daemon's tests: a work directory with the test module's ``CONFIG``,
and the figure-8 served by fake sensors (the harness itself: ``harness.py``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.io.fake import FakeCapture
from emlogd.launch import fake_sensors
from tests.emlogd.daemon.harness import PORTS, SPEED, make_work


@pytest.fixture
def work(request: pytest.FixtureRequest, tmp_path: Path) -> Path:
    """``tmp_path`` made a work directory with the requesting module's ``CONFIG``."""
    config = request.module.CONFIG
    assert isinstance(config, str)
    return make_work(tmp_path, config)


@pytest.fixture
def sensors(work: Path, trial_files: dict[str, Path]) -> Iterator[FakeCapture]:
    """The three sensors of the figure-8 served at SPEED on one clock (stopped at teardown)."""
    with fake_sensors(trial_files["figure-8"], work / "links", PORTS, speed=SPEED) as fake:
        yield fake
