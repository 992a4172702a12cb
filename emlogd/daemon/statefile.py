"""Persistence of the applied calibration: the state file, written atomically.

The file is a calibration file (:mod:`emlogd.calfile`): one record per UUT,
including the UUTs the operator reset (so a reset survives a restart). Writing is
crash-safe:

1. the new content goes to a temporary file in the same directory, flushed and
   fsync-ed;
2. if the current file is valid it is hard-linked to ``<file>.bak`` (through a
   temporary name and a rename, so the backup is always a whole good file);
3. the temporary file is renamed over the current one (atomic) and the directory
   is fsync-ed.

A kill -9 at any point leaves the previous or the new file, never a torn one.
A state file that is a symlink (a state kept on another volume) is written through
its link: every step above happens at its real path (:attr:`StateStore.real_path`),
beside which the backup, the refused file and the lock are kept; the link stays a
link.
A write that fails (disk full, read-only, permissions) raises
:class:`StateWriteError` and leaves the previous file untouched; so does a directory
at the file's path, which is never moved aside (a path ending in ``/`` names the
directory the file was meant to be in). On load a file
that cannot be parsed (or is no regular file, or longer than :data:`MAX_STATE_BYTES`), or whose records the caller's check refuses (parameters
outside the envelope, a lag outside ``[0, max_lag_s]``, a covariance that is not
positive-definite...), is reported and the backup used; without a good one the
daemon starts uncalibrated. Such a file never becomes the backup: the next write
moves it aside to ``<file>.refused`` (kept for a person to look at) and leaves the
backup as it is. A directory where the backup or the refused file goes, or a file
there that cannot be replaced (immutable, another user's in a sticky directory), costs
that step alone (:attr:`StateStore.backup_problem` says so): the new file is written all
the same, since a state that can never be saved again loses every calibration learnt
from then on at the next restart.

Besides the calibration in use, each UUT keeps its last calibration of every other
error model (``others``, :func:`emlogd.calfile.loads_state`): a config that switches
a UUT from EM3 to EM4 and back finds its EM3 calibration again, after a restart too.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import os
import re
import stat
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from drivers.errors import EmlogdError
from emlogd.calfile import CalibrationFileError, dumps, loads_state
from emlogd.fileio import fsync_dir, read_text_bounded, write_synced
from emlogd.pipeline.calibration import Calibration

STATE_RETRY_S = 30.0
"""How long after a failed save (a full or read-only disk) the daemon tries it again, s,
until one succeeds: what an operator froze or reset, or the learner persisted, reaches
the disk once it can, not only at the stop."""

MAX_STATE_BYTES = 256 * 1024
"""Longest state file read, bytes, for up to 16 UUTs (:data:`MAX_STATE_BYTES_PER_UUT`
each past them). A longer file, or one that is not a regular file (a FIFO would block
the read for ever, a directory), is damaged: reported unparsed, and the backup used."""

MAX_STATE_BYTES_PER_UUT = 16 * 1024
"""What each UUT of the config adds to the longest state file read, bytes (a UUT's
records of its error models take a few KiB). With one bound for any config, the
daemon wrote a state file of 1000 UUTs (0.5 MB) that its next start refused as
damaged: every calibration lost."""


def max_state_bytes(uuts: int) -> int:
    """The longest state file read for a config of ``uuts`` UUTs, bytes."""
    return max(MAX_STATE_BYTES, uuts * MAX_STATE_BYTES_PER_UUT)


class StateWriteError(EmlogdError):
    """The state file could not be written; the previous file is intact."""


class StateLockedError(EmlogdError):
    """Another process holds the state file's lock."""


LOCK_FLAGS = os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
"""How the lock file is opened: a symlink at its path is not followed, a FIFO's open
does not wait for a writer."""


