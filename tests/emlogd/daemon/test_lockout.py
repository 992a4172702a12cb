"""Nobody locks anyone out of the real daemon (a subprocess): idle and non-reading TCP
clients, control clients dripping bytes, a request with a key named twice, a second
instance reaching the state file through a symlink. Fake sensors on real ptys, real
sockets on 127.0.0.1, every wait bounded."""

from __future__ import annotations

import contextlib
import fcntl
import math
import select
import socket
import struct
import subprocess
import sys
import termios
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from emlogd.client import request
from emlogd.daemon.control import MAX_CLIENTS, REQUEST_S
from emlogd.launch import DaemonProcess
from tests.emlogd.daemon.harness import Daemon, free_port, tcp_port

STALL_S = 1.0
"""``outputs.tcp_stall_s`` of these tests (the default is 10 s)."""

CONFIG = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}
  - {name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut, baud: 38400}
  - {name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.165}
  - {uut: emlog2, reference: dvl, lag: 0.025, talker: VM}
outputs:
  pty: out/emlog0
  tcp: "127.0.0.1:{tcp}"
  tcp_stall_s: {stall}
  status_sentence_interval_s: 0.2
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
status_log_interval_s: 1
""".replace("{stall}", f"{STALL_S:g}")


@pytest.fixture
def daemon(work: Path) -> Iterator[DaemonProcess]:
    d = Daemon(work)
    try:
        yield d
    finally:
        d.kill()


def _tcp_counters(d: DaemonProcess, port: int) -> dict[str, int]:
    outputs = d.ask(cmd="status")["outputs"]
    assert isinstance(outputs, dict)
    doc = outputs[f"tcp:127.0.0.1:{port}"]
    assert isinstance(doc, dict)
    return {k: v for k, v in doc.items() if isinstance(v, int)}


def _first_sentence(s: socket.socket, timeout_s: float) -> float:
    """Seconds until ``s`` receives a whole sentence (fails after ``timeout_s``)."""
    t0 = time.monotonic()
    s.settimeout(timeout_s)
    data = b""
    while b"\r\n" not in data:
        chunk = s.recv(4096)
        assert chunk, f"closed after {data!r}"
        data += chunk
    assert data.startswith(b"$"), data[:40]
    return time.monotonic() - t0


@pytest.mark.usefixtures("sensors")
def test_40_idle_tcp_clients_then_a_new_one_receives_within_3_s(
    work: Path, daemon: DaemonProcess
) -> None:
    """40 clients connect and never read; a new client then gets sentences within 3 s: each
    newcomer past the 32-client limit evicted a client (counted as evicted), none was
    refused."""
    port = tcp_port(work)
    idle = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(40)]
    try:
        fresh = socket.create_connection(("127.0.0.1", port), timeout=5)
        try:
            assert _first_sentence(fresh, 3.0) < 3.0
        finally:
            fresh.close()
        counters = _tcp_counters(daemon, port)
        assert counters["evicted"] == 41 - 32, counters
        assert counters["clients"] <= 32, counters
    finally:
        for s in idle:
            s.close()
    assert daemon.stop() == 0


def _held(s: socket.socket) -> int:
    """Bytes waiting unread in ``s``'s receive buffer."""
    return int(struct.unpack("i", fcntl.ioctl(s.fileno(), termios.FIONREAD, b"\0" * 4))[0])


@pytest.mark.usefixtures("sensors")
def test_a_tcp_client_that_floods_the_output_port_is_closed(
    work: Path, daemon: DaemonProcess
) -> None:
    """A client sending as fast as it can to the (output-only) TCP port is reset as
    client_sent_data within a second or two, once past its TCP_INPUT_BURST budget; a
    client that sends one sentence keeps its slot, and a reading client is served on."""
    port = tcp_port(work)
    reader = socket.create_connection(("127.0.0.1", port), timeout=5)
    polite = socket.create_connection(("127.0.0.1", port), timeout=5)
    flood = socket.create_connection(("127.0.0.1", port), timeout=5)
    try:
        polite.sendall(b"$GPHDT,123.4,T*33\r\n")  # an echo: within the budget
        flood.setblocking(False)
        chunk = b"x" * 65536
        t0 = time.monotonic()
        with pytest.raises((ConnectionResetError, BrokenPipeError)):
            while time.monotonic() - t0 < 5.0:
                with contextlib.suppress(BlockingIOError):
                    flood.send(chunk)
                    continue
                select.select([], [flood], [], 0.1)
        assert time.monotonic() - t0 < 3.0
        assert _first_sentence(reader, 3.0) < 3.0
        assert _first_sentence(polite, 3.0) < 3.0
        counters = _tcp_counters(daemon, port)
        assert counters["sent_data"] == 1 and counters["clients"] == 2, counters
        assert f'"peer": "{flood.getsockname()}"' in daemon.log_path.read_text()
    finally:
        for s in (reader, polite, flood):
            s.close()
    assert daemon.stop() == 0


