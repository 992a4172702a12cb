"""The daemon's control socket: JSON lines over a unix stream socket.

Requests are one JSON object per line, ``{"cmd": "status"}``, ``{"cmd": "freeze"}``,
``{"cmd": "learn", "on": true}``, ``{"cmd": "reset", "port": "emlog1"}``; each gets
one JSON line back, ``{"ok": true, ...}`` or ``{"ok": false, "error": "..."}``. The
client's end of file (a half-close) ends its last request as a newline does.

No client can knock the server over: every line gets an answer whatever it holds
(any JSON type or nesting, unknown or duplicate keys, wrong types, invalid UTF-8); a
line longer than :data:`MAX_REQUEST` or nested deeper than :data:`MAX_DEPTH` is
refused before it is parsed (a long line also drops the client); ``accept`` failing
for lack of descriptors pauses the socket (:mod:`emlogd.daemon.listen`).

No client can hold the daemon's one thread: at most :data:`MAX_PIPELINED` requests are
answered from one read, a client sending more at once is closed with an error line.
No client can lock the operators out either: a request must be complete within
:data:`REQUEST_S` of its first byte (a client dripping bytes gets an error line and
is closed), a client that completes no request for :data:`IDLE_S` is closed, and at
:data:`MAX_CLIENTS` a newcomer is served and a client is closed with an error line:
of the peer user holding the most connections (``SO_PEERCRED``'s uid), of its process
holding the most, the one that has waited longest since it connected or last completed
a request (a process connecting in a loop, or a user's many processes, lose their own
connections, never another user's operator's). Each wake-up accepts a backlog's worth of
connections (:data:`ACCEPTS_PER_ROUND`). A socket file removed under the running
server is made again within :data:`PATH_CHECK_S`. An answer the socket's buffer does
not take whole (a status of hundreds of UUTs) waits in the client's buffer and leaves
as the client reads, within :data:`SEND_S`. A server may be read-only (``commands``: only ``status``), e.g. a
status socket open to every local user next to the operators' control socket. The
client side is :func:`emlogd.client.request`.
"""

from __future__ import annotations

import contextlib
import functools
import json
import selectors
import socket
import struct
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

from drivers.errors import DeviceError
from emlogd.daemon.listen import AcceptPause


class Deferred:
    """An answer the handler gives later (a ``freeze`` waiting for its save to land):
    settled once by :meth:`answer` or :meth:`refuse`. Until then the client waits, its
    further requests unread, while the other clients and the outputs are served."""

    __slots__ = ("_then", "line")

    def __init__(self) -> None:
        self.line: bytes | None = None
        """The answer's line once settled."""
        self._then: Callable[[bytes], None] | None = None

    def answer(self, doc: dict[str, object]) -> None:
        """Settle with ``{"ok": true, **doc}``."""
        self._settle(_line({"ok": True, **doc}))

    def refuse(self, error: str) -> None:
        """Settle with ``{"ok": false, "error": error}``."""
        self._settle(_line({"ok": False, "error": error}))

    def then(self, call: Callable[[bytes], None]) -> None:
        """Call ``call`` with the answer's line once settled (at once if it is)."""
        self._then = call
        if self.line is not None:
            call(self.line)

    def _settle(self, line: bytes) -> None:
        if self.line is not None:
            return
        self.line = line
        if self._then is not None:
            self._then(line)


Handler = Callable[[dict[str, object]], "dict[str, object] | Deferred"]

MAX_REQUEST = 4096
"""Longest accepted request line, bytes."""

MAX_DEPTH = 4
"""Deepest accepted nesting of arrays and objects in a request."""

MAX_CLIENTS = 16
"""Most clients connected to one socket at a time; a newcomer beyond it closes a client
(of the peer user holding the most, of its process holding the most, the one that
completed no request for the longest time)."""

MAX_PIPELINED = 4
"""Most requests answered from one read of a client: a client that sends more at once
gets an error line and is closed. A ``status`` answer takes about a millisecond of the
daemon's one thread; 240 of them pipelined in one 4 KiB read held the loop, and so the
logs' corrected sentences, for a quarter of a second — from the status socket, open to
every local user."""

