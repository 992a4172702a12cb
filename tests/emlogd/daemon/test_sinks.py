"""Output sinks: a TCP client that never reads is dropped, never blocks; streams (UDP:
test_udpsink.py)."""

from __future__ import annotations

import contextlib
import io
import selectors
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TypeAlias

import pytest

from drivers.errors import ConfigError
from emlogd.config import OutputConfig
from emlogd.daemon.listen import AcceptBudget
from emlogd.daemon.sinks import (
    TCP_BACKLOG_BYTES,
    TCP_CHECK_S,
    TCP_ENDED_QUIET_S,
    TCP_INPUT_BURST,
    TCP_INPUT_RATE,
    THROTTLE_PAUSE_S,
    StreamSink,
    TcpLimits,
    TcpServerSink,
    parse_hostport,
)

LINE = b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n"


def test_parse_hostport() -> None:
    """parse_hostport accepts HOST:PORT, :PORT, PORT and [IPv6]:PORT, and refuses a missing, zero,
    too large or non-numeric port."""
    assert parse_hostport("127.0.0.1:10110") == ("127.0.0.1", 10110)
    assert parse_hostport(":10110") == ("0.0.0.0", 10110)
    assert parse_hostport("10110") == ("0.0.0.0", 10110)
    assert parse_hostport("[::1]:5") == ("::1", 5)
    for bad in ("host:", "host:0", "host:70000", "a:b"):
        with pytest.raises(ConfigError, match="HOST:PORT"):
            parse_hostport(bad)


def test_the_tcp_limits_default_to_the_config_keys_defaults() -> None:
    """TcpLimits() (the sink's default) is what the outputs.tcp_* keys default to."""
    out = OutputConfig()
    assert TcpLimits() == TcpLimits(out.tcp_max_clients, out.tcp_max_pending_bytes, out.tcp_stall_s)


def _pump(sel: selectors.BaseSelector, until: float = 0.3) -> None:
    end = time.monotonic() + until
    while time.monotonic() < end:
        for key, _ in sel.select(timeout=0.02):
            key.data()


class _Clock:
    """A monotonic clock the test moves."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


Served: TypeAlias = tuple[
    TcpServerSink, selectors.BaseSelector, _Clock, list[tuple[str, str]], list[socket.socket]
]
"""What :func:`_serving` yields: the sink, its selector, its clock, its events, the clients."""


@contextlib.contextmanager
def _serving(limits: TcpLimits | None = None) -> Iterator[Served]:
    """A TCP server sink on a free port with ``limits`` (default: the config keys'
    defaults), the clock it reads (moved by the test), the events it reported and a list
    for the test's clients; the clients, the sink and its selector are closed at the end."""
    sel = selectors.DefaultSelector()
    clock = _Clock()
    notes: list[tuple[str, str]] = []
    sink = TcpServerSink(
        "127.0.0.1:0",
        selector=sel,
        on_event=lambda k, d: notes.append((k, d)),
        monotonic=clock,
        limits=limits or TcpLimits(),
    )
    held: list[socket.socket] = []
    try:
        yield sink, sel, clock, notes, held
    finally:
        for c in held:
            c.close()
        sink.close()
        sel.close()


