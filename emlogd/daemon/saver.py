"""The state file's saves, beside the daemon's loop: one writer thread.

The loop takes the snapshot (the calibrations, immutable records) and hands it to
:meth:`Saver.submit`; the thread does the disk work of
:meth:`~emlogd.daemon.statefile.StateStore.save` (the temporary file written and
fsync-ed, the backup linked, the rename, the directory's fsync). A slow disk (an SD
card whose fsync takes a third of a second, a disk that hangs) holds that thread, never
the outputs.

At most one save is in flight; a snapshot submitted meanwhile waits, and a newer one
replaces it (it holds everything the older one held: the latest state always ends on
disk, with at most two writes queued behind a slow disk). Each save's outcome (a
:class:`SaveResult`) is queued back and the loop woken through :attr:`Saver.wake_fd`:
counters, log lines and control answers stay in the loop's thread.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import queue
import threading
from collections.abc import Sequence
from pathlib import Path

from emlogd.daemon.statefile import StateStore
from emlogd.pipeline.calibration import Calibration


@dataclasses.dataclass(frozen=True)
class SaveJob:
    """One snapshot to write: the calibrations in use by UUT and the others."""

    seq: int
    states: dict[str, Calibration]
    others: tuple[Calibration, ...]
    final: bool = False


@dataclasses.dataclass(frozen=True)
class SaveResult:
    """What became of a :class:`SaveJob` (of number ``seq``)."""

    seq: int
    job: SaveJob
    error: str | None = None
    """Why the file was not written (the previous one is intact), or None."""
    aside: Path | None = None
    """Where a damaged or refused current file was moved (``save``'s return)."""
    backup_problem: str | None = None
    """Why no backup was kept (:attr:`StateStore.backup_problem`), or None."""


class Saver:
    """The writer thread of one :class:`StateStore`.

    Args:
        store: the state file; only this thread calls its ``save`` while the saver runs.
    """

    def __init__(self, store: StateStore) -> None:
        self.store = store
        self._cond = threading.Condition()
        self._queued: SaveJob | None = None
        self._busy = False
        self._closing = False
        self._seq = 0
        self.results: queue.SimpleQueue[SaveResult] = queue.SimpleQueue()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._thread = threading.Thread(target=self._run, name="emlogd-save", daemon=True)
        self._thread.start()

    @property
    def wake_fd(self) -> int:
        """Readable once a result waits in :attr:`results` (:meth:`drain` empties both)."""
        return self._wake_r

    def submit(
        self, states: dict[str, Calibration], others: Sequence[Calibration], *, final: bool = False
    ) -> int:
        """Queue a snapshot (replacing one queued and not yet started); return its
        number: a result of that number or higher holds it."""
        with self._cond:
            self._seq += 1
            self._queued = SaveJob(self._seq, dict(states), tuple(others), final)
            self._cond.notify()
            return self._seq

    @property
    def idle(self) -> bool:
        """Nothing queued and nothing being written."""
        with self._cond:
            return self._queued is None and not self._busy

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until :attr:`idle`, at most ``timeout_s``; return whether it is."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._queued is None and not self._busy, timeout=timeout_s
            )

    def drain(self) -> list[SaveResult]:
        """The results waiting, oldest first (the wake-up byte read too)."""
        with contextlib.suppress(OSError):
            while os.read(self._wake_r, 4096):
                pass
        out: list[SaveResult] = []
        while True:
            try:
                out.append(self.results.get_nowait())
            except queue.Empty:
                return out

    def close(self, timeout_s: float) -> bool:
        """Let the save in flight and the one queued finish (at most ``timeout_s``), then
        end the thread; return whether everything was written or failed in time (False:
        the thread is left writing, a daemon thread the exit ends)."""
        done = self.wait_idle(timeout_s)
        with self._cond:
            self._closing = True
            self._cond.notify()
        if done:
            self._thread.join(timeout_s)
            for fd in (self._wake_r, self._wake_w):
                os.close(fd)
        return done

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._queued is not None or self._closing)
                job = self._queued
                if job is None:
                    return
                self._queued, self._busy = None, True
            result = self._save(job)
            with self._cond:
                self.results.put(result)
                with contextlib.suppress(OSError):
                    os.write(self._wake_w, b"s")
                self._busy = False
                self._cond.notify_all()

    def _save(self, job: SaveJob) -> SaveResult:
        try:
            aside = self.store.save(job.states, job.others)
        except Exception as exc:  # contained: a writer that died would answer no one
            return SaveResult(job.seq, job, error=str(exc))
        return SaveResult(job.seq, job, aside=aside, backup_problem=self.store.backup_problem)
