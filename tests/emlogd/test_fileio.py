"""The atomic, durable write."""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

import pytest

from emlogd.fileio import part_path, replaceable, write_atomic


def test_replaces_the_file_with_mode_0640(tmp_path: Path) -> None:
    """The new content replaces the old; the mode is 0640; no temporary remains."""
    p = tmp_path / "f.yaml"
    p.write_text("old")
    write_atomic(p, b"new")
    assert p.read_bytes() == b"new"
    assert p.stat().st_mode & 0o777 == 0o640
    assert sorted(x.name for x in tmp_path.iterdir()) == ["f.yaml"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """When fsync fails the old content stays and the temporary is removed."""
    p = tmp_path / "f.yaml"
    p.write_text("old")

    def fail(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", fail)
    with pytest.raises(OSError, match="No space"):
        write_atomic(p, b"new")
    assert p.read_text() == "old"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["f.yaml"]


def test_a_part_file_is_named_for_its_process(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The file being written for a path lies beside it, hidden, keeps a ``.gz`` ending, and
    differs between two processes writing the same path."""
    out = tmp_path / "o.cap.gz"
    mine = part_path(out)
    monkeypatch.setattr(os, "getpid", lambda: os.getppid())
    theirs = part_path(str(out))
    assert mine.parent == tmp_path and mine.name.startswith(".o.cap.gz.")
    assert mine.name.endswith(".gz") and not part_path(tmp_path / "o.cap").name.endswith(".gz")
    assert mine != theirs


def _drain_fifo(fifo: Path, got: list[bytes]) -> threading.Thread:
    """A reader of ``fifo`` in a thread (left behind if no writer ever opens it)."""
    t = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    t.start()
    return t


def test_a_target_that_is_no_regular_file_is_written_into_never_replaced(
    tmp_path: Path,
) -> None:
    """A FIFO (as a device: ``--save /dev/stdout``, ``/dev/null``) at the target: the data
    are written into it and it stays what it was, no temporary left. The temporary was
    renamed over it: ``calibrate --save /dev/null`` run as root replaced the device node
    by a regular file (found so with ``/dev/full``)."""
    fifo = tmp_path / "params.yaml"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = _drain_fifo(fifo, got)
    write_atomic(fifo, b"model: EM3\n")
    reader.join(5.0)
    assert got == [b"model: EM3\n"]
    assert stat.S_ISFIFO(fifo.lstat().st_mode)
    assert list(tmp_path.iterdir()) == [fifo]
    assert not replaceable(fifo) and replaceable(tmp_path / "new") and not replaceable(tmp_path)
