"""The UDP output (emlogd/daemon/udpsink.py): datagrams sent and counted; a send that
fails shown as ``failing`` with its reason and count, ``open`` again once one succeeds."""

from __future__ import annotations

import contextlib
import socket

from emlogd.daemon.udpsink import FAIL_EVENT_S, UdpSink

LINE = b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n"


def test_udp_sink_sends_datagrams() -> None:
    """UdpSink sends each sentence as one datagram and counts it."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5)
    sink = UdpSink(f"127.0.0.1:{rx.getsockname()[1]}")
    try:
        sink.write(LINE)
        assert rx.recv(1024) == LINE
        assert sink.counters.sentences == 1
        assert sink.state == "open"
    finally:
        sink.close()
        rx.close()


def test_a_failing_send_is_shown_with_its_reason_and_count_until_one_succeeds() -> None:
    """The socket shut for writing (``sendto`` fails with ``EPIPE``): three writes are
    three errors, the state ``failing: EPIPE: Broken pipe (3 sends in a row)`` and one
    ``output_failing`` event; a working socket again: the next write is sent, the state
    ``open``, one ``output_recovered``. A failure within :data:`FAIL_EVENT_S` of the last
    told is counted, not told again (a route that comes and goes)."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5)
    now = [0.0]
    events: list[tuple[str, str]] = []
    sink = UdpSink(
        f"127.0.0.1:{rx.getsockname()[1]}",
        on_event=lambda kind, detail: events.append((kind, detail)),
        monotonic=lambda: now[0],
    )
    try:
        with contextlib.suppress(OSError):
            sink.sock.shutdown(socket.SHUT_WR)
        for _ in range(3):
            sink.write(LINE)
        assert sink.counters.errors == 3 and sink.counters.sentences == 0
        assert sink.state == "failing: EPIPE: Broken pipe (3 sends in a row)", sink.state
        assert [k for k, _ in events] == ["output_failing"], events
        sink.sock.close()
        sink.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.write(LINE)
        assert rx.recv(1024) == LINE
        assert sink.state == "open" and sink.counters.sentences == 1
        assert [k for k, _ in events] == ["output_failing", "output_recovered"], events
        with contextlib.suppress(OSError):
            sink.sock.shutdown(socket.SHUT_WR)
        sink.write(LINE)
        assert sink.state.startswith("failing: EPIPE") and len(events) == 2, events
        now[0] = FAIL_EVENT_S
        sink.write(LINE)
        assert sink.state.endswith("(2 sends in a row)") and len(events) == 2, events
        sink.sock.close()
        sink.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.write(LINE)
        assert [k for k, _ in events][2:] == ["output_recovered"], events
    finally:
        sink.close()
        rx.close()
