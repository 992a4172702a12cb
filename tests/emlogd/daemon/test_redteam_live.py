"""The third red team's findings against the live daemon, each pinned: a log reader
that is alive but does not read, TCP clients connecting again at once after each
close, and what the inputs, the clock, the signals and the control socket may throw at
it.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon."""

from __future__ import annotations

import contextlib
import fcntl
import functools
import json
import os
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.io.port import DEVICE_CHECK_S
from emlogd.client import request
from emlogd.config import MAX_CONFIG_BYTES
from emlogd.daemon.listen import SOURCE_BURST, SOURCE_RATE
from emlogd.daemon.loop import RELOAD_MIN_S
from emlogd.launch import STOP_TIMEOUT_S, fake_sensors
from tests.drivers.rdi_cases import HOSTILE_HEADER
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    SPEED,
    Daemon,
    device_ptys,
    free_port,
    make_work,
    raw_pty,
    reaped,
    run_daemon,
    tcp_port,
    wait,
)
from tests.emlogd.daemon.test_lockout import _first_sentence, _tcp_counters
from tests.emlogd.daemon.test_redteam import CONFIG, F_SETPIPE_SZ, _answers
from tests.sockets import drain

PORTS = ("emlog1", "dvl")
"""The sensors of ``CONFIG`` (a port served that the daemon never opens holds the
fake's one clock)."""


def _stop(proc: subprocess.Popen[bytes]) -> int:
    proc.send_signal(signal.SIGTERM)
    return proc.wait(STOP_TIMEOUT_S)


def _queued(fd: int) -> int:
    """Bytes waiting in the pipe whose read end is ``fd``."""
    raw = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
    return int(struct.unpack("i", raw)[0])


def test_a_log_reader_that_does_not_read_costs_log_lines_not_the_daemon(tmp_path: Path) -> None:
    """The daemon's stdout and stderr a pipe (one page) whose reader is alive but never
    reads (a stopped ``emlogd run | less``, a journald stuck): the daemon answers every
    status request at once, counts the lines it could not write (``log_lines_lost``) and
    exits 0 on SIGTERM; the lines that did go out are whole JSON lines (the lines past
    its backlog counted lost: ``TestLogStream``). The blocking
    write held the daemon's one thread from the first full page on: no status answer,
    no output, no exit."""
    work = make_work(tmp_path, CONFIG)
    sock = work / "run" / "control.sock"
    r, w = os.pipe()
    fcntl.fcntl(w, F_SETPIPE_SZ, 4096)  # one page: full with the first status line
    try:
        with reaped(run_daemon(work, w)) as proc:
            os.close(w)
            w = -1
            wait(functools.partial(_answers, sock), "the control socket", 10.0)
            for _ in range(30):  # 3 s: three status lines of 3 KB, past the page
                t0 = time.monotonic()
                assert _answers(sock)
                assert time.monotonic() - t0 < 1.0
                time.sleep(0.1)
            assert 0 < _queued(r) <= 4096
            assert _stop(proc) == 0
            os.set_blocking(r, False)
            lines = drain(r).decode().splitlines()
            assert lines and all(json.loads(x)["event"] for x in lines), lines[-1]
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)


def _reconnect_loop(port: int, source: str, until: float, conns: list[int]) -> None:
    """Connect from ``source`` and send 64 KiB blocks until closed, then again at once,
    until ``until`` (monotonic): the client ``bench_tcp_flood --mode reconnect`` runs."""
    block = b"x" * 65536
    while time.monotonic() < until:
        with contextlib.suppress(OSError):
            s = socket.create_connection(("127.0.0.1", port), 0.5, source_address=(source, 0))
            conns[0] += 1
            with s:
                while time.monotonic() < until:
                    s.send(block)


