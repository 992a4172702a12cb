"""Shared fixtures: real pseudo-terminals and capture files on disk."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest

from drivers.capture import CaptureWriter


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
def make_capture(tmp_path: Path) -> Callable[..., Path]:
    """Write a capture: make_capture({port: protocol}, [(t, port, bytes, binary)], name=...)."""

    def make(
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

    return make