REQUEST_S = 5.0
"""A request must be complete (its newline received) this long after its first byte,
or the client gets an error line and is closed."""

ACCEPTS_PER_ROUND = 2 * MAX_CLIENTS
"""Most connections accepted at one wake-up: a burst of clients leaves the listen backlog
at once, so an operator's connect waits behind it no longer than a round."""

BACKLOG = 32
"""The listen backlog: connections waiting to be accepted."""

SEND_S = 5.0
"""An answer must be taken whole this long after it was ready, or the client is closed:
an answer larger than the socket's buffer (the status of a few hundred UUTs is
megabytes) waits in the client's own buffer and leaves as the client reads, its other
requests read only once it has; a client that does not read holds that buffer no
longer."""

STATUS_REUSE = 2.0
"""How long the answer to a ``status`` request is sent again, as it was, to the same
request (its command and arguments) rather than built anew: this many times what its
building took (a few milliseconds for a few UUTs: as good as fresh), so answering
costs the daemon's one thread at most a third of its time however many ask; any other
command answered ends it. The status of 1000 UUTs (2 MB) takes about 0.1 s to build:
12 clients asking in a loop held the thread, every output with it, for 1.7 s in the
median between two answers to a 13th."""

IDLE_S = 30.0
"""A client that completes no request for this long is closed (it holds a slot)."""

PATH_CHECK_S = 2.0
"""How often a server checks that its path still names its socket, s: a socket file
removed (by hand, by a clean-up of the run directory) is bound again at once, since
the listening socket behind a removed name takes no connection and every operator
would be locked out until a restart. A path that names something else is logged and
left to whoever made it."""

COMMANDS = ("status", "freeze", "learn", "reset")

FIELDS: dict[str, tuple[type, str]] = {
    "cmd": (str, "a string"),
    "port": (str, "a UUT name"),
    "on": (bool, "true or false"),
}
"""The keys a request may have, with their type."""

KEYS_OF: dict[str, tuple[str, ...]] = {
    "status": ("cmd", "port"),
    "freeze": ("cmd", "port"),
    "learn": ("cmd", "port", "on"),
    "reset": ("cmd", "port"),
}
"""The keys each command takes: another is refused (``{"cmd": "freeze", "on": false}``, an
unfreeze meant, froze)."""


def nesting(line: bytes) -> int:
    """The deepest nesting of ``[`` and ``{`` in a JSON text (brackets in strings ignored)."""
    depth = deepest = 0
    in_str = escaped = False
    for c in line:
        if in_str:
            if escaped:
                escaped = False
            elif c == 0x5C:  # backslash
                escaped = True
            elif c == 0x22:  # quote
                in_str = False
        elif c == 0x22:
            in_str = True
        elif c in (0x5B, 0x7B):
            depth += 1
            deepest = max(deepest, depth)
        elif c in (0x5D, 0x7D):
            depth -= 1
    return deepest


class DuplicateKeyError(ValueError):
    """A JSON object names a key twice."""


def _unique_keys(pairs: list[tuple[str, object]]) -> dict[str, object]:
    """``object_pairs_hook`` refusing duplicate keys (``json`` keeps the last one)."""
    doc: dict[str, object] = {}
    for k, v in pairs:
        if k in doc:
            raise DuplicateKeyError(f"duplicate key {k!r}")
        doc[k] = v
    return doc


def parse_request(line: bytes) -> object:
    """The JSON value of a request line, objects with unique keys.

    Raises:
        DuplicateKeyError: an object names a key twice.
        ValueError: not JSON (or not UTF-8).
    """
    return json.loads(line, object_pairs_hook=_unique_keys)


def check_request(req: object, commands: Sequence[str] = COMMANDS) -> str:
    """``""`` when ``req`` is a well-formed request, else why not (one line)."""
    if not isinstance(req, dict):
        return "not a JSON object"
    for key, value in req.items():
        if key not in FIELDS:
            return f"unknown key {key!r}; valid: {', '.join(FIELDS)}"
        kind, what = FIELDS[key]
        if not isinstance(value, kind):
            return f"{key!r} must be {what}"
    cmd = req.get("cmd")
    if cmd not in commands:
        return f"unknown cmd; valid here: {', '.join(commands)}"
    keys = KEYS_OF.get(str(cmd), tuple(FIELDS))
    extra = [k for k in req if k not in keys]
    if extra:
        return f"{cmd} takes no {extra[0]!r}; its keys: {', '.join(keys)}"
    return ""