def test_a_client_reconnecting_at_once_after_each_reset_is_held_to_its_budget(
    tmp_path: Path, trial_files: dict[str, Path]
) -> None:
    """Two threads of one host (127.0.0.2) sending to the TCP output port and connecting
    again at once after each reset, for 3 s: the daemon makes clients of at most its
    budget (``SOURCE_BURST`` at once, then ``SOURCE_RATE`` a second), resets the rest
    as ``throttled``, and a newcomer from another host (127.0.0.3) connects within a
    second and a half, while a reader connected before keeps receiving. Each of the
    thousands of connections was accepted, registered, read and reset (0.37 cores)."""
    work = make_work(tmp_path, CONFIG)
    port = tcp_port(work)
    with contextlib.ExitStack() as stack:
        stack.enter_context(
            fake_sensors(trial_files["figure-8"], work / "links", PORTS, speed=SPEED)
        )
        d = Daemon(work)
        stack.callback(d.kill)
        reader = socket.create_connection(("127.0.0.1", port), timeout=5)
        stack.callback(reader.close)
        conns = [0]
        until = time.monotonic() + 3.0
        threads = [
            threading.Thread(target=_reconnect_loop, args=(port, "127.0.0.2", until, conns))
            for _ in range(2)
        ]
        for t in threads:
            t.start()
        time.sleep(1.0)
        t0 = time.monotonic()
        fresh = socket.create_connection(("127.0.0.1", port), 3.0, source_address=("127.0.0.3", 0))
        connect_s = time.monotonic() - t0
        fresh.close()
        for t in threads:
            t.join()
        counters = _tcp_counters(d, port)
        assert connect_s < 1.5, connect_s
        assert counters["throttled"] > 0, counters
        # the flooder's clients, all reset as sent_data; 1 s of slack for a slow machine
        assert counters["sent_data"] <= SOURCE_BURST + SOURCE_RATE * 4.0, counters
        assert counters["clients"] == 1, counters
        assert _first_sentence(reader, 3.0) < 3.0  # the reader, still served
        assert d.stop() == 0


def test_a_sighup_storm_costs_a_few_reloads(tmp_path: Path) -> None:
    """100 SIGHUPs a second for 2 s, the config changed (a UDP output added) half-way:
    at most one reload per ``RELOAD_MIN_S``, the last of them after the change, so the
    UDP output is open; the daemon answers and stops with 0. Each SIGHUP was a reload
    (reading and building the config, a log line), about 100 a second."""
    work = make_work(tmp_path, CONFIG)
    d = Daemon(work)
    try:
        cfg = work / "emlogd.yaml"
        udp = f"127.0.0.1:{free_port()}"
        t0 = time.monotonic()
        for k in range(200):
            if k == 100:
                cfg.write_text(cfg.read_text().replace("outputs: {", f'outputs: {{udp: "{udp}", '))
            d.send_signal(signal.SIGHUP)
            time.sleep(max(t0 + (k + 1) * 0.01 - time.monotonic(), 0.0))
        elapsed = time.monotonic() - t0
        wait(lambda: f"udp:{udp}" in d.ask(cmd="status")["outputs"], "the UDP output", 5.0)  # type: ignore[operator]
        assert d.events("reloaded") <= elapsed / RELOAD_MIN_S + 2, d.events("reloaded")
        assert d.stop() == 0
    finally:
        d.kill()