def test_a_tcp_client_is_closed_past_its_input_budget_refilled_at_the_rate() -> None:
    """What a client sends is discarded within TCP_INPUT_BURST bytes, refilled at
    TCP_INPUT_RATE bytes/s: a client sending at half the rate for long stays; one byte
    over the budget closes it as client_sent_data (counted)."""
    with _serving() as (sink, sel, clock, notes, _):
        c = socket.create_connection(sink.address)
        _pump(sel)
        half = b"x" * int(TCP_INPUT_RATE / 2)
        for _ in range(3 * TCP_INPUT_BURST // len(half)):  # three bursts' worth, in time
            clock.t += 1.0
            c.sendall(half)
            _pump(sel, 0.05)
        assert sink.counters.clients == 1 and sink.counters.sent_data == 0
        clock.t += 10 * TCP_INPUT_BURST / TCP_INPUT_RATE  # the budget refills to the burst only
        c.sendall(b"x" * TCP_INPUT_BURST)
        _pump(sel, 0.1)
        assert sink.counters.clients == 1
        c.sendall(b"x")
        _pump(sel, 0.1)
        assert sink.counters.clients == 0 and sink.counters.sent_data == 1
        assert sink.counters.dropped_clients == 1
        assert ("client_sent_data", str(c.getsockname())) in notes
        c.close()


def test_tcp_clients_receive_and_a_stuck_client_is_dropped() -> None:
    """A TCP client that never reads is dropped as client_too_slow without blocking the writer,
    while a reading client gets the sentences uncut and in order."""
    with _serving() as (sink, sel, _, notes, _):
        good = socket.create_connection(sink.address)
        stuck = socket.create_connection(sink.address)
        stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        _pump(sel)
        assert sink.counters.clients == 2
        good.settimeout(5)
        received = bytearray()
        t0 = time.monotonic()
        n = 0
        # write far more than the socket buffers plus the backlog can hold for a non-reader
        while sink.counters.dropped_clients == 0 and n < 200_000:
            sink.write(LINE)
            n += 1
            if n % 50 == 0:
                received += good.recv(1 << 20)
        elapsed = time.monotonic() - t0
        assert sink.counters.dropped_clients == 1
        assert ("client_too_slow", str(stuck.getsockname())) in notes
        assert sink.counters.clients == 1
        assert elapsed < 30  # it never blocked; generous, only catches a hang
        good.setblocking(False)
        try:
            while True:
                chunk = good.recv(1 << 20)
                if not chunk:
                    break
                received += chunk
        except BlockingIOError:
            pass
        # what the reading client got is the stream as written, uncut and in order, short of
        # at most its backlog (sent with the next write)
        assert len(received) >= n * len(LINE) - TCP_BACKLOG_BYTES
        assert received == (LINE * n)[: len(received)]
        good.close()
        stuck.close()
        _pump(sel)
        for _ in range(2):  # a client gone is noticed at the second write after its close
            sink.write(LINE)
            _pump(sel, 0.05)
        assert sink.counters.clients == 0


def test_a_client_that_ends_its_sending_is_served_on() -> None:
    """A reader that half-closes (``shutdown(SHUT_WR)``, ``nc -N``) keeps receiving for
    as long as output flows, no longer watched for input; a peer closed for good is
    closed at the second write after its close, or once nothing was sent to it for
    TCP_ENDED_QUIET_S; at the client limit a client that ended its sending goes first.
    A client's end of file closed it at once: the half-closed reader never got a
    sentence."""
    with _serving(TcpLimits(max_clients=3)) as (sink, sel, clock, notes, held):
        half, gone, quiet = (socket.create_connection(sink.address) for _ in range(3))
        held += [half, gone, quiet]
        gone_name = str(gone.getsockname())
        _pump(sel)
        half.shutdown(socket.SHUT_WR)
        gone.close()
        _pump(sel)
        assert sink.counters.clients == 3 and len(sel.get_map()) == 2  # listener, quiet
        for _ in range(5):
            clock.t += 1.0
            sink.write(LINE)
            _pump(sel, 0.05)
            sink.housekeep()
        half.settimeout(5)
        assert _read_all(half) == 5 * len(LINE)
        assert sink.counters.clients == 2
        assert ("client_disconnected", gone_name) in notes
        clock.t += TCP_ENDED_QUIET_S + TCP_CHECK_S  # no output: a half-close and a close
        sink.housekeep()  # look alike; both closed once quiet this long
        assert sink.counters.clients == 1
        later = socket.create_connection(sink.address)
        held.append(later)
        _pump(sel)
        later.shutdown(socket.SHUT_WR)
        later_name = str(later.getsockname())
        _pump(sel)
        clock.t += 0.1
        for _ in range(2):
            held.append(socket.create_connection(sink.address))
            clock.t += 0.1
            _pump(sel)
        assert sink.counters.evicted == 1 and sink.counters.clients == 3
        assert ("client_evicted", later_name) in notes


def _stuck_client(address: tuple[str, int]) -> socket.socket:
    """A client that never reads, with a small receive buffer (full after a few KiB)."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(address)
    return s


def _behind(
    sink: TcpServerSink, sel: selectors.BaseSelector, held: list[socket.socket]
) -> socket.socket:
    """A client that reads nothing (:func:`_stuck_client`, kept in ``held``), with 3000
    sentences (93 KB) written past its window and the sink's first check of what it took."""
    stuck = _stuck_client(sink.address)
    held.append(stuck)
    _pump(sel, 0.1)
    for _ in range(3000):
        sink.write(LINE)
    _pump(sel, 0.1)
    sink.housekeep()
    return stuck


def _read_all(s: socket.socket) -> int:
    s.setblocking(False)
    n = 0
    with contextlib.suppress(BlockingIOError):
        while chunk := s.recv(1 << 20):
            n += len(chunk)
    return n


def test_a_tcp_client_that_takes_nothing_is_closed_after_the_stall_time() -> None:
    """A client with output pending that takes nothing for stall_s is reset as
    client_stalled (counted with its reason), a reading client stays; before stall_s
    nothing happens."""
    limits = TcpLimits(max_pending_bytes=1 << 24, stall_s=2.0)
    with _serving(limits) as (sink, sel, clock, notes, _):
        good = socket.create_connection(sink.address)
        stuck = _stuck_client(sink.address)
        _pump(sel)
        for _ in range(4000):  # 124 KB: far more than the stuck client's window
            sink.write(LINE)
        _pump(sel, 0.1)
        _read_all(good)
        while clock.t < limits.stall_s:
            sink.housekeep()
            _read_all(good)
            assert sink.counters.clients == 2, clock.t
            clock.t += TCP_CHECK_S
        clock.t += TCP_CHECK_S
        sink.housekeep()
        assert sink.counters.clients == 1
        assert sink.counters.stalled == 1 and sink.counters.dropped_clients == 1
        assert ("client_stalled", str(stuck.getsockname())) in notes
        stuck.settimeout(5)  # reset, not a FIN queued behind output it will never take
        with pytest.raises(ConnectionResetError):
            while stuck.recv(1 << 20):
                pass
        sink.write(LINE)
        good.settimeout(5)
        assert good.recv(100) == LINE
        good.close()
        stuck.close()


def test_a_tcp_client_is_closed_when_the_kernel_holds_too_much_for_it() -> None:
    """Pending output counts the kernel's send queue, not only the daemon's backlog: a
    client whose queue exceeds max_pending_bytes is closed as client_too_slow at the next
    check, though every write went to the kernel."""
    with _serving(TcpLimits(max_pending_bytes=8192)) as (sink, sel, _clock, notes, _):
        stuck = _stuck_client(sink.address)
        _pump(sel)
        for _ in range(600):  # 19 KB
            sink.write(LINE)
        (client,) = sink.clients.values()
        assert len(client.backlog) <= 8192  # the kernel took it: write() alone would keep it
        sink.housekeep()
        assert sink.counters.too_slow == 1 and sink.counters.clients == 0
        assert ("client_too_slow", str(stuck.getsockname())) in notes
        stuck.close()


def test_at_the_client_limit_a_newcomer_evicts_a_client() -> None:
    """At max_clients a newcomer gets in and receives: the client with output stalled
    longest goes first; among clients that keep up, the most recently connected."""
    limits = TcpLimits(max_clients=3, max_pending_bytes=1 << 24)
    with _serving(limits) as (sink, sel, clock, notes, held):
        stuck = _behind(sink, sel, held)
        clock.t += 1.0
        for _ in range(2):
            clock.t += 0.1
            held.append(socket.create_connection(sink.address))
            _pump(sel, 0.1)
        assert sink.counters.clients == 3
        clock.t += 0.1
        newcomer = socket.create_connection(sink.address)
        held.append(newcomer)
        _pump(sel, 0.1)
        assert sink.counters.clients == 3 and sink.counters.evicted == 1
        assert notes[-2] == ("client_evicted", str(stuck.getsockname()))
        _read_all(held[1])
        _read_all(held[2])
        clock.t += 0.1
        latest = socket.create_connection(sink.address)
        held.append(latest)
        _pump(sel, 0.1)
        assert sink.counters.evicted == 2
        assert notes[-2] == ("client_evicted", str(newcomer.getsockname()))
        sink.write(LINE)
        latest.settimeout(5)
        assert latest.recv(100) == LINE


def test_a_slow_reader_with_output_pending_is_not_taken_for_stalled() -> None:
    """At the client limit a client with output pending that took some since the last
    check keeps its slot: the most recently connected goes instead."""
    limits = TcpLimits(max_clients=2, max_pending_bytes=1 << 24)
    with _serving(limits) as (sink, sel, clock, notes, held):
        slow = _behind(sink, sel, held)
        clock.t += 1.0
        latest = socket.create_connection(sink.address)
        held.append(latest)
        _pump(sel, 0.1)
        slow.settimeout(5)
        assert slow.recv(4096)  # it reads a little: the kernel sends it more
        time.sleep(0.05)
        clock.t += 0.1
        held.append(socket.create_connection(sink.address))
        _pump(sel, 0.1)
        assert notes[-2] == ("client_evicted", str(latest.getsockname()))
        assert sink.counters.evicted == 1 and sink.counters.clients == 2


def test_tcp_connect_disconnect_loop_leaks_nothing() -> None:
    """Fifty connect, write, disconnect cycles leave no client and no selector registration but the
    listening socket."""
    with _serving() as (sink, sel, _, _, _):
        for _ in range(50):
            c = socket.create_connection(sink.address)
            _pump(sel, 0.02)
            sink.write(LINE)
            c.close()
            _pump(sel, 0.02)
            sink.write(LINE)
        _pump(sel, 0.1)
        assert sink.counters.clients == 0
        assert len(sel.get_map()) == 1  # only the listening socket


def test_an_unbindable_tcp_output_is_retried_until_it_binds() -> None:
    """An address in use leaves the sink unbound, writes are harmless, and a retry once
    the address is free binds it (retries follow the sink's monotonic clock)."""
    sel = selectors.DefaultSelector()
    first = TcpServerSink("127.0.0.1:0", selector=sel)
    now = [0.0]
    notes: list[str] = []
    second = TcpServerSink(
        f"127.0.0.1:{first.address[1]}",
        selector=sel,
        on_event=lambda k, d: notes.append(k),
        monotonic=lambda: now[0],
    )
    try:
        assert second.state.startswith("unbound: ") and notes == ["output_unbound"]
        second.write(LINE)
        first.close()  # the address is free from here on
        now[0] = 0.5
        second.housekeep()  # not due yet: no retry, though it would bind now
        assert second.server is None and notes == ["output_unbound"]
        now[0] = 1.0
        second.housekeep()
        assert second.state == "open" and notes == ["output_unbound", "output_bound"]
        c = socket.create_connection(second.address)
        _pump(sel)
        assert second.counters.clients == 1
        c.close()
    finally:
        second.close()
        sel.close()


def test_stream_sink_counts_errors_instead_of_raising() -> None:
    """StreamSink writes to its stream; a write to a closed stream is counted as an error."""
    buf = io.BytesIO()
    sink = StreamSink("mem", buf)
    sink.write(LINE)
    assert buf.getvalue() == LINE
    buf.close()
    sink.write(LINE)
    assert sink.counters.errors == 1 and sink.counters.sentences == 1


@pytest.mark.root
def test_the_pty_output_belongs_to_its_readers_group(tmp_path: Path) -> None:
    """``pty_group``: the pty behind the link is in that group, with the given mode."""
    import grp
    import os
    import stat

    from emlogd.daemon.sinks import PtySink

    groups = [g for g in grp.getgrall() if g.gr_gid != os.getegid()]
    if os.geteuid() != 0 or not groups:
        pytest.skip("needs root and a second group to hand the pty to")
    sink = PtySink(tmp_path / "emlog0", mode=0o640, group=groups[0].gr_name)
    try:
        st = (tmp_path / "emlog0").stat()
        assert st.st_gid == groups[0].gr_gid and stat.S_IMODE(st.st_mode) == 0o640
    finally:
        sink.close()


def test_a_connection_past_the_accept_budget_is_reset_and_the_listener_rests() -> None:
    """A source past its budget: its connection is reset without a read (``throttled``,
    ``client_throttled``), the listener leaves the selector for THROTTLE_PAUSE_S, and
    once it is back a connection from another address is a client."""
    with _serving() as (sink, sel, clock, notes, held):
        sink.budget = AcceptBudget(clock, source=(1.0, 0.001))
        held.append(socket.create_connection(sink.address))
        held.append(socket.create_connection(sink.address))
        _pump(sel, 0.1)
        assert sink.counters.clients == 1 and sink.counters.throttled == 1
        assert notes[-1][0] == "client_throttled"
        with pytest.raises(ConnectionResetError):
            held[1].recv(10)
        assert len(sel.get_map()) == 1  # the client; the listener rests
        clock.t += THROTTLE_PAUSE_S
        sink.housekeep()
        held.append(socket.create_connection(sink.address, source_address=("127.0.0.2", 0)))
        _pump(sel, 0.1)
        assert sink.counters.clients == 2 and sink.counters.throttled == 1


def test_a_removed_pty_link_is_published_again(tmp_path: Path) -> None:
    """The pty output's link removed: at the next check (LINK_CHECK_S) it names the pty
    again, a reader opening it reads what is written, ``pty_link_restored`` noted; a
    link naming another file by then is left as it is, noted once, and kept at close.
    A reader opening the pty by its link (an autopilot after its own restart) found
    nothing there until the daemon's restart."""
    import os

    from emlogd.daemon.sinks import LINK_CHECK_S, PtySink

    t = [0.0]
    notes: list[tuple[str, str]] = []
    link = tmp_path / "emlog0"
    sink = PtySink(link, on_event=lambda k, d: notes.append((k, d)), monotonic=lambda: t[0])
    try:
        link.unlink()
        sink.housekeep()
        assert not link.is_symlink()  # not checked before LINK_CHECK_S
        t[0] += LINK_CHECK_S
        sink.housekeep()
        assert str(link.readlink()) == sink.port.slave_path
        assert [k for k, _ in notes] == ["pty_link_restored"]
        fd = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            sink.write(b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n")
            time.sleep(0.05)
            assert os.read(fd, 100) == b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n"
        finally:
            os.close(fd)
        link.unlink()
        link.symlink_to("/dev/null")
        for _ in range(3):
            t[0] += LINK_CHECK_S
            sink.housekeep()
        assert [k for k, _ in notes] == ["pty_link_restored", "pty_link"]
        assert "names /dev/null now" in notes[-1][1]
    finally:
        sink.close()
    assert str(link.readlink()) == "/dev/null"


def test_a_pty_whose_modes_a_reader_keeps_changing_is_one_line_a_minute(tmp_path: Path) -> None:
    """A reader that sets canonical mode before every link check: the modes are put back
    at each check, and ``pty_modes_restored`` is said once per ``MODES_LOG_S``, the next
    line with how many times since the one before."""
    import os
    import termios

    from emlogd.daemon.sinks import LINK_CHECK_S, MODES_LOG_S, PtySink

    t = [0.0]
    notes: list[tuple[str, str]] = []
    link = tmp_path / "emlog0"
    sink = PtySink(link, on_event=lambda k, d: notes.append((k, d)), monotonic=lambda: t[0])
    fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        checks = int(MODES_LOG_S / LINK_CHECK_S)
        for _ in range(checks + 1):
            attrs = termios.tcgetattr(fd)
            attrs[3] |= termios.ICANON
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
            t[0] += LINK_CHECK_S
            sink.housekeep()
            assert not termios.tcgetattr(fd)[3] & termios.ICANON
        said = [d for k, d in notes if k == "pty_modes_restored"]
        assert len(said) == 2, said
        assert said[0].endswith("(1 time)") and said[1].endswith(f"({checks} times)"), said
    finally:
        os.close(fd)
        sink.close()