Peer = tuple[int, int]
"""The user and process ids at the other end of a unix socket (as it connected)."""


def _peer(conn: socket.socket) -> Peer:
    """The peer's user and process ids (``(-1, 0)`` when they cannot be read)."""
    try:
        cred = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    except OSError:
        return (-1, 0)
    pid, uid, _ = struct.unpack("3i", cred)
    return (int(uid), int(pid))


class _Client:
    __slots__ = ("buf", "out", "peer", "seen", "sending", "sock", "started", "waiting")

    def __init__(self, sock: socket.socket, now: float, peer: Peer = (-1, 0)) -> None:
        self.sock = sock
        self.peer = peer
        """The user and process at the other end."""
        self.buf = bytearray()
        self.seen = now
        """When it connected or last completed a request."""
        self.started: float | None = None
        """When the first byte of its unfinished request came (None: none unfinished)."""
        self.out = bytearray()
        """Answers not yet sent (the socket's buffer was full)."""
        self.sending: float | None = None
        """When :attr:`out` began to wait (None: nothing waits)."""
        self.waiting = False
        """An answer is deferred (:class:`Deferred`): the socket is out of the selector
        and the client's further requests wait in :attr:`buf`."""


class ControlServer:
    """Serve JSON-line requests on ``path``; call :meth:`handle` via the selector.

    Args:
        path: socket path (its directory is created; a stale socket is replaced).
        handler: turns a request dict into a response dict (may raise ValueError), or a
            :class:`Deferred` settled later (the client waits, the others are served).
        selector: the daemon's selector; the server registers its sockets there
            with a callable as data.
        mode: permission bits of the socket file.
        commands: the commands this socket takes (``("status",)``: read-only).
        on_event: called as ``on_event(kind, detail)`` for what is worth a log line.
        monotonic: the clock of idle timeouts and pauses.
        wait: a path where the socket cannot be made (a regular file there) is logged
            (``control_socket_path``) and the socket made by the path check once it can
            be; without it, that is a ``DeviceError``. Another process listening there is
            a ``DeviceError`` either way.

    Call :meth:`housekeep` now and then (idle clients, the end of a pause).

    Raises:
        DeviceError: the socket cannot be created, or another process listens on it.
    """

    def __init__(
        self,
        path: str | Path,
        handler: Handler,
        selector: selectors.BaseSelector,
        mode: int = 0o660,
        *,
        commands: Sequence[str] = COMMANDS,
        on_event: Callable[[str, str], None] | None = None,
        monotonic: Callable[[], float] = time.monotonic,
        wait: bool = False,
    ) -> None:
        self.path = Path(path)
        self.handler = handler
        self.selector = selector
        self.commands = tuple(commands)
        self.on_event = on_event
        self.monotonic = monotonic
        self.clients: dict[socket.socket, _Client] = {}
        self.evicted = 0
        """Clients closed to make room for a newcomer."""
        self.timed_out = 0
        """Clients closed for a request not complete within :data:`REQUEST_S`."""
        self.flooded = 0
        """Clients closed for more than :data:`MAX_PIPELINED` requests in one read."""
        self.unread = 0
        """Clients closed for not taking an answer within :data:`SEND_S`."""
        self.pause = AcceptPause(lambda d: self._note("control_accept_error", d), monotonic)
        self.mode = mode
        self.rebound = 0
        """Times the socket file, removed, was made again."""
        self._reuse: dict[str, tuple[float, bytes]] = {}
        """The status answers to send again (:data:`STATUS_REUSE`): (until when, the line)."""
        self._next_check = monotonic() + PATH_CHECK_S
        self._path_problem = ""
        """What the last path check found wrong and logged (logged again only if new)."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.path.is_socket():
                if _listening(self.path):
                    raise DeviceError(f"control socket {self.path} is in use by another process")
                self.path.unlink()  # stale: left by a process that died
            self.sock, self._ident = self._bind()
        except OSError as exc:
            if not wait:
                raise DeviceError(f"control socket {self.path}: {exc.strerror or exc}") from None
            # not listening: bound by the path check once the path is free
            self.sock, self._ident = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM), (-1, -1)
            why = f"cannot be made: {exc.strerror or exc}; tried again every {PATH_CHECK_S:g} s"
            self._path_trouble(why)
            return
        selector.register(self.sock, selectors.EVENT_READ, self._accept)

    def _bind(self) -> tuple[socket.socket, tuple[int, int]]:
        """A listening socket bound at :attr:`path`, and the file's (device, inode).

        Raises:
            OSError: it cannot be made.
        """
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.bind(str(self.path))
            self.path.chmod(self.mode)
            st = self.path.lstat()
            sock.listen(BACKLOG)
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        return sock, (st.st_dev, st.st_ino)

    def _check_path(self) -> None:
        """Bind again if the socket file was removed; log once if it names another file."""
        try:
            st = self.path.lstat()
        except FileNotFoundError:
            st = None
        except OSError as exc:
            self._path_trouble(f"cannot be checked: {exc.strerror or exc}")
            return
        if st is not None:
            if (st.st_dev, st.st_ino) == self._ident:
                self._path_problem = ""
            else:
                self._path_trouble("names another file now: left to it, not listened on")
            return
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            sock, ident = self._bind()
        except OSError as exc:
            self._path_trouble(f"removed, and cannot be made again: {exc.strerror or exc}")
            return
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(self.sock)
        self.sock.close()
        self.sock, self._ident = sock, ident
        if not self.pause.paused:
            self.selector.register(self.sock, selectors.EVENT_READ, self._accept)
        self.rebound += 1
        self._path_problem = ""
        self._note("control_socket_restored", "the socket file was removed: made again")

    def _path_trouble(self, why: str) -> None:
        if why != self._path_problem:
            self._path_problem = why
            self._note("control_socket_path", why)

    def _note(self, kind: str, detail: str) -> None:
        if self.on_event is not None:
            self.on_event(kind, f"{self.path}: {detail}")

    def _accept(self) -> None:
        """Accept what waits in the backlog, at most :data:`ACCEPTS_PER_ROUND`."""
        for _ in range(ACCEPTS_PER_ROUND):
            try:
                conn, _ = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if self.pause.failed(exc):
                    with contextlib.suppress(KeyError, ValueError):
                        self.selector.unregister(self.sock)
                return
            self.pause.accepted()
            self._admit(conn)

    def _admit(self, conn: socket.socket) -> None:
        """Serve a new client (closing the one waiting longest at the limit)."""
        while self.clients and len(self.clients) >= MAX_CLIENTS:
            oldest = self._eviction_candidate()
            self.evicted += 1
            self._reply(oldest, {"ok": False, "error": "too many clients: closed for a newcomer"})
            self._drop(oldest)
        conn.setblocking(False)
        self.clients[conn] = _Client(conn, self.monotonic(), _peer(conn))
        self.selector.register(conn, selectors.EVENT_READ, lambda c=conn: self._ready(c))

    def _eviction_candidate(self) -> socket.socket:
        """The client to close for a newcomer: of the peer user holding the most
        connections, of its process holding the most, the one that waited longest (a
        process connecting in a loop loses its own, and so do a user's many processes,
        never another user's operator)."""
        users = Counter(c.peer[0] for c in self.clients.values())
        top = max(users.values())
        theirs = [c for c in self.clients.values() if users[c.peer[0]] == top]
        held = Counter(c.peer for c in theirs)
        most = max(held.values())
        mine = [c for c in theirs if held[c.peer] == most]
        return min(mine, key=lambda c: c.seen).sock

    def housekeep(self) -> None:
        """Close the clients past a deadline; listen again once an accept pause is over;
        every :data:`PATH_CHECK_S`, check the socket's path (:meth:`_check_path`)."""
        now = self.monotonic()
        if now >= self._next_check:
            self._next_check = now + PATH_CHECK_S
            self._check_path()
        for conn, client in list(self.clients.items()):
            if client.started is not None and now - client.started > REQUEST_S:
                self.timed_out += 1
                self._reply(
                    conn, {"ok": False, "error": f"request not complete within {REQUEST_S:g} s"}
                )
                self._drop(conn)
            elif client.sending is not None and now - client.sending > SEND_S:
                self.unread += 1
                self._drop(conn)
            elif client.sending is None and not client.waiting and now - client.seen > IDLE_S:
                self._drop(conn)
        if self.pause.resume_due():
            self.selector.register(self.sock, selectors.EVENT_READ, self._accept)

    def _ready(self, conn: socket.socket) -> None:
        """The selector's call: send what waits, then (nothing left waiting) read."""
        client = self.clients.get(conn)
        if client is None or client.waiting:  # waiting: an event of the same select
            return
        if client.out:
            self._flush(conn, client)
        if conn in self.clients and not client.out:
            self._read(conn)

    def _read(self, conn: socket.socket) -> None:
        """Read what the client sent and answer its whole requests (those read before
        while an answer waited too)."""
        data: bytes | None
        try:
            data = conn.recv(4096)
        except (BlockingIOError, InterruptedError):
            data = None
        except OSError:
            data = b""
        client = self.clients[conn]
        if data == b"":
            if not client.buf.strip():
                self._drop(conn)
                return
            # the end of file ends the last request (``printf '{"cmd":"status"}' | socat
            # - UNIX-CONNECT:…``): answered, then closed once it is sent and read again
            data = b"\n"
        client.buf += data or b""
        self._answer_buffered(conn, client)

    def _answer_buffered(self, conn: socket.socket, client: _Client) -> None:
        """Answer the whole requests in the client's buffer (up to a deferred answer)."""
        now = self.monotonic()
        buf = client.buf
        answered = 0
        while b"\n" in buf and conn in self.clients:
            if answered == MAX_PIPELINED:
                self.flooded += 1
                self._reply(
                    conn, {"ok": False, "error": f"more than {MAX_PIPELINED} requests at once"}
                )
                self._drop(conn)
                return
            answered += 1
            line, _, rest = bytes(buf).partition(b"\n")
            buf[:] = rest
            client.seen = now
            client.started = None
            answer = self._answer(line, now)
            if isinstance(answer, Deferred) and answer.line is None:
                self._defer(conn, client, answer)
                return
            self._send(conn, answer if isinstance(answer, bytes) else answer.line or b"")
        if conn in self.clients and client.out:
            return  # the rest is read once the answers are taken (:meth:`_ready`)
        if buf and client.started is None:
            client.started = now
        if len(buf) > MAX_REQUEST and conn in self.clients:
            self._reply(conn, {"ok": False, "error": "request too long"})
            self._drop(conn)

    def _defer(self, conn: socket.socket, client: _Client, answer: Deferred) -> None:
        """Hold the client until ``answer`` is settled: out of the selector (its requests
        unread, in order), then answered and served again (:meth:`_settled`)."""
        client.waiting = True
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(conn)
        answer.then(functools.partial(self._settled, conn))

    def _settled(self, conn: socket.socket, data: bytes) -> None:
        """A deferred answer is ready: send it and go on with the client's requests."""
        client = self.clients.get(conn)
        if client is None or not client.waiting:
            return  # closed meanwhile
        client.waiting = False
        client.seen = self.monotonic()
        client.sending = None  # registered for reading: the flush watches for room again
        self.selector.register(conn, selectors.EVENT_READ, lambda c=conn: self._ready(c))
        self._send(conn, data)
        if conn in self.clients and not client.out:
            self._answer_buffered(conn, client)

    def _answer(self, line: bytes, now: float) -> bytes | Deferred:
        """The answer's line: a ``status`` answer to the same request is sent again as it
        was for :data:`STATUS_REUSE` times what its building took."""
        if len(line) > MAX_REQUEST:
            return _line({"ok": False, "error": "request too long"})
        if nesting(line) > MAX_DEPTH:
            return _line({"ok": False, "error": f"nested deeper than {MAX_DEPTH}"})
        try:
            req = parse_request(line)
        except DuplicateKeyError as exc:
            return _line({"ok": False, "error": str(exc)})
        except (ValueError, UnicodeDecodeError, RecursionError):
            return _line({"ok": False, "error": "not a JSON object"})
        why = check_request(req, self.commands)
        if why or not isinstance(req, dict):
            return _line({"ok": False, "error": why or "not a JSON object"})
        key = json.dumps(req, sort_keys=True, default=str)
        if req.get("cmd") != "status":
            self._reuse.clear()  # a command may change what the status says
        elif (kept := self._reuse.get(key)) is not None and now < kept[0]:
            return kept[1]
        try:
            doc = self.handler(req)
        except (ValueError, KeyError) as exc:
            return _line({"ok": False, "error": str(exc)})
        if isinstance(doc, Deferred):
            return doc
        data = _line({"ok": True, **doc})
        if req.get("cmd") == "status":
            done = self.monotonic()
            self._reuse = {k: v for k, v in self._reuse.items() if done < v[0]}
            self._reuse[key] = (done + STATUS_REUSE * (done - now), data)
        return data

    def _reply(self, conn: socket.socket, doc: dict[str, object]) -> None:
        """Send ``doc`` as a line (:meth:`_send`)."""
        self._send(conn, _line(doc))

    def _send(self, conn: socket.socket, data: bytes) -> None:
        """Send ``data``, after the answers still waiting; what the socket does not take
        waits in the client's buffer (:meth:`_flush`)."""
        client = self.clients.get(conn)
        if client is None:
            with contextlib.suppress(OSError):
                conn.send(data)
            return
        client.out += data
        self._flush(conn, client)

    def _flush(self, conn: socket.socket, client: _Client) -> None:
        """Send what the client's buffer holds, as much as the socket takes; watch the
        socket for room while some is left, for requests once none is."""
        try:
            while client.out:
                sent = conn.send(client.out)
                del client.out[:sent]
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._drop(conn)
            return
        if client.out and client.sending is None:
            client.sending = self.monotonic()
            self.selector.modify(conn, selectors.EVENT_WRITE, lambda c=conn: self._ready(c))
        elif not client.out and client.sending is not None:
            client.sending = None
            client.seen = self.monotonic()
            self.selector.modify(conn, selectors.EVENT_READ, lambda c=conn: self._ready(c))

    def _drop(self, conn: socket.socket) -> None:
        if conn in self.clients:
            del self.clients[conn]
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(conn)
            conn.close()

    def retune(self, mode: int, commands: Sequence[str]) -> None:
        """Serve ``commands`` with the socket file's mode ``mode`` from now on (a reload
        that made this path the other kind's socket). The listener stays; when the
        commands change, the connected clients are closed: one that connected to the
        read-only socket gets no control through a reload."""
        if tuple(commands) != self.commands:
            for conn in list(self.clients):
                self._drop(conn)
            self._reuse.clear()
        self.commands = tuple(commands)
        self.mode = mode
        try:
            st = self.path.lstat()
            if (st.st_dev, st.st_ino) == self._ident:  # another's file at the path: left
                self.path.chmod(mode)
        except OSError as exc:
            self._path_trouble(f"cannot be given mode {mode:o}: {exc.strerror or exc}")

    def close(self) -> None:
        """Close every connection and remove the socket file (if it is still this one)."""
        for conn in list(self.clients):
            self._drop(conn)
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(self.sock)
        self.sock.close()
        with contextlib.suppress(OSError):
            st = self.path.lstat()
            if (st.st_dev, st.st_ino) == self._ident:  # another's file at the path stays
                self.path.unlink()


def _line(doc: dict[str, object]) -> bytes:
    return json.dumps(doc, default=str).encode("utf-8") + b"\n"


def _listening(path: Path) -> bool:
    """Whether a process accepts connections on the unix socket ``path``."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(1.0)
        try:
            s.connect(str(path))
        except OSError:
            return False
    return True
