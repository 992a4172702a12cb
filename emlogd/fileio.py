"""Durable file writes: the one atomic-write routine of the project.

:func:`write_atomic` writes a temporary file in the same directory, fsyncs it,
renames it over the target (atomic on POSIX) and fsyncs the directory, so a crash
leaves the old file or the new one, never a torn one. The daemon's state file and
``emlogd calibrate --save`` both write through it.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path


def write_synced(path: Path, data: bytes, mode: int = 0o640) -> None:
    """Create or truncate ``path`` with ``mode``, write ``data`` and fsync it.

    Raises:
        OSError: the write failed.
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, mode)
    try:
        view = memoryview(data)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(directory: Path) -> None:
    """fsync a directory, so that a rename in it survives a crash.

    Raises:
        OSError: the directory cannot be opened or synced.
    """
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: Path, data: bytes, mode: int = 0o640) -> None:
    """Replace ``path`` by ``data`` atomically and durably (see the module docstring).

    Raises:
        OSError: the write failed; ``path`` is unchanged and no temporary is left.
    """
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write_synced(tmp, data, mode)
        tmp.replace(path)
        fsync_dir(path.parent if str(path.parent) else Path())
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
