"""sd_notify over a real unix datagram socket (path and abstract namespace)."""

from __future__ import annotations

import contextlib
import os
import socket
import threading
from pathlib import Path

from emlogd.daemon.notify import Notifier


def _recv(sock: socket.socket) -> str:
    sock.settimeout(5)
    return sock.recv(4096).decode()


def test_messages_reach_the_socket(tmp_path: Path) -> None:
    """READY, STATUS (newlines flattened), WATCHDOG and STOPPING each arrive as one datagram, and
    the watchdog interval is half of WATCHDOG_USEC."""
    path = tmp_path / "notify.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind(str(path))
        n = Notifier.from_env({"NOTIFY_SOCKET": str(path), "WATCHDOG_USEC": "4000000"})
        assert n.enabled and n.watchdog_interval_s == 2.0
        assert n.ready() and _recv(srv) == "READY=1"
        assert (
            n.status("emlog1 learning\nsecond line")
            and _recv(srv) == "STATUS=emlog1 learning second line"
        )
        assert n.watchdog() and _recv(srv) == "WATCHDOG=1"
        assert n.stopping() and _recv(srv) == "STOPPING=1"
        assert n.sent == 4


def test_abstract_namespace() -> None:
    """A NOTIFY_SOCKET starting with '@' reaches the abstract-namespace socket."""
    name = f"emlogd-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind("\0" + name)
        n = Notifier(f"@{name}")
        assert n.ready() and _recv(srv) == "READY=1"


def test_disabled_and_failing() -> None:
    """Without NOTIFY_SOCKET the notifier is off and sends nothing; an unreachable socket makes
    ready() false and counts one failure."""
    off = Notifier.from_env({})
    assert not off.enabled and not off.ready() and off.watchdog_interval_s is None
    gone = Notifier("/nonexistent/notify.sock")
    assert not gone.ready() and gone.failed == 1


def test_watchdog_for_another_pid_is_ignored() -> None:
    """WATCHDOG_USEC meant for another process (WATCHDOG_PID not ours) leaves the watchdog off."""
    other = str(os.getpid() + 1)
    n = Notifier.from_env({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "1000", "WATCHDOG_PID": other})
    assert n.watchdog_interval_s is None


def test_watchdog_for_our_pid_and_malformed_values() -> None:
    """WATCHDOG_PID equal to our pid enables the watchdog; malformed or zero values do not."""
    ours = Notifier.from_env(
        {"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": "30000000", "WATCHDOG_PID": str(os.getpid())}
    )
    assert ours.watchdog_interval_s == 15.0
    for usec in ("", "abc", "-5", "0", "1e6", "²", "١٠٠٠٠٠", " 100000"):
        n = Notifier.from_env({"NOTIFY_SOCKET": "/x", "WATCHDOG_USEC": usec})
        assert n.watchdog_interval_s is None, usec


def test_status_is_one_bounded_line(tmp_path: Path) -> None:
    """STATUS= carries one line of at most 400 characters, whatever it is given."""
    path = tmp_path / "n.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind(str(path))
        n = Notifier(str(path))
        assert n.status("a\r\nb" + "x" * 1000)
        got = _recv(srv)
    assert got.startswith("STATUS=a b") and len(got) == len("STATUS=") + 400
    assert "\n" not in got and "\r" not in got


def test_a_socket_nobody_reads_never_holds_a_send(tmp_path: Path) -> None:
    """A notify socket whose reader never reads (its queue full after a few datagrams):
    every send returns at once, the ones that do not fit counted as failed; the reader's
    queue, once drained, takes messages again. A blocking send waited for ever."""
    path = tmp_path / "notify.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind(str(path))
        n = Notifier(str(path))
        results: list[bool] = []
        sender = threading.Thread(
            target=lambda: results.extend(n.watchdog() for _ in range(200)), daemon=True
        )
        sender.start()
        sender.join(5.0)  # a blocking send: waits for ever (the thread left behind)
        assert not sender.is_alive(), f"blocked after {n.sent} sends"
        assert results[0] and not results[-1]
        assert n.failed == results.count(False) > 0 and n.sent == results.count(True)
        srv.setblocking(False)
        with contextlib.suppress(BlockingIOError):
            while srv.recv(4096):
                pass
        assert n.ready()
