"""The control-socket client against real unix sockets."""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from emlogd.client import request


def _serve(path: Path, reply: Callable[[socket.socket], None]) -> threading.Thread:
    """A unix socket at ``path`` whose first client ``reply`` serves, in a thread."""
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(str(path))
    srv.listen(1)

    def run() -> None:
        with srv:
            conn, _ = srv.accept()
            with conn:
                reply(conn)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def _serve_once(path: Path, answer: bytes) -> threading.Thread:
    """A unix socket at ``path`` that reads one line and sends ``answer``, in a thread."""

    def reply(conn: socket.socket) -> None:
        buf = b""
        while b"\n" not in buf:
            buf += conn.recv(4096)
        conn.sendall(answer)

    return _serve(path, reply)


def test_request_sends_one_line_and_returns_the_answer(tmp_path: Path) -> None:
    """request() returns the JSON object of the first answer line, whatever follows it."""
    path = tmp_path / "c.sock"
    t = _serve_once(path, b'{"ok": true, "n": 1}\n{"ok": false}\n')
    assert request(path, {"cmd": "status"}) == {"ok": True, "n": 1}
    t.join(5)


@pytest.mark.parametrize("answer", [b"not json\n", b"[1, 2]\n", b""])
def test_a_malformed_answer_is_a_device_error(tmp_path: Path, answer: bytes) -> None:
    """An answer that is not a JSON object (or none) raises DeviceError naming the socket."""
    path = tmp_path / "c.sock"
    t = _serve_once(path, answer)
    with pytest.raises(DeviceError, match="malformed answer"):
        request(path, {"cmd": "status"})
    t.join(5)


def test_request_without_daemon_is_a_clear_error(tmp_path: Path) -> None:
    """request() to a missing socket raises DeviceError asking whether emlogd is running."""
    with pytest.raises(DeviceError, match="is emlogd running"):
        request(tmp_path / "missing.sock", {"cmd": "status"})


def test_an_answer_that_never_ends_is_refused_in_bounded_time(tmp_path: Path) -> None:
    """A peer at the socket's path that streams bytes without a newline for as long as it
    is read: a ``DeviceError`` within the timeout, holding at most ``MAX_ANSWER`` bytes
    (and a little more). The client read and held it for as long as it came, each read
    renewing the timeout."""
    path = tmp_path / "c.sock"

    def stream(conn: socket.socket) -> None:
        with contextlib.suppress(OSError):
            conn.settimeout(10.0)
            for _ in range(4000):  # 256 MiB at most, then the peer gives up
                conn.sendall(b"x" * 65536)

    t = _serve(path, stream)
    t0 = time.monotonic()
    with pytest.raises(DeviceError, match="without a newline"):
        request(path, {"cmd": "status"}, timeout_s=2.0)
    assert time.monotonic() - t0 < 4.0
    t.join(15)
