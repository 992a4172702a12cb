"""The daemon's control sockets: the control socket and the read-only status socket the
config names, kept in step with it at the start and at every reload.

An open socket whose path did not change is kept (same listener, same clients). A reload
that gives a path the other kind's socket holds (the control and status sockets' paths
swapped) turns that socket into the new kind in place — its commands and mode set, its
clients closed, since what they may ask changes — instead of binding a second listener at
a path the daemon itself listens on, which was taken for another instance's and refused.
A socket of a kind whose new one cannot be created is kept at its old path: a reload
naming an unusable path does not leave the daemon with no control socket at all.
"""

from __future__ import annotations

import selectors
from collections.abc import Callable, Iterator

from drivers.errors import DeviceError
from emlogd.daemon.control import COMMANDS, ControlServer, Handler

KINDS: dict[str, tuple[int, tuple[str, ...]]] = {
    "control": (0o660, COMMANDS),
    "status": (0o666, ("status",)),
}
"""Each kind of socket's file mode and the commands it takes."""


class Controls:
    """The open control sockets, keyed by (kind, path).

    Args:
        selector: where each server registers its sockets.
        handler: turns a request into an answer (:class:`ControlServer`'s).
        on_event: called as ``on_event(kind, detail)`` for what is worth a log line.
        monotonic: the servers' clock.
    """

    def __init__(
        self,
        selector: selectors.BaseSelector,
        handler: Handler,
        on_event: Callable[[str, str], None],
        monotonic: Callable[[], float],
    ) -> None:
        self.sel = selector
        self.handler = handler
        self.on_event = on_event
        self.monotonic = monotonic
        self.servers: dict[tuple[str, str], ControlServer] = {}

    def __iter__(self) -> Iterator[ControlServer]:
        return iter(list(self.servers.values()))

    def sync(self, control: str, status: str | None, *, started: bool) -> None:
        """Open the sockets named (``status`` None: no status socket), keep the open ones
        whose path did not change, turn one whose path the other kind now names into that
        kind, close the rest. ``started``: a reload (at a start, a file in the way costs
        the socket, tried again; later the old one is kept).

        Raises:
            DeviceError: a socket cannot be created (the others are still synced).
        """
        want = {("control", control)}
        if status:
            want.add(("status", status))
        failed: DeviceError | None = None
        failed_kinds: set[str] = set()
        for kind, path in sorted(want - self.servers.keys()):
            mode, commands = KINDS[kind]
            held = [k for k in self.servers if k[1] == path and k not in want]
            if held:  # the other kind's socket at this path: turned into this kind
                server = self.servers.pop(held[0])
                server.retune(mode, commands)
                self.servers[(kind, path)] = server
                continue
            try:
                self.servers[(kind, path)] = ControlServer(
                    path,
                    self.handler,
                    self.sel,
                    mode=mode,
                    commands=commands,
                    on_event=self.on_event,
                    monotonic=self.monotonic,
                    wait=not started,
                )
            except DeviceError as exc:
                failed = exc
                failed_kinds.add(kind)
        for key in [k for k in self.servers if k not in want and k[0] not in failed_kinds]:
            self.servers.pop(key).close()
        if failed is not None:
            raise failed

    def housekeep(self) -> None:
        """Each server's upkeep (deadlines, path checks)."""
        for server in self:
            server.housekeep()

    def close(self) -> None:
        """Close every socket."""
        for server in self:
            server.close()
        self.servers.clear()
