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
A write that fails (disk full, read-only, permissions) raises
:class:`StateWriteError` and leaves the previous file untouched. On load a file
that cannot be parsed, or whose records the caller's check refuses (parameters
outside the envelope, a covariance that is not positive-definite...), is reported
and the backup used; without a good one the daemon starts uncalibrated.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
from collections.abc import Callable, Mapping
from pathlib import Path

from drivers.errors import EmlogdError
from emlogd.calfile import CalibrationFileError, dumps, loads
from emlogd.fileio import fsync_dir, write_synced
from emlogd.pipeline.calibration import Calibration


class StateWriteError(EmlogdError):
    """The state file could not be written; the previous file is intact."""


class StateLockedError(EmlogdError):
    """Another process holds the state file's lock."""


class StateStore:
    """The state file and its backup.

    Args:
        path: the state file (its directory must exist or be creatable).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.backup = self.path.with_name(self.path.name + ".bak")

    @property
    def real_path(self) -> Path:
        """The state file with every symlink resolved (of the file and its directories)."""
        return Path(os.path.realpath(self.path))

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

        Raises:
            StateLockedError: another process holds it (the message names its pid).
        """
        path = self.lock_path
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            try:
                fd = os.open(path, os.O_RDONLY)
            except OSError:
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
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode("ascii"), 0)
        return fd

    def load(
        self, check: Callable[[Calibration], str] | None = None
    ) -> tuple[dict[str, Calibration], list[str]]:
        """Load the calibrations; returns (records, report lines about problems met).

        A missing file gives no record and no report; a damaged one — or one with a
        record ``check`` refuses (it returns why) — is reported and the backup tried.
        """
        report: list[str] = []
        for candidate in (self.path, self.backup):
            try:
                text = candidate.read_text(encoding="utf-8")
            except FileNotFoundError:
                if candidate == self.path and self.backup.exists():
                    report.append(f"{candidate} is missing")
                    continue
                if candidate == self.path:
                    return {}, report
                continue
            except (OSError, UnicodeDecodeError) as exc:
                report.append(f"{candidate} cannot be read: {exc}")
                continue
            try:
                states, _ = loads(text)
            except CalibrationFileError as exc:
                report.append(f"{candidate} is damaged: {exc}")
                continue
            refused = [
                f"{uut}: {why}"
                for uut, cal in states.items()
                if check is not None and (why := check(cal))
            ]
            if refused:
                report.append(f"{candidate} is refused: {'; '.join(refused)}")
                continue
            if candidate == self.backup:
                report.append(f"using the backup {candidate}")
            return states, report
        report.append("no usable state file: starting uncalibrated")
        return {}, report

    def save(self, states: Mapping[str, Calibration]) -> None:
        """Write atomically, keeping the previous good file as ``.bak``.

        Raises:
            StateWriteError: the write failed; the previous file is intact.
        """
        data = dumps(states).encode("utf-8")
        d = self.path.parent
        tmp = d / f".{self.path.name}.{os.getpid()}.tmp"
        try:
            d.mkdir(parents=True, exist_ok=True)
            write_synced(tmp, data)
            self._backup_current()
            tmp.replace(self.path)
            fsync_dir(self.path.parent)
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise StateWriteError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._remove_orphans()

    def _remove_orphans(self) -> None:
        """Delete temporary files left by a writer that was killed (its pid is gone)."""
        orphan = re.compile(rf"\.{re.escape(self.path.name)}(?:\.bak)?\.([0-9]+)\.tmp")
        try:
            entries = list(self.path.parent.iterdir())
        except OSError:
            return
        for entry in entries:
            m = orphan.fullmatch(entry.name)
            if m is not None and int(m[1]) != os.getpid() and not _alive(int(m[1])):
                with contextlib.suppress(OSError):
                    entry.unlink()

    def _backup_current(self) -> None:
        """Make the current file, if valid, the backup; a damaged one is left out.

        The backup is a hard link, or a copy where the file system has none (vfat).
        """
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return
        except (OSError, UnicodeDecodeError):
            return
        try:
            loads(text)
        except CalibrationFileError:
            return  # never back up a damaged file over a good backup
        link = self.path.with_name(f".{self.path.name}.bak.{os.getpid()}.tmp")
        with contextlib.suppress(FileNotFoundError):
            link.unlink()
        try:
            os.link(self.path, link)
        except OSError:  # e.g. vfat: no hard links
            write_synced(link, text.encode("utf-8"))
        link.replace(self.backup)
        # rename() between two names of one file does nothing: after a writer killed
        # between linking the backup and replacing the file, both are one inode
        with contextlib.suppress(FileNotFoundError):
            link.unlink()


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one owned by another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True
