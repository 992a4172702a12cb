"""Control socket: JSON lines over a real unix socket, served through a real selector."""

from __future__ import annotations

import json
import selectors
import socket
import stat
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from emlogd.client import request
from emlogd.daemon.control import (
    IDLE_S,
    MAX_CLIENTS,
    MAX_REQUEST,
    PATH_CHECK_S,
    REQUEST_S,
    SEND_S,
    STATUS_REUSE,
    ControlServer,
    Deferred,
)

BIG = 3 << 20
"""An answer's size past any socket buffer, bytes (the status of a thousand UUTs is 2 MB)."""


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


def test_a_key_the_command_does_not_take_is_refused(loop: _Loop, tmp_path: Path) -> None:
    """``{"cmd": "freeze", "on": false}`` (an unfreeze meant) and ``"on"`` with ``status``
    or ``reset`` are refused naming the key and the command's keys, and never reach the
    handler: the freeze was carried out, the ``on`` ignored."""
    path = tmp_path / "run" / "control.sock"
    for cmd in ("freeze", "status", "reset"):
        answer = request(path, {"cmd": cmd, "on": False})
        assert answer == {
            "ok": False,
            "error": f"{cmd} takes no 'on'; its keys: cmd, port",
        }, answer
    assert loop.seen == []
    assert request(path, {"cmd": "learn", "port": "emlog1", "on": True})["ok"] is True


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


def test_duplicate_keys_are_refused(loop: _Loop, tmp_path: Path) -> None:
    """A request naming a key twice (JSON's last-one-wins would make it a reset) is refused
    with an error naming the key, and never reaches the handler."""
    path = tmp_path / "run" / "control.sock"
    for line, key in (
        (b'{"cmd":"status","cmd":"reset"}\n', "cmd"),
        (b'{"cmd":"reset","port":"emlog1","port":"nope"}\n', "port"),
    ):
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(5)
            s.connect(str(path))
            s.sendall(line)
            data = s.recv(4096)
        assert data == b'{"ok": false, "error": "duplicate key \'' + key.encode() + b"'\"}\n"
    assert loop.seen == []


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class _Sync:
    """A control server on a clock the test moves, served from the test's thread."""

    def __init__(self, path: Path) -> None:
        self.clock = _Clock()
        self.sel = selectors.DefaultSelector()
        self.server = ControlServer(
            path, lambda req: {"echo": req["cmd"]}, self.sel, monotonic=self.clock
        )

    def pump(self, s: float = 0.05) -> None:
        end = time.monotonic() + s
        while time.monotonic() < end:
            for key, _ in self.sel.select(timeout=0.01):
                key.data()


@pytest.fixture
def sync(tmp_path: Path) -> Iterator[_Sync]:
    srv = _Sync(tmp_path / "s.sock")
    yield srv
    srv.server.close()
    srv.sel.close()


