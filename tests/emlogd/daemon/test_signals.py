"""The daemon's signals (:mod:`emlogd.daemon.signals`): a signal it has no use for is
counted and logged, never the end of the daemon."""

from __future__ import annotations

import os
import pty
import select
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from drivers.errors import DeviceError
from emlogd.client import request
from emlogd.daemon.signals import UNUSED_LOG_S, UNUSED_SIGNALS, Unused, drain, install, restore
from tests.emlogd.cli.test_common import ROOT
from tests.emlogd.daemon.harness import PD0_CONFIG, Daemon, make_work, raw_pty, wait

ENDING_SIGNALS = (
    signal.SIGRTMAX,
    signal.SIGRTMIN + 3,
    signal.SIGRTMIN,
    signal.SIGSTKFLT,
    signal.SIGIO,
    signal.SIGXFSZ,
    signal.SIGXCPU,
    signal.SIGPWR,
    signal.SIGPROF,
    signal.SIGVTALRM,
    signal.SIGALRM,
    signal.SIGUSR2,
    signal.SIGUSR1,
)
"""Signals whose default action ends a process, none raised by a fault of the daemon's own."""


class _Log:
    def __init__(self) -> None:
        self.lines: list[tuple[str, dict[str, Any]]] = []

    def warning(self, event: str, **kw: Any) -> None:
        self.lines.append((event, kw))


def test_unused_signals_are_counted_and_logged_once_per_interval() -> None:
    """Each unused signal counted by name; one ``signal_ignored`` line per
    ``UNUSED_LOG_S`` with the counts since the line before, none when none came."""
    unused, log = Unused(), _Log()
    for _ in range(3):
        unused.handler(signal.SIGUSR1, None)
    unused.handler(signal.SIGUSR2, None)
    unused.log(log, 100.0)
    unused.handler(signal.SIGUSR1, None)
    unused.log(log, 100.0 + UNUSED_LOG_S / 2)  # too soon: kept for the next line
    unused.log(log, 100.0 + UNUSED_LOG_S)
    unused.log(log, 100.0 + 3 * UNUSED_LOG_S)  # nothing new: no line
    assert [kw["signals"] for _, kw in log.lines] == [{"SIGUSR1": 3, "SIGUSR2": 1}, {"SIGUSR1": 1}]
    assert {e for e, _ in log.lines} == {"signal_ignored"}
    assert unused.total == 5


def test_install_handles_the_unused_signals_and_restore_puts_back() -> None:
    """Installed, every unused signal (SIGUSR1, SIGALRM, SIGPWR, SIGRTMIN+3…) is counted in
    this process (its default action would end it) and wakes the loop's pipe; restored,
    the handlers before are back."""
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, *UNUSED_SIGNALS)}
    r, w = os.pipe()
    os.set_blocking(r, False)
    os.set_blocking(w, False)
    unused = Unused()
    stops: list[int] = []
    old = install(lambda s, f: stops.append(s), lambda s, f: None, unused, w)
    try:
        for sig in UNUSED_SIGNALS:
            os.kill(os.getpid(), sig)
        assert unused.total == len(UNUSED_SIGNALS)
        assert unused.pending["SIGALRM"] == unused.pending["SIGRTMIN+3"] == 1
        assert os.read(r, 16)  # the loop would wake
        os.write(w, b"x" * 100)
        drain(r)
        assert not stops
    finally:
        restore(old)
        os.close(r)
        os.close(w)
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_unused_signals_do_not_end_the_live_daemon(tmp_path: Path) -> None:
    """Every signal of ``ENDING_SIGNALS`` (the timers', SIGPWR, SIGXCPU, SIGXFSZ, SIGIO,
    real-time ones...), five times each, to the running daemon: it answers, logs
    ``signal_ignored`` with their counts, and SIGTERM still persists and exits 0.
    Left to its default action, each ended it at once (killed by the signal: no
    calibration persisted, the control socket and the pty link left behind)."""
    work = make_work(tmp_path, PD0_CONFIG)
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    try:
        d = Daemon(work)
        try:
            for _ in range(5):
                for sig in ENDING_SIGNALS:
                    d.send_signal(sig)
            wait(lambda: d.events("signal_ignored") > 0, "a signal_ignored line", 10.0)
            assert d.running
            assert d.status()["ports"]
            text = d.log_path.read_text()
            assert '"SIGUSR1": ' in text and '"SIGUSR2": ' in text  # (a signal pending coalesces)
            assert d.stop() == 0
            assert d.events("calibration_persisted") == 1
            assert not (work / "run" / "control.sock").exists()
        finally:
            d.kill()
    finally:
        for fd in masters:
            os.close(fd)


_BACKGROUND = """\
import os, subprocess, sys, termios
os.setsid()
fd = os.open(sys.argv[1], os.O_RDWR)  # the session's controlling terminal
attrs = termios.tcgetattr(fd)
attrs[3] |= termios.TOSTOP
termios.tcsetattr(fd, termios.TCSANOW, attrs)
p = subprocess.Popen(sys.argv[2:], stdin=subprocess.DEVNULL, stdout=fd, stderr=fd, process_group=0)
print(p.pid, flush=True)
p.wait()
"""
"""Run argv[2:] in a background process group of a new session whose terminal is
argv[1], with ``stty tostop``, its output on the terminal (``emlogd run &``)."""


def test_a_daemon_in_the_background_of_a_tostop_terminal_runs(tmp_path: Path) -> None:
    """``emlogd run &`` in a terminal with ``stty tostop``, its log on the terminal: it
    runs, answers and logs there (its lines reach the terminal). SIGTTOU stopped it at
    its first log line (state ``T``): no output, no answer, until a SIGCONT."""
    work = make_work(tmp_path, PD0_CONFIG.replace("log_format: json", "log_format: console"))
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    term, slave = pty.openpty()
    name = os.ttyname(slave)
    os.close(slave)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    argv = [sys.executable, "-m", "emlogd", "run", "--config", str(work / "emlogd.yaml")]
    shell = subprocess.Popen(
        [sys.executable, "-c", _BACKGROUND, name, *argv], cwd=work, stdout=subprocess.PIPE, env=env
    )
    pid = -1
    try:
        assert shell.stdout is not None
        pid = int(shell.stdout.readline())
        wait(lambda: _answers(work / "run" / "control.sock"), "the daemon's answer", 10.0)
        said = b""
        while select.select([term], [], [], 0.2)[0]:
            said += os.read(term, 65536)
        assert b"ready" in said
        os.kill(pid, signal.SIGTERM)
        assert shell.wait(timeout=10) == 0
    finally:
        if shell.poll() is None:
            os.kill(pid, signal.SIGKILL)
            os.kill(pid, signal.SIGCONT)
            shell.wait()
        for fd in (term, *masters):
            os.close(fd)


def _answers(sock: Path) -> bool:
    try:
        return bool(request(sock, {"cmd": "status"}, timeout_s=1.0)["ok"])
    except DeviceError:
        return False
