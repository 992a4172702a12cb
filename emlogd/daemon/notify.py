"""systemd notification protocol (sd_notify) over a unix datagram socket.

``NOTIFY_SOCKET`` names the socket (a path, or ``@name`` for the abstract
namespace). Messages are newline-separated ``KEY=value`` assignments: ``READY=1``
once the config is valid and the outputs are open, ``STATUS=...`` (one line),
``WATCHDOG=1`` at half the ``WATCHDOG_USEC`` interval, ``STOPPING=1``. Without
``NOTIFY_SOCKET`` every call is a no-op; a send that fails is counted and ignored
(systemd may be gone during shutdown). A send never waits: a socket whose reader
does not read (a stuck or foreign receiver; a datagram socket's queue holds
``net.unix.max_dgram_qlen`` messages, 10 by default) fails the send with ``EAGAIN``,
where a blocking send held the daemon's one thread, and so every output, for good.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Mapping


class Notifier:
    """Send sd_notify messages.

    Args:
        address: the ``NOTIFY_SOCKET`` value, or None to disable.
        watchdog_usec: ``WATCHDOG_USEC`` (None: no watchdog).
    """

    def __init__(self, address: str | None, watchdog_usec: int | None = None) -> None:
        self.address = address or None
        self.watchdog_usec = watchdog_usec if watchdog_usec and watchdog_usec > 0 else None
        self.sent = 0
        self.failed = 0

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> Notifier:
        """From ``NOTIFY_SOCKET``, ``WATCHDOG_USEC`` (ASCII digits, else no watchdog) and
        ``WATCHDOG_PID`` (the pid must be ours)."""
        e = os.environ if env is None else env
        usec: int | None = None
        raw = e.get("WATCHDOG_USEC", "")
        pid = e.get("WATCHDOG_PID", "")
        if raw.isascii() and raw.isdigit() and (not pid or pid == str(os.getpid())):
            usec = int(raw)  # ASCII: "²" is a digit to isdigit() and no number to int()
        return cls(e.get("NOTIFY_SOCKET"), usec)

    @property
    def enabled(self) -> bool:
        """A notify socket is configured."""
        return self.address is not None

    @property
    def watchdog_interval_s(self) -> float | None:
        """How often to send WATCHDOG=1 (half the configured timeout), or None."""
        return None if self.watchdog_usec is None else self.watchdog_usec / 2e6

    def notify(self, message: str) -> bool:
        """Send one message; True if it was delivered."""
        if self.address is None:
            return False
        addr = self.address
        if addr.startswith("@"):
            addr = "\0" + addr[1:]
        try:
            with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
                s.sendto(message.encode("utf-8", "replace"), socket.MSG_DONTWAIT, addr)
        except OSError:
            self.failed += 1
            return False
        self.sent += 1
        return True

    def ready(self) -> bool:
        """READY=1."""
        return self.notify("READY=1")

    def status(self, text: str) -> bool:
        """STATUS=<one line>."""
        return self.notify("STATUS=" + " ".join(text.splitlines())[:400])

    def watchdog(self) -> bool:
        """WATCHDOG=1."""
        return self.notify("WATCHDOG=1")

    def stopping(self) -> bool:
        """STOPPING=1."""
        return self.notify("STOPPING=1")