def _connect(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(5)
    s.connect(str(path))
    return s


def _rest(s: socket.socket) -> bytes:
    """What the server sent until it closed the connection."""
    data = b""
    while chunk := s.recv(4096):
        data += chunk
    return data


def test_a_request_dripped_byte_by_byte_times_out(sync: _Sync, tmp_path: Path) -> None:
    """A client sending a byte a second is served no longer than REQUEST_S after its first
    byte: then an error line and the connection closed, though it never went quiet."""
    path = tmp_path / "s.sock"
    drip = _connect(path)
    sync.pump()
    sent = 0
    while sync.clock.t <= REQUEST_S:
        drip.sendall(b'{"cmd": "status"}'[sent % 10 : sent % 10 + 1])
        sent += 1
        sync.pump(0.02)
        sync.server.housekeep()
        assert len(sync.server.clients) == 1, sync.clock.t
        sync.clock.t += 1.0
    sync.pump(0.02)
    sync.server.housekeep()
    assert not sync.server.clients and sync.server.timed_out == 1
    assert _rest(drip) == b'{"ok": false, "error": "request not complete within 5 s"}\n'
    drip.close()


def test_at_the_client_limit_a_newcomer_is_served(sync: _Sync, tmp_path: Path) -> None:
    """With MAX_CLIENTS clients holding unfinished requests, a newcomer's status is answered
    at once and the client waiting longest is closed with an error line; a client that just
    completed a request outlives older unfinished ones."""
    path = tmp_path / "s.sock"
    held = []
    for _ in range(MAX_CLIENTS):
        s = _connect(path)
        held.append(s)
        sync.pump(0.02)
        s.sendall(b'{"cmd"')
        sync.pump(0.02)
        sync.clock.t += 0.1
    held[0].sendall(b': "status"}\n')  # the oldest completes its request: now the newest
    sync.pump(0.02)
    assert held[0].recv(4096) == b'{"ok": true, "echo": "status"}\n'
    sync.clock.t += 0.1
    newcomer = _connect(path)
    newcomer.sendall(b'{"cmd": "status"}\n')
    sync.pump(0.05)
    assert newcomer.recv(4096) == b'{"ok": true, "echo": "status"}\n'
    assert sync.server.evicted == 1 and len(sync.server.clients) == MAX_CLIENTS
    assert b"too many clients" in _rest(held[1])
    for s in [*held, newcomer]:
        s.close()


def _ask(sync: _Sync, path: Path) -> bytes:
    """A status request's answer through ``path``, served from the test's thread."""
    with _connect(path) as s:
        s.sendall(b'{"cmd": "status"}\n')
        sync.pump(0.05)
        return s.recv(4096)


def test_a_request_ended_by_the_end_of_file_is_answered(sync: _Sync, tmp_path: Path) -> None:
    """A request without its newline, the client then ending its sending (``printf
    '{"cmd":"status"}' | socat - UNIX-CONNECT:…``), is answered and the connection
    closed; an end of file after nothing, or after blanks, closes it with no answer.
    The request was dropped with the connection: the operator got nothing."""
    for sent, answer in (
        (b'{"cmd": "status"}', b'{"ok": true, "echo": "status"}\n'),
        (b'{"cmd": "freeze"}\n{"cmd": "learn"}', b'"echo": "learn"}\n'),
        (b"", b""),
        (b"  ", b""),
    ):
        with _connect(tmp_path / "s.sock") as s:
            s.sendall(sent)
            s.shutdown(socket.SHUT_WR)
            sync.pump(0.1)
            got = _rest(s)
        assert got.endswith(answer) and bool(got) == bool(answer), (sent, got)
    assert not sync.server.clients


def test_a_removed_socket_file_is_made_again(sync: _Sync, tmp_path: Path) -> None:
    """The socket file removed under the running server (by hand, a clean-up of the run
    directory): within PATH_CHECK_S it is bound again and answers, a client connected
    before is still served, the event logged once; a path that names another file is
    left to it (logged once) and survives the server's close. The listening socket
    behind the removed name took no connection until a restart."""
    events: list[tuple[str, str]] = []
    sync.server.on_event = lambda kind, detail: events.append((kind, detail))
    path = tmp_path / "s.sock"
    before = _connect(path)
    sync.pump()
    path.unlink()
    with pytest.raises(OSError):
        _connect(path)
    sync.server.housekeep()
    assert not path.exists()  # not checked before PATH_CHECK_S
    sync.clock.t += PATH_CHECK_S
    sync.server.housekeep()
    assert stat.S_ISSOCK(path.lstat().st_mode) and sync.server.rebound == 1
    assert _ask(sync, path) == b'{"ok": true, "echo": "status"}\n'
    before.sendall(b'{"cmd": "status"}\n')
    sync.pump()
    assert before.recv(4096) == b'{"ok": true, "echo": "status"}\n'
    before.close()
    assert [k for k, _ in events] == ["control_socket_restored"]
    path.unlink()
    path.write_text("another's")
    for _ in range(3):
        sync.clock.t += PATH_CHECK_S
        sync.server.housekeep()
    assert [k for k, _ in events] == ["control_socket_restored", "control_socket_path"]
    assert "names another file" in events[-1][1]
    sync.server.close()
    assert path.read_text() == "another's"


class _BigLoop(_Loop):
    """The loop, its ``status`` answer :data:`BIG` bytes long."""

    def handle(self, req: dict[str, object]) -> dict[str, object]:
        if req["cmd"] == "status":
            return {"blob": "x" * BIG}
        return super().handle(req)


def test_an_answer_larger_than_the_socket_buffer_arrives_whole(tmp_path: Path) -> None:
    """A 3 MB answer reaches the client whole, and the requests sent after it in the same
    write are answered after it, in order. The rest of the first ``send`` (a few hundred
    KB) was lost: the client waited for its newline until its timeout."""
    lp = _BigLoop(tmp_path / "run" / "control.sock")
    try:
        answer = request(tmp_path / "run" / "control.sock", {"cmd": "status"}, timeout_s=10)
        assert answer["ok"] is True and answer["blob"] == "x" * BIG
        s = _connect(tmp_path / "run" / "control.sock")
        with s:
            s.sendall(b'{"cmd": "status"}\n{"cmd": "freeze"}\n{"cmd": "learn"}\n')
            f = s.makefile("rb")
            lines = [f.readline() for _ in range(3)]
        assert len(lines[0]) > BIG and b'"echo": "freeze"' in lines[1]
        assert b'"echo": "learn"' in lines[2]
    finally:
        lp.close()


def test_a_client_not_taking_its_answer_is_closed_the_others_served(tmp_path: Path) -> None:
    """A client asking for a 3 MB answer and reading nothing holds it no longer than
    ``SEND_S``: then it is closed (counted ``unread``); another client is answered
    meanwhile."""
    clock = _Clock()
    sel = selectors.DefaultSelector()
    server = ControlServer(
        tmp_path / "s.sock",
        lambda req: {"blob": "x" * BIG} if req["cmd"] == "status" else {"echo": req["cmd"]},
        sel,
        monotonic=clock,
    )

    def pump() -> None:
        for key, _ in sel.select(timeout=0.05):
            key.data()

    try:
        idle = _connect(tmp_path / "s.sock")
        idle.sendall(b'{"cmd": "status"}\n')
        pump()
        other = _connect(tmp_path / "s.sock")
        other.sendall(b'{"cmd": "freeze"}\n')
        for _ in range(4):
            pump()
        assert b'"echo": "freeze"' in other.recv(4096)
        clock.t += SEND_S / 2
        server.housekeep()
        assert server.unread == 0 and len(server.clients) == 2
        clock.t += SEND_S
        server.housekeep()
        assert server.unread == 1 and len(server.clients) == 1
        idle.close()
        other.close()
    finally:
        server.close()
        sel.close()


def test_a_status_asked_by_many_at_once_is_built_once(tmp_path: Path) -> None:
    """Eight clients asking ``status`` at one moment, its building taking 0.1 s: the
    answer is built once and sent to each (a 1000-UUT status takes the daemon's thread
    0.1 s: built for each, a dozen clients asking in a loop held every output for
    seconds); STATUS_REUSE times its building later, after another command, and for
    other arguments it is built anew."""
    clock = _Clock()
    built: list[dict[str, object]] = []

    def handle(req: dict[str, object]) -> dict[str, object]:
        built.append(req)
        clock.t += 0.1  # what building it took
        return {"n": len(built)}

    sel = selectors.DefaultSelector()
    path = tmp_path / "s.sock"
    server = ControlServer(path, handle, sel, monotonic=clock)
    sync = _Sync.__new__(_Sync)
    sync.sel = sel
    try:
        clients = [_connect(path) for _ in range(8)]
        for s in clients:
            s.sendall(b'{"cmd": "status"}\n')
        sync.pump(0.2)
        assert [json.loads(s.recv(4096))["n"] for s in clients] == [1] * 8
        clock.t += 0.1 * STATUS_REUSE - 0.01
        assert _ask(sync, path) == b'{"ok": true, "n": 1}\n'
        clock.t += 0.01
        assert json.loads(_ask(sync, path))["n"] == 2
        with _connect(path) as s:
            s.sendall(b'{"cmd": "status", "port": "emlog1"}\n{"cmd": "reset"}\n')
            sync.pump(0.05)
        assert len(built) == 4
        assert json.loads(_ask(sync, path))["n"] == 5  # the reset ended the reuse
        for s in clients:
            s.close()
    finally:
        server.close()
        sel.close()


def test_a_server_told_to_wait_makes_its_socket_once_the_path_is_free(tmp_path: Path) -> None:
    """A regular file at the path: without ``wait`` a ``DeviceError``; with it the server
    says why (``control_socket_path``), answers nothing, and makes its socket at the path
    check after the file is gone, then answers. Another live server's socket at the path
    is a ``DeviceError`` either way."""
    path = tmp_path / "c.sock"
    path.write_text("not a socket")
    sel = selectors.DefaultSelector()
    clock = _Clock()
    notes: list[tuple[str, str]] = []
    with pytest.raises(DeviceError, match="Address already in use"):
        ControlServer(path, lambda req: {}, sel, monotonic=clock)
    srv = ControlServer(
        path,
        lambda req: {"echo": req["cmd"]},
        sel,
        monotonic=clock,
        on_event=lambda k, d: notes.append((k, d)),
        wait=True,
    )
    try:
        assert [k for k, _ in notes] == ["control_socket_path"] and "cannot be made" in notes[0][1]
        path.unlink()
        clock.t += PATH_CHECK_S
        srv.housekeep()
        assert path.is_socket() and notes[-1][0] == "control_socket_restored"
        with pytest.raises(DeviceError, match="in use by another process"):
            ControlServer(path, lambda req: {}, sel, monotonic=clock, wait=True)
        with _connect(path) as s:
            s.sendall(b'{"cmd": "status"}\n')
            for key, _ in sel.select(timeout=1.0):
                key.data()
            for key, _ in sel.select(timeout=1.0):
                key.data()
            assert s.recv(4096) == b'{"ok": true, "echo": "status"}\n'
    finally:
        srv.close()
        sel.close()


def test_a_deferred_answer_holds_its_client_alone(tmp_path: Path) -> None:
    """A handler that answers a ``freeze`` later (:class:`Deferred`, the daemon's wait for
    its save): that client gets nothing, and its next request (pipelined) is not
    answered, until the answer is settled; another client is served meanwhile, and an
    idle check does not close the waiting one. Then it gets the freeze's answer, then
    the next's, in order."""
    pending: list[Deferred] = []

    def handle(req: dict[str, object]) -> dict[str, object] | Deferred:
        if req["cmd"] == "freeze":
            pending.append(Deferred())
            return pending[-1]
        return {"echo": req["cmd"]}

    clock = _Clock()
    sel = selectors.DefaultSelector()
    path = tmp_path / "s.sock"
    server = ControlServer(path, handle, sel, monotonic=clock)

    def pump(s: float = 0.05) -> None:
        end = time.monotonic() + s
        while time.monotonic() < end:
            for key, _ in sel.select(timeout=0.01):
                key.data()

    try:
        waiting = _connect(path)
        waiting.sendall(b'{"cmd": "freeze"}\n{"cmd": "learn", "on": true}\n')
        pump()
        assert len(pending) == 1
        waiting.settimeout(0.1)
        with pytest.raises(TimeoutError):
            waiting.recv(4096)
        with _connect(path) as other:
            other.sendall(b'{"cmd": "status"}\n')
            pump()
            assert other.recv(4096) == b'{"ok": true, "echo": "status"}\n'
        clock.t += IDLE_S + 1
        server.housekeep()
        assert len(server.clients) == 1
        pending[0].answer({"persisted": True})
        pump()
        waiting.settimeout(5)
        got = b""
        while got.count(b"\n") < 2:
            got += waiting.recv(4096)
        assert got == b'{"ok": true, "persisted": true}\n{"ok": true, "echo": "learn"}\n'
        waiting.sendall(b'{"cmd": "freeze"}\n')
        pump()
        pending[1].refuse("not saved")
        assert waiting.recv(4096) == b'{"ok": false, "error": "not saved"}\n'
        waiting.close()
    finally:
        server.close()
        sel.close()
