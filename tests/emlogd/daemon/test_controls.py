"""The daemon's control sockets kept in step with the config (emlogd/daemon/controls.py)."""

from __future__ import annotations

import selectors
import socket
import stat
from pathlib import Path

from emlogd.daemon.controls import Controls


def _answer(req: dict[str, object]) -> dict[str, object]:
    """A handler answering every request with its command."""
    return {"cmd": req["cmd"]}


def test_swapped_paths_turn_each_socket_into_the_other_kind_in_place(tmp_path: Path) -> None:
    """``sync(a, b)`` then ``sync(b, a)``: the same two listeners, each now the other kind
    (commands and mode), no socket made or closed; a client connected to the read-only
    socket is closed when it becomes the control socket (it gets no control through a
    reload); a third sync to a new status path closes the old one."""
    a, b = str(tmp_path / "a.sock"), str(tmp_path / "b.sock")
    sel = selectors.DefaultSelector()
    controls = Controls(sel, _answer, lambda kind, detail: None, lambda: 0.0)
    try:
        controls.sync(a, b, started=False)
        first = dict(controls.servers)
        client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        client.connect(b)
        for key, _ in sel.select(0.5):
            key.data()
        assert len(first[("status", b)].clients) == 1
        controls.sync(b, a, started=True)
        assert controls.servers[("control", b)] is first[("status", b)]
        assert controls.servers[("status", a)] is first[("control", a)]
        assert controls.servers[("control", b)].commands != ("status",)
        assert controls.servers[("status", a)].commands == ("status",)
        assert stat.S_IMODE(Path(a).stat().st_mode) == 0o666
        assert stat.S_IMODE(Path(b).stat().st_mode) == 0o660
        client.settimeout(1.0)
        assert client.recv(10) == b""  # closed by the daemon
        client.close()
        controls.sync(b, str(tmp_path / "c.sock"), started=True)
        assert not Path(a).exists() and Path(b).exists() and (tmp_path / "c.sock").exists()
    finally:
        controls.close()
        sel.close()
