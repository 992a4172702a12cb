"""The thirteenth red team's findings, each pinned: the live daemon, and sensors that
lie in ways the twelfth did not try, edited into the simulated trial's captures and
replayed against the truth.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon, nothing
worse than raw reaches the autopilot."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import time
import tty
from pathlib import Path

from emlogd.client import request
from emlogd.daemon.outputs import OUTPUT_RETRY_S
from emlogd.launch import STOP_TIMEOUT_S
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    make_work,
    raw_pty,
    reaped,
    run_daemon,
    wait,
)
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon
from tests.emlogd.daemon.test_redteam_reload import TWO_LOGS


def test_a_watchdog_interval_of_a_digit_int_cannot_read_is_no_watchdog(tmp_path: Path) -> None:
    """``WATCHDOG_USEC=²`` (a unit's ``Environment=`` line, a superscript typed for a
    square): the daemon starts, says ``READY=1``, decodes its EMlog and exits 0, with no
    watchdog. ``str.isdigit`` takes ``²`` for a digit and ``int`` refused it: the start
    ended with ``internal error: ValueError`` (exit 1, a restart loop under systemd)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify:
        notify.bind(str(work / "notify.sock"))
        notify.settimeout(5.0)
        env = {**os.environ, "NOTIFY_SOCKET": str(work / "notify.sock"), "WATCHDOG_USEC": "²"}
        with _pd0_daemon(work, env) as (d, emlog):
            assert notify.recv(4096) == b"READY=1"
            for k in range(5):
                os.write(emlog, VHW[k % 2])
            d.pump(1.0)
            assert any(line.startswith(b"$VWVHW") for line in d.lines)
            assert d.stop() == 0
            notify.setblocking(False)
            said = []
            while True:
                try:
                    said.append(notify.recv(4096))
                except BlockingIOError:
                    break
            assert b"WATCHDOG=1" not in said, said


OTHER_VHW = (b"$VWVHW,,T,,M,7.00,N,,K*4D\r\n", b"$VWVHW,,T,,M,7.01,N,,K*4C\r\n")
"""The second EMlog's two readings (7 kn against the first's 5)."""


def test_a_log_whose_own_pty_is_not_open_sends_nothing_to_the_shared_one(
    tmp_path: Path,
) -> None:
    """emlog2 has a pty of its own (``calibration[].pty``), a regular file in its way at
    the start; emlog1 goes out on the shared pty, both under talker ``VW`` (the config's
    check lets two logs share a talker when one has outputs of its own: it writes only
    there). The shared pty carries emlog1's sentences only; once the file is gone emlog2's
    own pty is published and carries emlog2's. emlog2's sentences went to the shared
    outputs while its own was not open: the autopilot on the shared pty read `$VWVHW`
    at 7 kn and 5 kn in turns, two logs it cannot tell apart."""
    work = make_work(tmp_path, TWO_LOGS.replace("talker: VD}", "pty: out/two}"))
    (work / "out" / "two").write_text("in the way\n")
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "emlog2", "dvl")]
    try:
        d = Daemon(work, pty=True)
        own = -1
        try:
            tty.setraw(d.fd)
            for k in range(10):
                os.write(masters[0], VHW[k % 2])
                os.write(masters[1], OTHER_VHW[k % 2])
                d.pump(0.1)
            shared = [line for line in d.lines if b"VHW" in line or b"PEMLS" in line]
            assert any(line.startswith(b"$VWVHW,,T,,M,5.0") for line in shared), shared
            assert not [x for x in shared if b"7.0" in x or b"emlog2" in x], shared
            (work / "out" / "two").unlink()
            wait(lambda: (work / "out" / "two").is_symlink(), "emlog2's pty", OUTPUT_RETRY_S + 3)
            own = os.open(work / "out" / "two", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
            tty.setraw(own)
            got = b""
            for k in range(10):
                os.write(masters[1], OTHER_VHW[k % 2])
                time.sleep(0.1)
                with contextlib.suppress(BlockingIOError):
                    got += os.read(own, 4096)
            assert b"$VWVHW,,T,,M,7.0" in got, got
            assert d.stop() == 0
        finally:
            d.kill()
            if own >= 0:
                os.close(own)
    finally:
        for fd in masters:
            os.close(fd)


def _read_ready(fd: int) -> bytes:
    """What the non-blocking pipe ``fd`` holds now."""
    data = b""
    with contextlib.suppress(BlockingIOError):
        while chunk := os.read(fd, 65536):
            data += chunk
    return data


def test_a_reload_turning_stdout_on_moves_the_log_to_stderr(tmp_path: Path) -> None:
    """The daemon started without ``outputs.stdout`` logs to stdout (a pipe here); a
    SIGHUP into a config with ``outputs.stdout: true`` moves the log to stderr before
    the NMEA comes to stdout, which then carries sentences only (``control_reset`` and
    the rest on stderr); a SIGHUP turning it off moves the log back. The log stayed on
    stdout, its JSON lines between the corrected sentences of the autopilot's stream."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    plain = cfg.read_text()
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    out_r, out_w = os.pipe()
    os.set_blocking(out_r, False)
    try:
        with (work / "stderr.log").open("wb") as err:
            proc = run_daemon(work, stdout=out_w, stderr=err.fileno())
        os.close(out_w)
        with reaped(proc):
            wait(lambda: (work / "run" / "control.sock").exists(), "the control socket")
            cfg.write_text(plain.replace("{pty: out/emlog0}", "{pty: out/emlog0, stdout: true}"))
            proc.send_signal(signal.SIGHUP)
            stderr = work / "stderr.log"
            wait(lambda: b'"reloaded"' in stderr.read_bytes(), "the reload logged on stderr")
            _read_ready(out_r)  # the log's lines before the reload
            for k in range(10):
                os.write(masters[0], VHW[k % 2])
                time.sleep(0.05)
            request(work / "run" / "control.sock", {"cmd": "reset"})
            time.sleep(0.5)
            lines = _read_ready(out_r).splitlines()
            assert [x for x in lines if x.startswith(b"$VWVHW")], lines
            assert all(x.startswith(b"$") for x in lines), lines
            assert b'"control_reset"' in stderr.read_bytes()
            cfg.write_text(plain)
            proc.send_signal(signal.SIGHUP)
            wait(lambda: b'"reloaded"' in _read_ready(out_r), "the log back on stdout")
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(STOP_TIMEOUT_S) == 0
    finally:
        os.close(out_r)
        for fd in masters:
            os.close(fd)
