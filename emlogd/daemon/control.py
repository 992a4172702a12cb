"""The daemon's control socket: JSON lines over a unix stream socket.

Requests are one JSON object per line, ``{"cmd": "status"}``, ``{"cmd": "freeze"}``,
``{"cmd": "learn", "on": true}``, ``{"cmd": "reset", "port": "emlog1"}``; each gets
one JSON line back, ``{"ok": true, ...}`` or ``{"ok": false, "error": "..."}``. The
socket is created with mode 0660 (the daemon's group may control it). The server
side is non-blocking and bounded (a client sending an endless line is dropped); the
client side (:func:`request`) is what ``emlogd status|freeze|learn|reset`` use.
"""

from __future__ import annotations

import contextlib
import json
import selectors
import socket
from collections.abc import Callable
from pathlib import Path

from drivers.errors import DeviceError

Handler = Callable[[dict[str, object]], dict[str, object]]

MAX_REQUEST = 4096
"""Longest accepted request line, bytes."""

COMMANDS = ("status", "freeze", "learn", "reset")


class ControlServer:
    """Serve JSON-line requests on ``path``; call :meth:`handle` via the selector.

    Args:
        path: socket path (its directory is created; a stale socket is replaced).
        handler: turns a request dict into a response dict (may raise ValueError).
        selector: the daemon's selector; the server registers its sockets there
            with a callable as data.
        mode: permission bits of the socket file.

    Raises:
        DeviceError: the socket cannot be created.
    """

    def __init__(
        self,
        path: str | Path,
        handler: Handler,
        selector: selectors.BaseSelector,
        mode: int = 0o660,
    ) -> None:
        self.path = Path(path)
        self.handler = handler
        self.selector = selector
        self.clients: dict[socket.socket, bytearray] = {}
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.path.is_socket():
                if _listening(self.path):
                    raise DeviceError(f"control socket {self.path} is in use by another process")
                self.path.unlink()  # stale: left by a process that died
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            self.sock.bind(str(self.path))
            self.path.chmod(mode)
            self.sock.listen(4)
            self.sock.setblocking(False)
        except OSError as exc:
            raise DeviceError(f"control socket {self.path}: {exc.strerror or exc}") from None
        selector.register(self.sock, selectors.EVENT_READ, self._accept)

    def _accept(self) -> None:
        try:
            conn, _ = self.sock.accept()
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        conn.setblocking(False)
        self.clients[conn] = bytearray()
        self.selector.register(conn, selectors.EVENT_READ, lambda c=conn: self._read(c))

    def _read(self, conn: socket.socket) -> None:
        try:
            data = conn.recv(4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop(conn)
            return
        buf = self.clients[conn]
        buf += data
        while b"\n" in buf:
            line, _, rest = bytes(buf).partition(b"\n")
            buf[:] = rest
            self._reply(conn, self._answer(line))
        if len(buf) > MAX_REQUEST:
            self._reply(conn, {"ok": False, "error": "request too long"})
            self._drop(conn)

    def _answer(self, line: bytes) -> dict[str, object]:
        try:
            req = json.loads(line)
        except (ValueError, UnicodeDecodeError):
            return {"ok": False, "error": "not a JSON object"}
        if not isinstance(req, dict):
            return {"ok": False, "error": "not a JSON object"}
        if req.get("cmd") not in COMMANDS:
            return {"ok": False, "error": f"unknown cmd; valid: {', '.join(COMMANDS)}"}
        try:
            return {"ok": True, **self.handler(req)}
        except (ValueError, KeyError) as exc:
            return {"ok": False, "error": str(exc)}

    def _reply(self, conn: socket.socket, doc: dict[str, object]) -> None:
        try:
            conn.send(json.dumps(doc, default=str).encode("utf-8") + b"\n")
        except OSError:
            self._drop(conn)

    def _drop(self, conn: socket.socket) -> None:
        if conn in self.clients:
            del self.clients[conn]
            with contextlib.suppress(KeyError, ValueError):
                self.selector.unregister(conn)
            conn.close()

    def close(self) -> None:
        """Close every connection and remove the socket file."""
        for conn in list(self.clients):
            self._drop(conn)
        with contextlib.suppress(KeyError, ValueError):
            self.selector.unregister(self.sock)
        self.sock.close()
        with contextlib.suppress(OSError):
            self.path.unlink()


def _listening(path: Path) -> bool:
    """Whether a process accepts connections on the unix socket ``path``."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(1.0)
        try:
            s.connect(str(path))
        except OSError:
            return False
    return True


def request(path: str | Path, req: dict[str, object], timeout_s: float = 5.0) -> dict[str, object]:
    """Send one request and return the response.

    Raises:
        DeviceError: the daemon is not reachable or answered garbage.
    """
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(timeout_s)
            s.connect(str(path))
            s.sendall(json.dumps(req).encode("utf-8") + b"\n")
            buf = bytearray()
            while b"\n" not in buf:
                chunk = s.recv(65536)
                if not chunk:
                    break
                buf += chunk
    except OSError as exc:
        raise DeviceError(
            f"cannot reach the daemon at {path}: {exc.strerror or exc} (is emlogd running?)"
        ) from None
    try:
        doc = json.loads(bytes(buf).partition(b"\n")[0])
    except ValueError:
        raise DeviceError(f"{path}: the daemon sent a malformed answer") from None
    if not isinstance(doc, dict):
        raise DeviceError(f"{path}: the daemon sent a malformed answer")
    return doc
