"""The daemon harness of these tests: ``emlogd run`` as a subprocess in a work directory
(its config, links, output pty, state and control socket beneath it), read as it goes,
with bounded waits. The fixtures that use it are in this folder's ``conftest.py``."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import time
import tty
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from calib.estimate import Estimate
from calib.models import Params
from emlogd.launch import STOP_TIMEOUT_S, DaemonProcess
from emlogd.pipeline.calibration import Calibration

SPEED = 20.0
"""How much faster than real time the fake sensors serve their capture."""

PORTS = ("emlog1", "emlog2", "dvl")
"""The sensors of the configs here: two EMlogs and a DVL (PD6)."""

OUTPUTS = """\
outputs: {pty: out/emlog0, tcp: "127.0.0.1:{tcp}", status_sentence_interval_s: 0.2}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
status_log_interval_s: 1
"""
"""The outputs, state, control socket and logging of the configs here (``{tcp}``: see
:func:`make_work`)."""


PD0_CONFIG = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}
  - {name: dvl, url: links/dvl, protocol: pd0, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.2}
outputs: {pty: out/emlog0}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
"""
"""An EMlog and a PD0 DVL, on ptys the test or benchmark serves itself (:func:`raw_pty`)."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def saved_calibration(m: float = 0.1, *, n: int = 100, lag_s: float = 3.2) -> Calibration:
    """A calibration as the state file holds one: EMlog1's EM3 scale ``m`` against the
    DVL's bottom track, learnt from ``n`` samples at lag ``lag_s``."""
    return Calibration(
        estimate=Estimate(Params("EM3", m=m, b_mps=0.05), {"m": 0.001, "b": 0.002}),
        uut="emlog1",
        lag_s=lag_s,
        covariance=((1e-4, 0.0, 0.0), (0.0, 1e-6, -1e-7), (0.0, -1e-7, 4e-6)),
        t=1.75e9,
        n_samples=n,
        reference={"port": "dvl", "field": "bottom"},
        nis_mean=1.01,
    )


def make_work(tmp_path: Path, config: str) -> Path:
    """``tmp_path`` as a daemon's work directory: ``links``, ``out``, ``state`` and ``run``,
    and ``emlogd.yaml`` from ``config`` with ``{tcp}`` a free TCP port."""
    for sub in ("links", "out", "state", "run"):
        (tmp_path / sub).mkdir()
    (tmp_path / "emlogd.yaml").write_text(config.replace("{tcp}", str(free_port())))
    return tmp_path


def run_daemon(
    work: Path, stdout: int | IO[bytes], stderr: int | IO[bytes] | None = None
) -> subprocess.Popen[bytes]:
    """``emlogd run`` in ``work`` as a bare subprocess (not a :class:`Daemon`: no log file,
    no wait for the control socket), its stdout on ``stdout`` and its stderr on ``stderr``
    (default: the same); end it in :func:`reaped`."""
    argv = [sys.executable, "-m", "emlogd", "run", "--config", str(work / "emlogd.yaml")]
    return subprocess.Popen(
        argv, cwd=work, stdout=stdout, stderr=stdout if stderr is None else stderr
    )


@contextmanager
def reaped(proc: subprocess.Popen[bytes]) -> Iterator[subprocess.Popen[bytes]]:
    """``proc``, killed at the end of the block if it still runs."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def tcp_port(work: Path) -> int:
    """The TCP output's port in ``work``'s config."""
    return int((work / "emlogd.yaml").read_text().split('tcp: "127.0.0.1:')[1].split('"')[0])


def raw_pty(link: Path) -> int:
    """A pty in raw mode whose slave is published at ``link`` (a serial device the test
    or benchmark serves itself); its master, non-blocking."""
    master, slave = os.openpty()
    for fd in (master, slave):
        tty.setraw(fd)
    os.set_blocking(master, False)
    link.symlink_to(os.ttyname(slave))
    return master


@contextmanager
def device_ptys(links: Path, names: tuple[str, ...]) -> Iterator[list[int]]:
    """Raw ptys published as ``links/NAME`` for each name (:func:`raw_pty`), their masters
    closed on the way out."""
    masters: list[int] = []
    try:
        masters += [raw_pty(links / name) for name in names]
        yield masters
    finally:
        for fd in masters:
            os.close(fd)


def wait(cond: Callable[[], bool], what: str, timeout_s: float = 20.0) -> None:
    """Poll ``cond`` every 50 ms until it holds; fail with ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


class Daemon(DaemonProcess):
    """``emlogd run --config emlogd.yaml`` in ``work``, started when constructed (the
    control socket answers), with what the tests read.

    Args:
        work: the work directory (:func:`make_work`).
        pty: read the shared output pty ``out/emlog0`` as it goes (:meth:`pump`,
            :attr:`lines`).
        argv: the command instead of ``emlogd run`` (a daemon with an injected clock).
        env: the environment instead of this process's.
    """

    def __init__(
        self,
        work: Path,
        *,
        pty: bool = False,
        argv: list[str] | None = None,
        env: dict[str, str] | None = None,
    ) -> None:
        self.fd = -1  # before the harness starts: a failed start calls kill()
        super().__init__(
            "emlogd.yaml", socket="run/control.sock", log="daemon.log", cwd=work, argv=argv, env=env
        )
        self.buf = b""
        self.lines: list[bytes] = []
        if not pty:
            return
        try:  # the control socket answers: the output pty exists
            self.fd = os.open(work / "out" / "emlog0", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        except BaseException:
            self.kill()
            raise

    def pump(self, seconds: float) -> None:
        """Read the output pty for ``seconds``, its whole lines into :attr:`lines`."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            r, _, _ = select.select([self.fd], [], [], 0.05)
            if r:
                try:
                    self.buf += os.read(self.fd, 65536)
                except (BlockingIOError, OSError):
                    continue
                *done, self.buf = self.buf.split(b"\r\n")
                self.lines.extend(done)

    def uut(self, name: str) -> dict[str, object]:
        """One UUT's status."""
        uuts = self.status()["uuts"]
        assert isinstance(uuts, dict)
        u = uuts[name]
        assert isinstance(u, dict)
        return u

    def events(self, name: str) -> int:
        """How many ``name`` events the log holds."""
        return self.log_path.read_text().count(f'"event": "{name}"')

    def _close_pty(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = STOP_TIMEOUT_S) -> int:
        self._close_pty()
        return super().stop(sig, timeout_s)

    def kill(self) -> int:
        self._close_pty()
        return super().kill()
