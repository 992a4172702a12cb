"""Shared fixtures: real pseudo-terminals, capture files on disk, fake devices, real
recordings imported once per run, captures read once per run by the offline
commands (:mod:`tests.recordings`); the hypothesis profile of the run
(:mod:`tests.profiles`)."""

from __future__ import annotations

import os

# One BLAS thread per process, set before numpy is first imported (this file is the
# first the run imports; the daemons and commands the tests start inherit it): the run's
# two workers on two cores each spawned an OpenBLAS thread per core, and on a busy
# machine a small least-squares fit waited on a descheduled thread (numpy.linalg.lstsq
# 2.7 ms -> 52 ms a call, test_twoaxis_learn's figure-8 0.3 s -> 12 s). An explicit
# setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import contextlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

from drivers.io.capture import CaptureWriter
from drivers.io.fake import FakeDevice
from emlogd.offline.importbase import ImportReport
from emlogd.offline.importer import import_nmea
from tests import profiles
from tests.once import Imported, once_per_run, run_folder
from tests.recordings import ReadOnce, TwoAxisOnce


def pytest_configure(config: pytest.Config) -> None:
    """Load the run's hypothesis profile (before any test module is imported), unless
    ``--hypothesis-profile`` names one."""
    from hypothesis import settings

    if config.getoption("hypothesis_profile", None):
        return
    settings.load_profile(profiles.choose(config.getoption("markexpr", ""), os.environ))


@pytest.fixture(scope="session", autouse=True)
def read_once(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ReadOnce]:
    """The offline commands read each capture once per test run
    (:class:`tests.recordings.ReadOnce`, :class:`tests.recordings.TwoAxisOnce`, shared by
    the run's workers): the same trials and examples are read by many tests with the
    same inputs."""
    from emlogd.offline.dataset import record_captures
    from emlogd.offline.twoaxis import record_two_axis

    folder = run_folder(tmp_path_factory) / "read-once"
    with pytest.MonkeyPatch.context() as mp:
        reader = ReadOnce(record_captures, folder)
        mp.setattr("emlogd.offline.jobs.record_captures", reader)
        two = TwoAxisOnce(record_two_axis, folder)
        mp.setattr("emlogd.offline.twoaxis.record_two_axis", two)
        yield reader


@pytest.fixture(scope="session")
def imported(tmp_path_factory: pytest.TempPathFactory) -> Imported:
    """``imported(src)``: the NMEA log ``src`` imported with the default options once per
    test run (:func:`tests.once.once_per_run`): its report and its capture, to be read only."""

    def imp(src: Path) -> tuple[ImportReport, Path]:
        def build(folder: Path) -> tuple[ImportReport, Path]:
            cap = folder / f"{src.stem}.cap.gz"
            return import_nmea([src], cap), cap

        return once_per_run(tmp_path_factory, f"import-{src.name}", build, tuple)

    return imp


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, int, str]]:
    """A raw pty: (master fd, slave fd, slave path); both closed afterwards."""
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, slave, os.ttyname(slave)
    for fd in (master, slave):
        with contextlib.suppress(OSError):
            os.close(fd)


@pytest.fixture
def write_capture(tmp_path: Path) -> Callable[..., Path]:
    """Write a capture: write_capture({port: protocol}, [(t, port, bytes, binary)], name=...).

    Text records (``binary`` false) are lines without CR/LF, binary records chunks.
    """

    def write(
        ports: dict[str, str],
        records: Sequence[tuple[float, str, bytes, bool]],
        name: str = "c.cap",
    ) -> Path:
        path = tmp_path / name
        with CaptureWriter(path, ports) as w:
            for t, port, data, binary in records:
                if binary:
                    w.write_chunk(t, port, data)
                else:
                    w.write_line(t, port, data)
        return path

    return write


@pytest.fixture
def fake_device(tmp_path: Path) -> Iterator[Callable[..., FakeDevice]]:
    """Start fake devices: fake_device(capture, port, speed=None, loop=False, link=None).

    The device serves ``port`` of ``capture`` at ``link`` (default
    ``tmp_path/links/PORT``) in a background thread; every device started is stopped
    and joined at teardown (and must have ended).
    """
    devices: list[FakeDevice] = []

    def start(
        capture: Path,
        port: str,
        *,
        speed: float | None = None,
        loop: bool = False,
        link: Path | None = None,
    ) -> FakeDevice:
        where = link if link is not None else tmp_path / "links" / port
        dev = FakeDevice(capture, port, where, speed=speed, loop=loop).start()
        devices.append(dev)
        return dev

    yield start
    for dev in devices:
        dev.stop()
    for dev in devices:
        dev.join(5)
        assert dev._thread is not None and not dev._thread.is_alive(), "a fake device hung"
