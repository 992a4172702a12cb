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
import signal
import struct
import subprocess
import sys
import termios
import time
from collections.abc import Iterator
from pathlib import Path

from emlogd.launch import STOP_TIMEOUT_S
from tests.emlogd.daemon.harness import make_work, wait
from tests.emlogd.daemon.test_redteam import CONFIG, F_SETPIPE_SZ, _answers


def _run(work: Path, out: int) -> subprocess.Popen[bytes]:
    """``emlogd run`` in ``work``, its stdout and stderr to the descriptor ``out``."""
    argv = [sys.executable, "-m", "emlogd", "run", "--config", str(work / "emlogd.yaml")]
    return subprocess.Popen(argv, cwd=work, stdout=out, stderr=out)


def _stop(proc: subprocess.Popen[bytes]) -> int:
    proc.send_signal(signal.SIGTERM)
    return proc.wait(STOP_TIMEOUT_S)


@contextlib.contextmanager
def _reaped(proc: subprocess.Popen[bytes]) -> Iterator[subprocess.Popen[bytes]]:
    """``proc``, killed at the end of the block if it still runs."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


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
        with _reaped(_run(work, w)) as proc:
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
            data = b""
            with contextlib.suppress(BlockingIOError):
                while chunk := os.read(r, 65536):
                    data += chunk
            lines = data.decode().splitlines()
            assert lines and all(json.loads(x)["event"] for x in lines), lines[-1]
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)
