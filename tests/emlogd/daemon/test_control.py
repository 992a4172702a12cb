"""Control socket: JSON lines over a real unix socket, served through a real selector."""

from __future__ import annotations

import selectors
import socket
import stat
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from emlogd.client import request
from emlogd.daemon.control import MAX_REQUEST, ControlServer


class _Loop:
    """A selector loop in a thread, like the daemon's."""

    def __init__(self, path: Path) -> None:
        self.sel = selectors.DefaultSelector()
        self.seen: list[dict[str, object]] = []
        self.server = ControlServer(path, self.handle, self.sel)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def handle(self, req: dict[str, object]) -> dict[str, object]:
        self.seen.append(req)
        if req["cmd"] == "reset" and req.get("port") == "nope":
            raise ValueError("no UUT 'nope'")
        return {"echo": req["cmd"]}

    def run(self) -> None:
        while not self.stop.is_set():
            for key, _ in self.sel.select(timeout=0.05):
                key.data()

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.server.close()
        self.sel.close()


@pytest.fixture
def loop(tmp_path: Path) -> Iterator[_Loop]:
    lp = _Loop(tmp_path / "run" / "control.sock")
    yield lp
    lp.close()


def test_requests_get_one_json_answer_each(loop: _Loop, tmp_path: Path) -> None:
    """The socket is created mode 0660 and each request gets one JSON answer with ok: true; the
    handler sees the request as sent."""
    path = tmp_path / "run" / "control.sock"
    assert stat.S_IMODE(path.stat().st_mode) == 0o660
    assert request(path, {"cmd": "status"}) == {"ok": True, "echo": "status"}
    assert request(path, {"cmd": "learn", "on": False}) == {"ok": True, "echo": "learn"}
    assert loop.seen[-1] == {"cmd": "learn", "on": False}


def test_bad_requests_are_answered_not_fatal(loop: _Loop, tmp_path: Path) -> None:
    """An unknown command, a handler error, a non-JSON line and a non-object line each get
    ok: false, and the server keeps serving."""
    path = tmp_path / "run" / "control.sock"
    assert request(path, {"cmd": "explode"})["ok"] is False
    bad = request(path, {"cmd": "reset", "port": "nope"})
    assert bad == {"ok": False, "error": "no UUT 'nope'"}
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5)
        s.connect(str(path))
        s.sendall(b"not json\n[1,2]\n")
        data = b""
        while data.count(b"\n") < 2:
            data += s.recv(4096)
    assert data.count(b'"ok": false') == 2
    # the server still answers afterwards
    assert request(path, {"cmd": "freeze"})["ok"] is True


def test_an_endless_line_drops_the_client(loop: _Loop, tmp_path: Path) -> None:
    """A request longer than MAX_REQUEST without a newline is answered 'request too long' and the
    connection closed; other clients are still served."""
    path = tmp_path / "run" / "control.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5)
        s.connect(str(path))
        s.sendall(b"x" * (MAX_REQUEST + 10))
        data = b""
        while True:
            chunk = s.recv(4096)
            if not chunk:
                break
            data += chunk
    assert b"request too long" in data
    assert request(path, {"cmd": "status"})["ok"] is True


def test_close_removes_the_socket(tmp_path: Path) -> None:
    """Closing the control server removes its socket file."""
    lp = _Loop(tmp_path / "c.sock")
    lp.close()
    assert not (tmp_path / "c.sock").exists()
