"""What a test run builds once for all its workers: a simulated trial, an imported
recording. The first process of the run to ask builds it into a folder beside the
workers' temporary directories (under a lock) and leaves its result there; the other
processes (xdist's workers) read that result. The tests only read what is built."""

from __future__ import annotations

import fcntl
import os
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import pytest

from emlogd.offline.importbase import ImportReport

T = TypeVar("T")

Imported = Callable[[Path], tuple[ImportReport, Path]]
"""The ``imported`` fixture (``tests/conftest.py``): a recording's import report and
capture, imported once per run."""


def run_folder(factory: pytest.TempPathFactory) -> Path:
    """The test run's own temporary folder: above each xdist worker's, shared by them."""
    root = factory.getbasetemp()
    return root.parent if os.environ.get("PYTEST_XDIST_WORKER") else root


def once_per_run(
    factory: pytest.TempPathFactory, name: str, build: Callable[[Path], T], kind: type[T]
) -> T:
    """``build(folder)``'s result, built once per test run into ``folder``
    (``once-NAME`` beside the run's temporary directories) and of type ``kind``."""
    root = run_folder(factory)
    done = root / f"once-{name}.pickle"
    with (root / f"once-{name}.lock").open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            result = pickle.loads(done.read_bytes())
        else:
            folder = root / f"once-{name}"
            folder.mkdir(exist_ok=True)  # a build that failed is tried again
            result = build(folder)
            done.write_bytes(pickle.dumps(result))
    assert isinstance(result, kind)
    return result
