"""What two parts of a valid config may not share: a TCP output's port, or a path among
the control socket, the status socket, the state file, the output ptys and the input
ports' devices. Each clash was found only when the daemon opened the second (an output
unbound, the start ended, or the daemon reading its own output as a sensor), and is
refused when the config is loaded (or reloaded: the running one kept).
"""

from __future__ import annotations

import ipaddress
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

if TYPE_CHECKING:
    from emlogd.config import Config

WILDCARD_HOSTS = frozenset({"", "0.0.0.0", "::"})
"""The hosts a TCP output listens on every interface with: such a listener takes its
port from every address, so another on that port clashes whatever its host."""


def same_listener(a: str, b: str) -> bool:
    """Whether two TCP outputs' ``HOST:PORT`` cannot both be bound: one port, and one
    host or either a wildcard (:data:`WILDCARD_HOSTS`)."""
    (ha, _, pa), (hb, _, pb) = a.rpartition(":"), b.rpartition(":")
    ha, hb = ha.strip("[]"), hb.strip("[]")
    return pa == pb and (ha == hb or ha in WILDCARD_HOSTS or hb in WILDCARD_HOSTS)


def tcp_clash(listeners: Sequence[str]) -> str:
    """Why two of the TCP outputs ``listeners`` cannot both listen, or ``""``."""
    for i, a in enumerate(listeners):
        for b in listeners[i + 1 :]:
            if same_listener(a, b):
                return (
                    f"each TCP output must listen on its own port: {a} and {b} clash "
                    "(a log's tcp repeats another)"
                )
    return ""


def path_clash(cfg: Config) -> tuple[str, str, str]:
    """Why two of the control socket, the status socket, the state file and the output
    ptys share a path, or an input port's device is one of them, the key of the second
    and its top-level section (``("", "", "")``: none do). A status
    socket at the control socket's path ended the start with "in use by another
    process"; a pty at the state file's, "exists and is not a symlink"; a port at an
    output pty's link read the daemon's own corrected sentences as a sensor's (a second
    log's speed made of the first's output). Two paths through a symlinked directory to
    one place clash too (:func:`_real_place`), and so does a ``socket://`` input on a TCP
    output's port of this host (:func:`_own_listener`). Ports may share a device with
    each other (not checked here)."""
    named: list[tuple[str, str, str | None]] = [
        ("control_socket", "control_socket", cfg.control_socket),
        ("status_socket", "status_socket", cfg.status_socket),
        ("state_file", "state_file", cfg.state_path),
        ("outputs.pty", "outputs", cfg.outputs.pty),
    ]
    named += [
        (f"calibration[{i}].pty", "calibration", c.outputs.pty)
        for i, c in enumerate(cfg.calibration)
    ]
    seen: dict[str, str] = {}
    for what, section, path in named:
        if path:
            other = seen.setdefault(_real_place(path), what)
            if other != what:
                return f"the same path as {other} ({path}): each needs its own", what, section
    listeners = [("outputs.tcp", cfg.outputs.tcp)]
    listeners += [(f"calibration[{i}].tcp", c.outputs.tcp) for i, c in enumerate(cfg.calibration)]
    for i, port in enumerate(cfg.ports):
        hops = _hops(port.url) if "://" not in port.url else []
        read = next((seen[hop] for hop in hops if hop in seen), None)
        read = read or next((k for k, t in listeners if t and _own_listener(port.url, t)), None)
        if read is not None:
            return (
                f"the same place as {read} ({port.url}): a port cannot read the daemon's "
                "own output, state or sockets",
                f"ports[{i}].url",
                "ports",
            )
    return "", "", ""


def _real_place(path: str) -> str:
    """Where ``path`` puts its file: its directory with every symlink resolved, and its
    own name (a pty's link is itself a symlink, to the pty of the day). Two UUTs' ptys
    at ``run/x`` and ``run2/x``, ``run2`` a symlink to ``run``, passed the check: the
    second pty's link took the place and the first's output reached no reader."""
    head, name = os.path.split(os.path.normpath(path))
    return str(Path(os.path.realpath(head or ".")) / name)


MAX_HOPS = 40
"""The most symlinks followed from a port's path (the kernel's own limit, ``ELOOP``)."""


def _hops(path: str) -> list[str]:
    """The places (:func:`_real_place`) of ``path`` and of each symlink it leads through,
    in order: a port given as a link to an output pty's link (``links/emlog2`` naming
    ``out/emlog0``) reaches it through one more name."""
    places = [_real_place(path)]
    for _ in range(MAX_HOPS):
        try:
            link = Path(places[-1])
            target = link.readlink()
        except (OSError, ValueError):
            break
        places.append(_real_place(str(link.parent / target)))
    return places


def _own_listener(url: str, listener: str) -> bool:
    """Whether the input ``url`` (``socket://HOST:PORT``) connects to the TCP output
    ``listener`` (``HOST:PORT``): its port, and a loopback host or the listener's own,
    an IPv4 address written IPv6-mapped (``[::ffff:127.0.0.1]``) as itself, and the
    unspecified ``0.0.0.0`` or ``[::]``, which a connect takes for this host (both
    spellings passed the check, and the daemon read its own sentences as the log's). A
    host of another address may be this host's or another's (a multiplexer on the usual
    10110): not refused."""
    if not url.lower().startswith("socket://"):
        return False
    try:
        parts = urlsplit(url)
        host, port = ipaddress.ip_address(parts.hostname or ""), parts.port
    except ValueError:
        return False
    lhost, _, lport = listener.rpartition(":")
    if port is None or str(port) != lport:
        return False
    if isinstance(host, ipaddress.IPv6Address) and host.ipv4_mapped is not None:
        host = host.ipv4_mapped
    return host.is_loopback or host.is_unspecified or str(host) == lhost.strip("[]")
