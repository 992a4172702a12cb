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
counters, log lines and control answers stay in the loop's thread: :class:`Saves`, the
loop's side, keeps them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import queue
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from emlogd.daemon.control import Deferred
from emlogd.daemon.statefile import STATE_RETRY_S, StateStore, same_records
from emlogd.pipeline.calibration import Calibration

STOP_SAVE_S = 10.0
"""Longest wait of a stop for the saves in flight and queued (the final one among them),
s: under systemd's ``TimeoutStopSec`` (15 s), so that a disk that hangs costs the last
save, logged (``state_save_pending``), not a SIGKILL."""


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


class Saves:
    """The loop's side of the writer thread: what was submitted and what landed, the
    counters, the retry after a failure, the control answers waiting for a save. Every
    method runs in the loop's thread.

    Args:
        store: the state file.
        log: the daemon's logger.
        monotonic: the clock of the retry.
    """

    def __init__(self, store: StateStore, log: Any, monotonic: Callable[[], float]) -> None:
        self.store = store
        self.log = log
        self.monotonic = monotonic
        self.saver = Saver(store)
        self.state_errors = 0
        self.persists = 0
        self.retry_at = math.inf
        """When a failed save is tried again (monotonic)."""
        self.written: list[Calibration] | None = None
        """The records last written to the state file."""
        self.submitted: list[Calibration] | None = None
        """The records of the last save submitted (the file's once it lands)."""
        self.last_seq = 0
        """The number of the last save submitted; :attr:`landed_seq`, of the last landed."""
        self.landed_seq = 0
        self.waiters: list[tuple[int, Callable[[str | None], None]]] = []
        """Answers waiting for a save: (its number, called with the error or None)."""

    @property
    def wake_fd(self) -> int:
        """Readable once a save has landed: call :meth:`landed`."""
        return self.saver.wake_fd

    def persist(
        self,
        snaps: list[Calibration],
        others: list[Calibration],
        *,
        final: bool = False,
        operator: bool = False,
    ) -> int | None:
        """Submit the calibrations in use (``snaps``) and of the other models; return the
        number of the save that will hold them, or None when the file holds them already.

        Coalesced: nothing is written when the file (or the save in flight or queued)
        holds the same records (their time aside), or for an operator's command
        (``operator``) the same calibrations (reset flags, parameters and σ, lag, model):
        a burst of ``freeze`` or ``reset`` requests costs at most one fsync per actual
        change. A file another process removed or replaced since the last save is
        written again.
        """
        self.retry_at = math.inf
        if not snaps:
            return None
        records = snaps + others
        if self.submitted is not None and same_records(records, self.submitted, material=operator):
            if self.last_seq > self.landed_seq:  # in flight or queued
                return self.last_seq
            if self.store.holds_last_save():  # not removed or replaced since
                return None
        self.submitted = records
        self.last_seq = self.saver.submit({s.uut: s for s in snaps}, others, final=final)
        return self.last_seq

    def landed(self) -> None:
        """The writer thread's results: counters, log lines, and the answers that waited
        for them (a result holds every save submitted up to its number)."""
        for r in self.saver.drain():
            self.landed_seq = max(self.landed_seq, r.seq)
            if r.error is not None:
                self.state_errors += 1
                self.retry_at = self.monotonic() + STATE_RETRY_S
                self.log.error("state_write_failed", error=r.error, final=r.job.final)
                if r.seq == self.last_seq:  # nothing newer queued: the retry writes it
                    self.submitted = self.written
            else:
                if r.aside is not None:
                    self.log.warning("state_file_set_aside", path=str(r.aside), backup_kept=True)
                if r.backup_problem is not None:  # a directory in the way: written all the same
                    self.log.warning("state_backup_failed", why=r.backup_problem)
                self.written = [*r.job.states.values(), *r.job.others]
                self.persists += 1
                self.log.info(
                    "calibration_persisted",
                    uuts=list(r.job.states),
                    final=r.job.final,
                    path=str(self.store.path),
                )
            due = [w for w in self.waiters if w[0] <= r.seq]
            self.waiters = [w for w in self.waiters if w[0] > r.seq]
            for _, call in due:
                call(r.error)

    def after(
        self, ticket: int | None, reply: Callable[[str | None], dict[str, object]]
    ) -> dict[str, object] | Deferred:
        """``reply(error)`` now when nothing is to be written (``ticket`` None), else a
        :class:`Deferred` answered with it once save ``ticket`` has landed (a
        ``ValueError`` it raises is the refusal)."""
        if ticket is None:
            return reply(None)
        answer = Deferred()

        def settle(err: str | None) -> None:
            try:
                answer.answer(reply(err))
            except ValueError as exc:
                answer.refuse(str(exc))

        self.waiters.append((ticket, settle))
        return answer

    def finish(self) -> None:
        """At the stop: wait for the saves in flight and queued (at most
        :data:`STOP_SAVE_S`), report them, end the writer thread."""
        t0 = self.monotonic()
        done = self.saver.wait_idle(STOP_SAVE_S)
        self.landed()
        waited = self.monotonic() - t0
        if not done:
            self.log.error("state_save_pending", waited_s=round(waited, 2))
            for _, call in self.waiters:
                call(f"the daemon stopped before the save landed (waited {waited:.1f} s)")
            self.waiters = []
        elif waited > 1.0:
            self.log.warning("state_save_slow", waited_s=round(waited, 2))
        self.saver.close(STOP_SAVE_S if done else 0.0)