@pytest.mark.usefixtures("sensors")
def test_a_tcp_client_that_does_not_read_is_evicted(work: Path, daemon: DaemonProcess) -> None:
    """A client that never reads and one that reads a byte now and then are reset as
    client_stalled; the one that never reads within tcp_stall_s (+ 3 s, under the
    default 10 s) of the last byte its full receive buffer took, however fast the output
    filled it; a reading client keeps receiving all along."""
    port = tcp_port(work)
    reader = socket.create_connection(("127.0.0.1", port), timeout=5)
    slow: list[socket.socket] = []
    for _ in range(2):
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # full after a few KiB
        s.connect(("127.0.0.1", port))
        slow.append(s)
    never, trickle = slow
    trickle.setblocking(False)
    reader.setblocking(False)
    watch = select.poll()
    watch.register(never, select.POLLRDHUP | select.POLLHUP | select.POLLERR)
    try:
        deadline = time.monotonic() + 60.0
        received = held = 0
        grew = reset = math.nan
        while math.isnan(reset) or _tcp_counters(daemon, port)["stalled"] < 2:
            assert time.monotonic() < deadline, _tcp_counters(daemon, port)
            with contextlib.suppress(BlockingIOError, ConnectionError):
                trickle.recv(1)
            with contextlib.suppress(BlockingIOError):
                received += len(reader.recv(65536))
            if math.isnan(reset):
                if _held(never) > held:
                    held, grew = _held(never), time.monotonic()
                if watch.poll(0):
                    reset = time.monotonic()
            time.sleep(0.1)
        assert held > 0 and received > 0
        assert reset - grew < STALL_S + 3.0, (reset - grew, held)
        never.settimeout(5)
        with pytest.raises(ConnectionResetError):  # reset, once what it holds is read
            while never.recv(1 << 20):
                pass
        assert _first_sentence(reader, 3.0) < 3.0  # the reader is served on
        counters = _tcp_counters(daemon, port)
        assert counters["clients"] == 1 and counters["too_slow"] == 0, counters
        log = daemon.log_path.read_text()
        for s in slow:
            assert f'"peer": "{s.getsockname()}"' in log
        assert log.count('"event": "client_stalled"') == 2
    finally:
        for s in [reader, *slow]:
            s.close()
    assert daemon.stop() == 0


def test_drip_control_clients_do_not_lock_the_operator_out(
    work: Path, daemon: DaemonProcess
) -> None:
    """20 clients drip a byte every 0.5 s into the control socket: an operator's
    ``emlogd status`` still answers at once (the clients waiting longest make room), and
    every dripper is closed with an error line within REQUEST_S of its first byte."""
    drips: list[socket.socket] = []
    try:
        for _ in range(MAX_CLIENTS + 4):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(str(daemon.socket))
            s.setblocking(False)
            drips.append(s)
        t0 = time.monotonic()
        answered = False
        text = b'{"cmd": "status"}'
        i = 0
        while time.monotonic() - t0 < REQUEST_S + 2.0:
            for s in drips:
                with contextlib.suppress(OSError):
                    s.send(text[i % len(text) : i % len(text) + 1])
            i += 1
            if not answered and i == 4:
                t = time.monotonic()
                out = subprocess.run(
                    [sys.executable, "-m", "emlogd", "status", "--socket", str(daemon.socket)],
                    capture_output=True,
                    text=True,
                    timeout=30,
                )
                took = time.monotonic() - t
                assert out.returncode == 0 and "emlog1" in out.stdout, out
                assert took < 5.0, took  # the interpreter's start-up included
                t = time.monotonic()
                assert request(daemon.socket, {"cmd": "status"}, timeout_s=1.0)["ok"]
                assert time.monotonic() - t < 1.0
                answered = True
            time.sleep(0.5)
        assert answered
        replies = []
        for s in drips:
            s.settimeout(2.0)
            data = b""
            with contextlib.suppress(ConnectionError):
                while chunk := s.recv(4096):
                    data += chunk
            replies.append(data)
        timed_out = sum(b"request not complete within" in r for r in replies)
        evicted = sum(b"too many clients" in r for r in replies)
        assert timed_out + evicted == len(drips), replies
        assert evicted >= 4 and timed_out > 0, (evicted, timed_out)
        assert request(daemon.socket, {"cmd": "status"})["ok"]
    finally:
        for s in drips:
            s.close()
    assert daemon.stop() == 0


def test_a_key_named_twice_is_refused(work: Path, daemon: DaemonProcess) -> None:
    """``{"cmd":"status","cmd":"reset"}`` (a reset by JSON's last-one-wins) is refused with
    an error naming the key, and nothing is reset."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(5)
        s.connect(str(daemon.socket))
        s.sendall(b'{"cmd":"status","cmd":"reset"}\n')
        answer = s.recv(4096)
    assert answer == b'{"ok": false, "error": "duplicate key \'cmd\'"}\n'
    assert '"control_reset"' not in daemon.log_path.read_text()
    assert daemon.stop() == 0
    assert '"control_reset"' not in daemon.log_path.read_text()


def test_a_second_instance_through_a_symlinked_state_file_refuses_to_start(
    work: Path, daemon: DaemonProcess
) -> None:
    """A second daemon with a config of its own (its own control socket, pty and TCP port)
    whose state file is a symlink to the first's exits 1 with one line naming the real
    path and the first's pid, within the timeout (had it started, it would run until
    killed); the first runs on."""
    link = work / "elsewhere.yaml"
    link.symlink_to(work / "state" / "state.yaml")
    text = (work / "emlogd.yaml").read_text()
    other = (
        text.replace("run/control.sock", "run/other.sock")
        .replace("out/emlog0", "out/other0")
        .replace(f"127.0.0.1:{tcp_port(work)}", f"127.0.0.1:{free_port()}")
        .replace("state/state.yaml", "elsewhere.yaml")
    )
    (work / "other.yaml").write_text(other)
    second = subprocess.run(
        [sys.executable, "-m", "emlogd", "run", "--config", "other.yaml"],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=15,
    )
    assert second.returncode == 1, second
    assert second.stderr.count("\n") == 1, second.stderr
    assert f"real path {work / 'state' / 'state.yaml'}" in second.stderr
    assert f"pid {daemon.pid}" in second.stderr
    assert not (work / "run" / "other.sock").exists()
    assert daemon.ask(cmd="status")["ok"]
    assert daemon.stop() == 0