VHW = (b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n", b"$VWVHW,,T,,M,5.01,N,,K*4E\r\n")
"""Two readings the EMlog alternates (one repeated for ever is a stuck log, not emitted)."""


FLOOD = """\
import os, select, sys, time
fd, data, until = int(sys.argv[1]), bytes.fromhex(sys.argv[2]) * 1000, time.time() + float(sys.argv[3])
while time.time() < until:
    try:
        os.write(fd, data)
    except BlockingIOError:
        select.select([], [fd], [], 0.01)
"""
"""Write a pattern (hex) to a descriptor as fast as it takes it, for some seconds: a
process of its own, so that the test's reading thread never waits for it."""


def _flood(fd: int, pattern: bytes, seconds: float) -> subprocess.Popen[bytes]:
    argv = [sys.executable, "-c", FLOOD, str(fd), pattern.hex(), str(seconds)]
    return subprocess.Popen(argv, pass_fds=(fd,))


def _vhw_within(fd: int, seconds: float) -> bool:
    """Whether a VHW comes out of the output pty ``fd`` within ``seconds``."""
    end = time.monotonic() + seconds
    data = b""
    while b"VHW" not in data and (left := end - time.monotonic()) > 0:
        if select.select([fd], [], [], left)[0]:
            data += os.read(fd, 65536)
    return b"VHW" in data


def test_a_dvl_sending_pd0_headers_of_long_ensembles_with_wrong_checksums(
    tmp_path: Path,
) -> None:
    """The PD0 port flooded with headers claiming 16 000-byte ensembles, one every 6
    bytes, their checksums wrong, while the EMlog sends a VHW every 0.1 s: nine in ten
    corrected VHW leave within 50 ms of their reading; each claimed ensemble is a
    checksum reject.
    Each header cost a 16 KB sum in the daemon's one thread: the median VHW waited
    60 ms and 40 of 56 more than 100 ms."""
    work = make_work(tmp_path, PD0_CONFIG)
    with device_ptys(work / "links", ("emlog1", "dvl")) as masters:
        d = Daemon(work, pty=True)
        try:
            tty.setraw(d.fd)
            until = time.monotonic() + 4.0
            flood = _flood(masters[1], HOSTILE_HEADER, 4.0)
            late: list[bool] = []
            while time.monotonic() < until:
                sent = time.monotonic()
                os.write(masters[0], VHW[len(late) % 2])
                late.append(not _vhw_within(d.fd, 0.05))
                time.sleep(max(sent + 0.1 - time.monotonic(), 0.0))
            flood.wait(STOP_TIMEOUT_S)
            assert sum(late) <= len(late) // 10, f"{sum(late)} of {len(late)} late"
            rejects = d.status()["ports"]["dvl"]["rejects"]  # type: ignore[index]
            assert rejects["checksum"] >= 10, rejects  # one per claimed ensemble
            assert d.stop() == 0
        finally:
            d.kill()


CONNECT_FLOOD = """\
import socket, sys, time
path, until, held = sys.argv[1], time.time() + float(sys.argv[2]), []
while time.time() < until:
    s = socket.socket(socket.AF_UNIX)
    try:
        s.connect(path)
    except OSError:
        s.close()
        continue
    held.append(s)
    if len(held) > 200:
        held.pop(0).close()
"""
"""Connect to a unix socket as fast as it accepts, holding the last 200 connections."""


def test_a_connect_flood_on_the_control_socket_does_not_lock_the_operators_out(
    tmp_path: Path,
) -> None:
    """A local process connecting to the control socket as fast as it can (holding its
    last 200 connections), for 3 s: every ``status`` request of the operators is answered
    meanwhile (the daemon accepts a backlog's worth per wake-up, and the client's connect
    waits in the kernel's queue up to its timeout, as the flooder's do). The daemon
    accepted one connection per wake-up and the client's connect, non-blocking, failed
    at once with EAGAIN whenever the backlog was full: "is emlogd running?"."""
    d = Daemon(make_work(tmp_path, CONFIG))
    argv = [sys.executable, "-c", CONNECT_FLOOD, str(d.socket), "3"]
    try:
        with reaped(subprocess.Popen(argv)) as flood:
            time.sleep(0.5)
            for _ in range(5):
                assert request(d.socket, {"cmd": "status"}, timeout_s=5.0)["ok"] is True
                time.sleep(0.2)
            flood.wait(STOP_TIMEOUT_S)
        assert d.stop() == 0
    finally:
        d.kill()


def test_an_emlog_whose_device_path_moves_to_another_device_is_read_there(
    tmp_path: Path,
) -> None:
    """The EMlog's link deleted and made again to name a new pty, the old one left open
    and silent (a device re-created, an adapter re-enumerated under its udev name): the
    daemon reads the new device within a few seconds (``DEVICE_CHECK_S`` of silence, then
    a reopen). It read the old descriptor, silent, for ever: the port stale, the EMlog
    at its path never read."""
    work = make_work(tmp_path, PD0_CONFIG)
    link = work / "links" / "emlog1"
    masters = [raw_pty(link)]
    d = Daemon(work)
    try:
        for k in range(4):
            os.write(masters[0], VHW[k % 2])
        wait(lambda: _records(d) == 4, "the first device read", 5.0)
        link.unlink()
        masters.append(raw_pty(link))
        _write_until_read(d, masters[1], DEVICE_CHECK_S + 4.0)
    finally:
        d.kill()
        for fd in masters:
            os.close(fd)


def _write_until_read(d: Daemon, master: int, within_s: float) -> None:
    """Write VHW to ``master`` every 0.1 s until the EMlog's port has read a fifth
    record, within ``within_s``; then stop the daemon cleanly."""
    deadline = time.monotonic() + within_s
    k = 0
    while _records(d) <= 4:
        assert time.monotonic() < deadline, d.status()["ports"]
        os.write(master, VHW[k % 2])
        k += 1
        time.sleep(0.1)
    assert d.stop() == 0


def test_an_emlog_link_whose_pty_number_another_program_took_is_not_read(
    tmp_path: Path,
) -> None:
    """The EMlog's pty goes away and another program's new pty takes its number while the
    link stays as it was: the daemon does not read that session (the port closed, saying
    why) and reads the device again once its link is made again. It read the other
    program's pty as the EMlog."""
    work = make_work(tmp_path, PD0_CONFIG)
    link = work / "links" / "emlog1"
    master, slave = os.openpty()
    tty.setraw(slave)
    number = os.ttyname(slave)
    os.close(slave)
    link.symlink_to(number)
    masters = [master]
    d = Daemon(work)
    try:
        for k in range(4):
            os.write(master, VHW[k % 2])
        wait(lambda: _records(d) == 4, "the device read", 5.0)
        os.close(masters.pop())  # the device goes away; the daemon closes the port
        wait(lambda: not _port(d)["open"], "the port lost", 5.0)
        other = _pty_numbered(number)
        if other is None:
            pytest.skip(f"{number} was taken by another process before this test could")
        masters.append(other)
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            os.write(other, VHW[0])
            time.sleep(0.1)
        port = _port(d)
        assert _records(d) == 4 and not port["open"], port
        assert "a pty made since under the number" in str(port["why_closed"]), port
        link.unlink()
        link.symlink_to(number)
        _write_until_read(d, other, 8.0)
    finally:
        d.kill()
        for fd in masters:
            os.close(fd)


def _pty_numbered(number: str, tries: int = 50) -> int | None:
    """The master of a raw pty whose slave is ``number``, the slave closed (the kernel
    gives the lowest free number: the one just freed, unless another process takes it
    first); None when it did not come within ``tries``."""
    kept: list[int] = []
    try:
        for _ in range(tries):
            master, slave = os.openpty()
            name = os.ttyname(slave)
            tty.setraw(slave)
            os.close(slave)
            if name == number:
                os.set_blocking(master, False)
                return master
            kept.append(master)
            time.sleep(0.02)
        return None
    finally:
        for fd in kept:
            os.close(fd)


def _port(d: Daemon) -> dict[str, object]:
    ports = d.status()["ports"]
    assert isinstance(ports, dict)
    port = ports["emlog1"]
    assert isinstance(port, dict)
    return port


def _records(d: Daemon) -> int:
    return int(str(_port(d)["records"]))


def _user_flood(path: Path, seconds: float, n: int, uid: int) -> int:
    """Fork a process that becomes user ``uid`` and forks into ``n``, each holding one
    connection to the unix socket ``path`` and connecting again at once whenever it is
    closed, for ``seconds``; the first one's pid (it waits for the others). The
    interpreter may not be readable by ``uid``: the children run on in the fork."""
    first = os.fork()
    if first:
        return first
    code = 0
    try:
        os.setgid(uid)
        os.setuid(uid)
        until = time.monotonic() + seconds
        kids: list[int] = []
        for _ in range(n - 1):
            pid = os.fork()
            if pid == 0:
                kids = []  # a child: none of its own
                break
            kids.append(pid)
        while time.monotonic() < until:
            with socket.socket(socket.AF_UNIX) as s, contextlib.suppress(OSError):
                s.settimeout(1.0)
                s.connect(str(path))
                s.recv(4096)  # held until the daemon closes it
        for pid in kids:
            os.waitpid(pid, 0)
    except BaseException:
        code = 1
    os._exit(code)


FLOOD_PROCESSES = 20
"""Processes of the flooding user: more than ``MAX_CLIENTS``, one connection each."""

NOBODY = 65534
"""The flooding user's id (``nobody``)."""


@pytest.mark.root
@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to run a flood as another user")
def test_a_users_many_processes_on_the_status_socket_do_not_evict_another_users_client(
    tmp_path: Path,
) -> None:
    """Another user's 20 processes on the status socket (mode 0666), each holding one
    connection and connecting again at once when closed, for 3 s: the operator's
    connection, opened before and idle meanwhile, is still served afterwards (at the
    client limit the user holding the most connections loses one of its own). Eviction
    grouped by process: every flooder held one, as did the operator, whose connection,
    idle longest, was the first closed."""
    sockdir = Path(tempfile.mkdtemp(prefix="emlogd-red4-"))
    try:
        sockdir.chmod(0o755)  # the other user reaches the socket (tmp_path is root's only)
        status = sockdir / "status.sock"
        config = CONFIG.replace("outputs:", f"status_socket: {status}\noutputs:")
        d = Daemon(make_work(tmp_path, config))
        try:
            with socket.socket(socket.AF_UNIX) as operator:
                operator.settimeout(5.0)
                operator.connect(str(status))
                time.sleep(0.2)  # accepted before the flood
                flood = _user_flood(status, 3.0, FLOOD_PROCESSES, NOBODY)
                try:
                    time.sleep(3.0)
                    assert _status_answered(operator), d.status()
                finally:
                    os.waitpid(flood, 0)
            assert d.stop() == 0
        finally:
            d.kill()
    finally:
        shutil.rmtree(sockdir, ignore_errors=True)


def _status_answered(sock: socket.socket) -> bool:
    """A status request on ``sock`` gets an ``ok`` answer (and not the eviction's error)."""
    try:
        sock.sendall(b'{"cmd": "status"}\n')
        buf = b""
        while not buf.endswith(b"\n"):
            chunk = sock.recv(65536)
            if not chunk:
                return False
            buf += chunk
    except OSError:
        return False
    return bool(json.loads(buf.splitlines()[0])["ok"])


def _slow_config(config: str) -> str:
    """``config`` grown to a quarter of the size limit with a flow list of one-digit
    items under an unknown key: the YAML the parser takes longest on for its size (a
    reload fails on the key, once the whole file is parsed). A quarter takes the parser
    1.4 s (the whole limit 5.8 s), well past the 0.5 s a VHW may take."""
    room = MAX_CONFIG_BYTES // 4 - len(config) - 16
    return config + "zz: [" + "1," * (room // 2) + "1]\n"


def test_a_reload_of_a_config_slow_to_parse_does_not_hold_the_output(tmp_path: Path) -> None:
    """A SIGHUP into a config of 64 KiB that the YAML parser takes seconds on, while the
    EMlog sends a VHW every 0.1 s: every corrected VHW leaves within 0.5 s of its reading
    (the config is parsed beside the loop), and the reload is refused in the end, the
    running config kept. Parsed in the daemon's one thread it held every output for the
    whole parse (6 s)."""
    work = make_work(tmp_path, PD0_CONFIG)
    config = (work / "emlogd.yaml").read_text()
    with _pd0_daemon(work) as (d, emlog):
        (work / "emlogd.yaml").write_text(_slow_config(config))
        late: list[float] = []
        sent = time.monotonic()
        os.kill(d.proc.pid, signal.SIGHUP)
        while d.events("reload_failed") == 0:
            assert time.monotonic() - sent < 30.0, "no reload_failed"
            t0 = time.monotonic()
            os.write(emlog, VHW[len(late) % 2])
            if not _vhw_within(d.fd, 0.5):
                late.append(t0 - sent)
            time.sleep(max(t0 + 0.1 - time.monotonic(), 0.0))
        assert not late, f"VHW late at {late} s after the SIGHUP"
        assert d.stop() == 0


@contextlib.contextmanager
def _pd0_daemon(work: Path, env: dict[str, str] | None = None) -> Iterator[tuple[Daemon, int]]:
    """The daemon of ``PD0_CONFIG`` in ``work`` (its environment ``env``), its output pty
    raw, and the EMlog's pty master (the DVL's served, silent); killed and closed at the
    end of the block."""
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    try:
        d = Daemon(work, pty=True, env=env)
        try:
            tty.setraw(d.fd)
            yield d, masters[0]
        finally:
            d.kill()
    finally:
        for fd in masters:
            os.close(fd)
