"""The client side of the daemon's control socket: one JSON request, one JSON answer.

``emlogd status|freeze|learn|reset``, the demo and :mod:`emlogd.launch` talk to a
running daemon through :func:`request`; the server side is
:mod:`emlogd.daemon.control`. The client needs nothing of the daemon but its socket's
path, so the offline tools (the demo) reach it without importing the daemon.
"""

from __future__ import annotations

import json
import socket
import struct
import time
from pathlib import Path

from drivers.errors import DeviceError

MAX_ANSWER = 4 << 20
"""Longest answer line taken, bytes (a status of many UUTs is tens of KB): a peer at the
socket's path streaming bytes without a newline is refused past it, within ``timeout_s``
as a whole, rather than held in memory for as long as it sends."""


def request(path: str | Path, req: dict[str, object], timeout_s: float = 5.0) -> dict[str, object]:
    """Send one request and return the response.

    Raises:
        DeviceError: the daemon is not reachable or answered garbage.
    """
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            # a blocking connect bounded by SO_SNDTIMEO waits in the kernel's queue for
            # room in a full listen backlog (a burst of clients), as the others do; with
            # settimeout() the socket is non-blocking and the connect fails at once (EAGAIN)
            whole, frac = divmod(timeout_s, 1.0)
            tv = struct.pack("ll", int(whole), int(frac * 1e6))
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
            s.connect(str(path))
            s.settimeout(timeout_s)
            s.sendall(json.dumps(req).encode("utf-8") + b"\n")
            buf = bytearray()
            deadline = time.monotonic() + timeout_s
            while True:
                chunk = s.recv(65536)
                buf += chunk
                if not chunk or b"\n" in chunk:
                    break
                if len(buf) > MAX_ANSWER or time.monotonic() > deadline:
                    raise DeviceError(
                        f"{path}: no whole answer within {timeout_s:g} s and "
                        f"{MAX_ANSWER} bytes: {len(buf)} bytes without a newline"
                    )
                s.settimeout(max(deadline - time.monotonic(), 0.001))
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
