"""A ``socket://`` input: connected without blocking, read, lost and retried (real
sockets on 127.0.0.1; the source's monotonic clock injected for the connect timeout)."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest

from drivers.errors import DeviceError
from drivers.io.port import CONNECT_TIMEOUT_S, SerialSource, socket_url_problem, url_problem
from tests.sockets import unanswered_port

LINE = b"$VWVHW,,T,,M,5.0,N,9.26,K*55\r\n"


class _Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def blackhole() -> Iterator[int]:
    """A port that does not answer (:func:`tests.sockets.unanswered_port`)."""
    with unanswered_port() as port:
        yield port


def _until(cond: object, src: SerialSource, clock: _Clock, timeout_s: float = 5.0) -> None:
    end = time.monotonic() + timeout_s
    while not (callable(cond) and cond()):
        assert time.monotonic() < end
        clock.t += 0.1
        src.poll()
        time.sleep(0.01)


def test_an_unanswered_connect_costs_no_wait_and_fails_after_its_timeout(blackhole: int) -> None:
    """``open`` returns at once (pyserial's waited 5 s in the daemon's one thread), the
    port says it is connecting; past :data:`CONNECT_TIMEOUT_S` of the source's clock it
    is ``disconnected`` (timed out) and retried."""
    clock = _Clock()
    src = SerialSource("gnss", f"socket://127.0.0.1:{blackhole}", monotonic=clock)
    t0 = time.monotonic()
    assert src.open() is False
    for _ in range(5):
        src.poll()
    assert time.monotonic() - t0 < 0.5
    assert not src.is_open and "connecting" in str(src.why_closed)
    assert src.events() == []
    clock.t += CONNECT_TIMEOUT_S + 0.1
    events = src.poll()
    assert [e.kind for e in events] == ["disconnected"]
    assert "timed out" in events[0].detail
    src.close()


def test_a_tcp_input_is_read_and_reconnected_after_the_peer_closes() -> None:
    """Connected: the bytes the peer sends arrive; the peer closing is a lost port
    (``disconnected``), and the next connect reads again (``reconnects`` 1)."""
    clock = _Clock()
    with socket.socket() as ls:
        ls.bind(("127.0.0.1", 0))
        ls.listen(4)
        port = int(ls.getsockname()[1])
        src = SerialSource("gnss", f"socket://127.0.0.1:{port}", monotonic=clock)
        for round_ in range(2):
            src.open()
            conn, _ = ls.accept()
            _until(lambda: src.is_open, src, clock)
            assert [e.kind for e in src.events()] == ["connected"]
            conn.sendall(LINE * 10)
            data = b""
            end = time.monotonic() + 5
            while len(data) < len(LINE) * 10 and time.monotonic() < end:
                chunk = src.read()
                if chunk is not None:
                    data += chunk[1]
            assert data == LINE * 10
            conn.close()
            end = time.monotonic() + 5
            while src.is_open and time.monotonic() < end:
                src.read()
            assert not src.is_open
            assert [e.kind for e in src.events()] == ["disconnected"]
            assert src.reconnects == round_
            clock.t += 10.0  # past the backoff
        src.close()


def test_a_socket_input_by_host_name_is_refused_an_address_is_not() -> None:
    """A socket:// host must be an IP address (a name would go to the system's resolver,
    in the daemon's one thread): a name is a DeviceError at construction (and a config
    error: tests/emlogd/test_config.py), an IPv4 or IPv6 address or a device path is not."""
    for name in ("localhost", "gnss.local", "h"):
        assert socket_url_problem(f"socket://{name}:10110") is not None
        with pytest.raises(DeviceError, match="needs an IP address, not a host name"):
            SerialSource("gnss", f"socket://{name}:10110")
    for ok in ("socket://127.0.0.1:10110", "socket://[::1]:10110", "/dev/ttyUSB0"):
        assert socket_url_problem(ok) is None
        SerialSource("gnss", ok).close()


def test_an_rfc2217_input_and_a_socket_scheme_in_capitals_are_judged() -> None:
    """pyserial takes a URL's scheme in any case and opens ``rfc2217://`` in the caller's
    thread (resolve, connect, negotiate: 3.4 s against a server that never answers, 5 s
    against one that is off, at every retry): ``rfc2217://`` is refused in any case, and
    ``SOCKET://`` is a socket input like ``socket://``, its host an IP address and its
    connect the port's own. ``SOCKET://`` and ``rfc2217://`` passed the check, then went
    to pyserial's blocking open (``tests/emlogd/daemon/test_redteam.py -k socket_input``)."""
    for url in ("rfc2217://127.0.0.1:2217", "RFC2217://10.0.0.5:2217"):
        assert url_problem(url) is not None
        with pytest.raises(DeviceError, match="rfc2217:// input in the daemon's one thread"):
            SerialSource("gnss", url)
    assert url_problem("SOCKET://gnss.local:10110") is not None
    src = SerialSource("gnss", "SOCKET://127.0.0.1:10110")
    assert src._tcp == ("127.0.0.1", 10110)
    src.close()
    assert url_problem("/dev/ttyUSB0") is None and url_problem("loop://") is None
