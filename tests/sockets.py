"""Socket helpers of the tests: a TCP port on 127.0.0.1 that does not answer; what a
non-blocking descriptor holds now."""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Iterator


@contextlib.contextmanager
def unanswered_port() -> Iterator[int]:
    """A port on 127.0.0.1 whose listen queue is full: a SYN to it is dropped and a connect
    waits, as to a host that is off."""
    ls = socket.socket()
    fill = [socket.socket() for _ in range(3)]
    try:
        ls.bind(("127.0.0.1", 0))
        ls.listen(0)
        port = int(ls.getsockname()[1])
        for s in fill:
            s.setblocking(False)
            s.connect_ex(("127.0.0.1", port))
        time.sleep(0.1)
        yield port
    finally:
        for s in [*fill, ls]:
            s.close()


def drain(fd: int) -> bytes:
    """What the non-blocking descriptor ``fd`` (a pty's master, a pipe) holds now."""
    data = b""
    with contextlib.suppress(BlockingIOError):
        while chunk := os.read(fd, 65536):
            data += chunk
    return data
