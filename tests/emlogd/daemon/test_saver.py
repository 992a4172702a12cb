"""The state file's writer thread (:mod:`emlogd.daemon.saver`) and the daemon's stop
waiting for it."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from emlogd import fileio
from emlogd.daemon import saver as saver_module
from emlogd.daemon import statefile
from emlogd.daemon.control import Deferred
from emlogd.daemon.loop import Daemon
from emlogd.daemon.saver import Saver
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import make_work, saved_calibration
from tests.emlogd.daemon.test_redteam_reload import TWO_LOGS, _saved


class _Gate:
    """``write_synced`` held until :attr:`open` is set; counts the writes."""

    def __init__(self) -> None:
        self.open = threading.Event()
        self.entered = threading.Event()
        self.writes = 0
        self._write = fileio.write_synced

    def __call__(self, path: Path, data: bytes, mode: int = 0o640) -> None:
        self.writes += 1
        self.entered.set()
        self.open.wait(10)
        self._write(path, data, mode)


def _line(answer: Deferred) -> bytes | None:
    """The deferred answer's line, once settled."""
    return answer.line


class _Log:
    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, object]]] = []

    def _add(self, event: str, **kw: object) -> None:
        self.events.append((event, kw))

    info = warning = error = debug = _add

    def kinds(self) -> list[str]:
        return [e for e, _ in self.events]


def test_a_newer_snapshot_replaces_the_queued_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A save in flight (held), two more submitted: the second replaces the first queued,
    so two writes in all, results for the first and the last, and the file holds the
    last."""
    gate = _Gate()
    monkeypatch.setattr(statefile, "write_synced", gate)
    store = StateStore(tmp_path / "state.yaml")
    saver = Saver(store)
    try:
        first = saver.submit({"emlog1": saved_calibration(0.1)}, ())
        assert gate.entered.wait(5)
        saver.submit({"emlog1": saved_calibration(0.2)}, ())
        last = saver.submit({"emlog1": saved_calibration(0.3)}, ())
        assert not saver.idle
        gate.open.set()
        assert saver.wait_idle(5)
        results = saver.drain()
        assert [r.seq for r in results] == [first, last]
        assert all(r.error is None for r in results)
        assert gate.writes == 2
        assert _saved(store) == {"emlog1": 0.3}
    finally:
        gate.open.set()
        assert saver.close(5)


def _daemon(tmp_path: Path) -> tuple[Daemon, StateStore, _Log]:
    work = make_work(tmp_path, TWO_LOGS)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": saved_calibration(0.1, lag_s=0.165)})
    log = _Log()
    daemon = Daemon(work / "emlogd.yaml", log)
    daemon._start()
    return daemon, store, log


def _close(daemon: Daemon) -> None:
    os.close(daemon._wake_r)
    os.close(daemon._wake_w)


def test_the_stop_waits_for_the_save_in_flight(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A ``reset`` whose save the disk holds: its answer waits; the stop waits for the
    save (released 0.3 s later), which lands, and the answer says it persisted."""
    daemon, store, log = _daemon(tmp_path)
    gate = _Gate()
    monkeypatch.setattr(statefile, "write_synced", gate)
    try:
        answer = daemon._control({"cmd": "reset", "port": "emlog1"})
        assert isinstance(answer, Deferred) and answer.line is None
        assert gate.entered.wait(5)
        threading.Timer(0.3, gate.open.set).start()
    finally:
        daemon._shutdown()
        _close(daemon)
    assert "emlog1" not in _saved(store)
    line = _line(answer)
    assert line is not None and b'"persisted": true' in line, line
    assert "calibration_persisted" in log.kinds() and "state_save_pending" not in log.kinds()


def test_the_stop_waits_no_longer_than_its_bound(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A disk that hangs: the stop waits STOP_SAVE_S (made 0.3 s here), logs
    ``state_save_pending``, refuses the answer that waited, and ends; the previous file
    stays."""
    monkeypatch.setattr(saver_module, "STOP_SAVE_S", 0.3)
    daemon, store, log = _daemon(tmp_path)
    gate = _Gate()
    monkeypatch.setattr(statefile, "write_synced", gate)
    try:
        answer = daemon._control({"cmd": "reset", "port": "emlog1"})
        assert isinstance(answer, Deferred)
        assert gate.entered.wait(5)
        assert daemon.saves is not None
        saver = daemon.saves.saver
    finally:
        daemon._shutdown()
        _close(daemon)
    try:
        assert "state_save_pending" in log.kinds()
        line = _line(answer)
        assert line is not None and b"stopped before the save landed" in line, line
        assert _saved(store) == {"emlog1": 0.1}
    finally:
        gate.open.set()
        assert saver.wait_idle(5)


def test_a_command_repeated_while_its_save_is_in_flight_waits_for_that_save(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two ``reset``s of one UUT while the first one's save is held: the second changes
    nothing more, so it submits no save of its own but is answered with the first once
    that lands: one write, both answered that they persisted."""
    daemon, store, _ = _daemon(tmp_path)
    gate = _Gate()
    monkeypatch.setattr(statefile, "write_synced", gate)
    try:
        first = daemon._control({"cmd": "reset", "port": "emlog1"})
        assert gate.entered.wait(5)
        second = daemon._control({"cmd": "reset", "port": "emlog1"})
        assert isinstance(first, Deferred) and isinstance(second, Deferred)
        assert not second.line
        gate.open.set()
        assert daemon.saves is not None and daemon.saves.saver.wait_idle(5)
        daemon.saves.landed()
        for answer in (first, second):
            line = _line(answer)
            assert line is not None and b'"persisted": true' in line, line
        assert gate.writes == 1
    finally:
        gate.open.set()
        daemon._shutdown()
        _close(daemon)
    assert "emlog1" not in _saved(store)