def _open_lock(path: Path) -> int | None:
    """``path``, the lock file, opened for reading and writing (created if missing), else
    for reading (a read-only directory); None if neither can be done. A symlink at the
    path is not the daemon's (it makes none there): removed, and a lock file made in its
    place."""
    for _ in range(2):
        try:
            return os.open(path, os.O_RDWR | os.O_CREAT | LOCK_FLAGS, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP and path.is_symlink():
                with contextlib.suppress(OSError):
                    path.unlink()
                    continue
            try:
                return os.open(path, os.O_RDONLY | LOCK_FLAGS)
            except OSError:
                return None
    return None


class StateStore:
    """The state file and its backup.

    Args:
        path: the state file (its directory must exist or be creatable).
        uuts: the UUTs of the config, which bound the file read (:func:`max_state_bytes`).
    """

    def __init__(self, path: str | Path, uuts: int = 1) -> None:
        self.path = Path(path)
        self.max_bytes = max_state_bytes(uuts)
        """The longest file read (and written: a longer one would not load)."""
        self.backup_problem: str | None = None
        """Why the last :meth:`save` kept no backup, or set no refused file aside (a
        directory in the way), or None."""
        self._check: Callable[[Calibration], str] | None = None
        """The check of the last :meth:`load`: a current file it refuses is no backup."""
        self._saved: tuple[int, int, int, int] | None = None
        """The identity of the file the last :meth:`save` wrote (:func:`_identity`)."""

    @property
    def real_path(self) -> Path:
        """The state file with every symlink resolved (of the file and its directories)."""
        return Path(os.path.realpath(self.path))

    @property
    def backup(self) -> Path:
        """The backup: ``<file>.bak`` next to the state file's real path."""
        real = self.real_path
        return real.with_name(real.name + ".bak")

    @property
    def refused(self) -> Path:
        """Where a damaged or refused state file is moved by the next write:
        ``<file>.refused`` next to its real path."""
        real = self.real_path
        return real.with_name(real.name + ".refused")

    @property
    def lock_path(self) -> Path:
        """The lock file next to the state file's real path: two instances reaching one
        file through different names (a symlink, a symlinked directory) share one lock."""
        real = self.real_path
        return real.with_name(real.name + ".lock")

    def lock(self) -> int | None:
        """Take the state file's lock for this process (released when it exits).

        An exclusive ``flock`` on ``<file>.lock`` next to the file's real path
        (:attr:`lock_path`), which then holds the pid. Returns
        the lock's descriptor, or None when no lock file can be opened at all (a
        read-only or missing directory: writes will fail and be reported anyway).

        The lock's path is never followed as a symlink (:func:`_open_lock`), and the pid
        is written only into a regular file of one link: a symlink or a hard link planted
        there (to the state file itself, to any file the daemon may write) had its target
        truncated and the pid written in its place — the state file and its calibration
        lost at the start.

        Raises:
            StateLockedError: another process holds it (the message names its pid).
        """
        path = self.lock_path
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
        fd = _open_lock(path)
        if fd is None:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown"
            finally:
                os.close(fd)
            real = self.real_path
            via = f" (real path {real})" if real != self.path.absolute() else ""
            raise StateLockedError(
                f"{self.path}{via} is in use by another emlogd (pid {holder}; lock {path})"
            ) from None
        with contextlib.suppress(OSError):
            st = os.fstat(fd)
            if stat.S_ISREG(st.st_mode) and st.st_nlink == 1:  # the lock's own file only
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        return fd

    def load(
        self, check: Callable[[Calibration], str] | None = None
    ) -> tuple[dict[str, Calibration], list[str]]:
        """Load the calibrations in use; returns (records, report lines about problems
        met). See :meth:`load_state`."""
        states, _, report = self.load_state(check)
        return states, report

    def load_state(
        self, check: Callable[[Calibration], str] | None = None
    ) -> tuple[dict[str, Calibration], list[Calibration], list[str]]:
        """Load the calibrations in use by UUT, the UUTs' calibrations of their other
        models, and report lines about problems met.

        A missing file gives no record and no report; a damaged one — or one with a
        record ``check`` refuses (it returns why) — is reported and the backup tried.
        ``check`` is kept: the next :meth:`save` judges the current file with it.
        """
        self._check = check
        report: list[str] = []
        for candidate in (self.path, self.backup):
            try:
                text = read_text_bounded(candidate, self.max_bytes)
            except FileNotFoundError:
                if candidate == self.path and self.backup.exists():
                    report.append(f"{candidate} is missing")
                    continue
                if candidate == self.path:
                    return {}, [], report
                continue
            except (OSError, UnicodeDecodeError) as exc:
                report.append(f"{candidate} cannot be read: {exc}")
                continue
            why = _refusal(text, check)
            if why:
                report.append(f"{candidate} is {why}")
                continue
            states, others = loads_state(text)
            if candidate == self.backup:
                report.append(f"using the backup {candidate}")
            return states, others, report
        report.append("no usable state file: starting uncalibrated")
        return {}, [], report

    def save(
        self, states: Mapping[str, Calibration], others: Iterable[Calibration] = ()
    ) -> Path | None:
        """Write atomically, keeping the previous good file as ``.bak``; ``others``: the
        UUTs' calibrations of their other error models.

        Returns where a current file that is damaged, or that the last :meth:`load`'s
        check refuses, was moved aside (:attr:`refused`), or None.

        Raises:
            StateWriteError: the write failed; the previous file is intact.
        """
        data = dumps(states, others=others).encode("utf-8")
        if len(data) > self.max_bytes:  # it would not load: keep the file that does
            raise StateWriteError(
                f"cannot write {self.path}: {len(data)} bytes, past the {self.max_bytes} "
                "a load reads"
            )
        self.backup_problem = None
        real = self.real_path  # a symlink's target replaced, the link left a link
        if _is_device(real):  # no temporary file beside it (in /dev for /dev/null)
            raise StateWriteError(
                f"cannot write {self.path}: a device or a socket, left where it is"
            )
        d = real.parent
        tmp = d / f".{real.name}.{os.getpid()}.tmp"
        try:
            d.mkdir(parents=True, exist_ok=True)
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()  # whatever is there: a FIFO would hold the open for a reader
            write_synced(tmp, data)
            aside = self._backup_current(real)
            tmp.replace(real)
            fsync_dir(d)
            self._saved = _identity(real)
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise StateWriteError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._remove_orphans(real)
        return aside

    def holds_last_save(self) -> bool:
        """Whether the state file is still the file the last :meth:`save` wrote (same
        inode, size and modification time): False once another process removed, replaced
        or edited it, or before any save. A save skipped because nothing changed would
        otherwise leave such a file in place, and the next start load it, or nothing."""
        try:
            return self._saved is not None and _identity(self.real_path) == self._saved
        except OSError:
            return False

    def _remove_orphans(self, real: Path) -> None:
        """Delete temporary files left by a writer that was killed (its pid is gone)
        beside ``real``, the state file's real path."""
        orphan = re.compile(rf"\.{re.escape(real.name)}(?:\.bak)?\.([0-9]+)\.tmp")
        try:
            entries = list(real.parent.iterdir())
        except OSError:
            return
        for entry in entries:
            m = orphan.fullmatch(entry.name)
            if m is not None and int(m[1]) != os.getpid() and not _alive(int(m[1])):
                with contextlib.suppress(OSError):
                    entry.unlink()

    def _backup_current(self, real: Path) -> Path | None:
        """Make the current file (at its real path ``real``), if good, the backup; move a
        damaged or refused one aside to :attr:`refused` (the backup stays); return where,
        or None.

        The backup is a hard link, or a copy where the file system has none (vfat).
        """
        try:
            text = read_text_bounded(real, self.max_bytes)
        except FileNotFoundError:
            return None
        except (OSError, UnicodeDecodeError):
            text = None
        if text is None and real.is_dir():
            # a directory is no damaged state file: a path ending in "/" names the
            # directory it was meant to be in, whose files no save may move away
            raise IsADirectoryError(errno.EISDIR, "a directory, left where it is")
        if text is None and _is_device(real):
            # a device (state_file: /dev/null, meant as "no state") is no damaged file:
            # moved aside, the node itself would be renamed and a file made in its place
            raise OSError(errno.ENODEV, "a device or a socket, left where it is")
        bad = text is None or _refusal(text, self._check)
        refused, backup = self.refused, self.backup
        step = refused if bad else backup
        if step.is_dir():  # no file goes over a directory: that step alone is skipped
            what = "the refused file not set aside" if bad else "no backup kept"
            self.backup_problem = f"{what}: {step} is a directory"
            return None
        if bad or text is None:
            # never back up a damaged or refused file over a good backup
            try:
                real.replace(refused)
            except OSError as exc:  # e.g. an immutable file there: that step alone fails
                self.backup_problem = f"the refused file not set aside: {step}: {_why(exc)}"
                return None
            return refused
        link = real.with_name(f".{real.name}.bak.{os.getpid()}.tmp")
        try:
            with contextlib.suppress(FileNotFoundError):
                link.unlink()
            try:
                os.link(real, link)
            except OSError:  # e.g. vfat: no hard links
                write_synced(link, text.encode("utf-8"))
            link.replace(backup)
        except OSError as exc:  # e.g. an immutable .bak, one of another user in a
            # sticky directory: the backup alone is not kept, the new file is written
            self.backup_problem = f"no backup kept: {backup}: {_why(exc)}"
        # rename() between two names of one file does nothing: after a writer killed
        # between linking the backup and replacing the file, both are one inode
        with contextlib.suppress(OSError):
            link.unlink()
        return None


def _is_device(path: Path) -> bool:
    """Whether ``path`` itself (not a symlink's target) is a device node or a socket."""
    try:
        mode = path.lstat().st_mode
    except OSError:
        return False
    return stat.S_ISCHR(mode) or stat.S_ISBLK(mode) or stat.S_ISSOCK(mode)


def _identity(path: Path) -> tuple[int, int, int, int]:
    """A file's device, inode, size and modification time (ns), symlinks not followed."""
    st = path.lstat()
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _why(exc: OSError) -> str:
    """An ``OSError``'s reason without its file names."""
    return exc.strerror or str(exc)


def _refusal(text: str, check: Callable[[Calibration], str] | None) -> str:
    """``""`` when a state file's text is good, else what is wrong with it (``damaged:
    …`` or ``refused: …``, every record — in use and of other models — checked)."""
    try:
        states, others = loads_state(text)
    except CalibrationFileError as exc:
        return f"damaged: {exc}"
    if check is None:
        return ""
    refused = [
        f"{cal.uut}{'' if cal is states.get(cal.uut) else ' ' + cal.params.model}: {why}"
        for cal in (*states.values(), *others)
        if (why := check(cal))
    ]
    return f"refused: {'; '.join(refused)}" if refused else ""


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one owned by another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def same_records(a: list[Calibration], b: list[Calibration], *, material: bool) -> bool:
    """Whether two sets of records are equal but for their time (``material``: and but
    for what learning refines: covariance, current, NIS, sample count)."""
    return [_record_key(c, material) for c in a] == [_record_key(c, material) for c in b]


def _record_key(c: Calibration, material: bool) -> Calibration:
    if not material:
        return dataclasses.replace(c, t=0.0)
    return dataclasses.replace(
        c,
        t=0.0,
        covariance=(),
        estimate=dataclasses.replace(c.estimate, current_mps=None, current_std_mps=None),
        nis_mean=None,
        n_samples=0,
        unidentifiable=(),
    )
