"""Durable file writes: the one atomic-write routine of the project; and the bounded
read of a file that may be anything.

:func:`write_atomic` writes a temporary file in the same directory, fsyncs it,
renames it over the target (atomic on POSIX) and fsyncs the directory, so a crash
leaves the old file or the new one, never a torn one. The daemon's state file and
``emlogd calibrate --save`` both write through it. A file written in pieces (a capture
that ``emlogd import`` or ``replay --out`` writes) is written under
:func:`part_path` and renamed into place when complete, so no other process ever reads
it half-written. A target that exists and is no regular file (``--save /dev/stdout``,
a device, a pipe) is written in place, never renamed over: the rename replaced the
device node itself (``--save /dev/null`` run as root left a regular file at
``/dev/null``).

:func:`read_text_bounded` reads the config and the state file: whatever is found at
their path — a FIFO (whose ``open`` would wait for a writer for ever), a device, a
directory, a file of a gigabyte — is refused with an :class:`OSError` at once, without
blocking and without reading more than the bound.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
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


def part_path(path: str | Path) -> Path:
    """Where a file bound for ``path`` is written until it is complete: beside it, named
    for this process (two processes writing the same ``path`` at once each write their
    own), with ``path``'s ``.gz`` ending kept (what decides the compression)."""
    path = Path(path)
    gz = ".gz" if path.name.endswith(".gz") else ""
    return path.with_name(f".{path.name}.{os.getpid()}.part{gz}")


def replaceable(path: str | Path) -> bool:
    """Whether a file written for ``path`` may be renamed over it: nothing is there yet,
    or a regular file (through symlinks); not a device, a pipe, a socket or a directory."""
    p = Path(path)
    return p.is_file() or not p.exists()


def write_atomic(path: Path, data: bytes, mode: int = 0o640) -> None:
    """Replace ``path`` by ``data`` atomically and durably (see the module docstring).

    Raises:
        OSError: the write failed; ``path`` is unchanged and no temporary is left.
    """
    if not replaceable(path):  # a device, a pipe: written into, never replaced
        with open(path, "wb") as f:
            f.write(data)
        return
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write_synced(tmp, data, mode)
        tmp.replace(path)
        fsync_dir(path.parent if str(path.parent) else Path())
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def read_text_bounded(path: str | Path, max_bytes: int) -> str:
    """The UTF-8 text of the regular file ``path``, at most ``max_bytes`` long.

    Opened non-blocking, so a FIFO or a device at ``path`` costs no wait; at most
    ``max_bytes + 1`` bytes are read.

    Raises:
        OSError: it cannot be opened or read, is not a regular file (``EINVAL``), or is
            longer than ``max_bytes`` (``EFBIG``); the message says which.
        UnicodeDecodeError: it is not UTF-8.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            chunk = os.read(fd, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > max_bytes:
            raise OSError(errno.EFBIG, f"longer than {max_bytes} bytes", str(path))
    finally:
        os.close(fd)
    return b"".join(chunks).decode("utf-8")
