"""The daemon as a subprocess, and fake sensors to feed it: what the demo, the tests
and the benchmarks run.

:class:`DaemonProcess` starts ``python -m emlogd run --config CFG`` (or any argv) with
its output appended to a log file, waits until its control socket answers a status
request, and fails with the tail of the log when the process exits or a deadline
passes first. :func:`fake_sensors` serves ports of a capture on virtual serial ports
at ``links/<port>``, on the capture's one clock, for as long as a ``with`` block runs.

This module imports neither :mod:`emlogd.daemon` nor :mod:`emlogd.offline`: it talks
to the daemon through :mod:`emlogd.client`, so the demo (offline) may use it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO

from drivers.errors import DeviceError, EmlogdError
from drivers.io.closing import Closing
from drivers.io.fake import FakeCapture
from emlogd.client import request

START_TIMEOUT_S = 30.0
"""How long :class:`DaemonProcess` waits by default for the control socket to answer."""

STOP_TIMEOUT_S = 20.0
"""How long :meth:`DaemonProcess.stop` waits by default for the daemon to exit."""

TAIL_LINES = 20
"""Lines of the log quoted in a :class:`LaunchError`."""


class LaunchError(EmlogdError):
    """The daemon did not start (it exited, or its control socket never answered) or did
    not stop; the message ends with the tail of its log (also in :attr:`tail`)."""

    def __init__(self, message: str, tail: str = "") -> None:
        super().__init__(f"{message}\n{tail}" if tail else message)
        self.tail = tail


class DaemonProcess(Closing):
    """``emlogd run`` as a subprocess, until :meth:`stop`, :meth:`kill` or the end of a
    ``with`` block (which stops it with SIGTERM, then SIGKILL if it hangs).

    Args:
        config: the config file, passed as ``run --config CONFIG``.
        socket: the control socket the config names.
        log: file the daemon's stdout and stderr are appended to.
        err_log: when given, stderr goes to this file instead.
        cwd: the daemon's working directory; relative ``config``, ``socket``, ``log``
            and ``err_log`` are taken from it, as the daemon takes the config's paths.
        argv: the whole command instead of ``python -m emlogd run --config CONFIG``.
        env: variables added to (or replacing) the current environment.
        python: the interpreter of the default command.
        wait: wait for the control socket (:meth:`wait_ready`) before returning.
        timeout_s: how long to wait for it.

    Raises:
        LaunchError: with ``wait``, the daemon exited or its socket did not answer
            within ``timeout_s`` (the process is killed first).
        OSError: the log cannot be opened or the command cannot be run.
    """

    def __init__(
        self,
        config: str | Path,
        *,
        socket: str | Path,
        log: str | Path,
        err_log: str | Path | None = None,
        cwd: str | Path | None = None,
        argv: Sequence[str] | None = None,
        env: Mapping[str, str] | None = None,
        python: str = sys.executable,
        wait: bool = True,
        timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        base = Path(cwd) if cwd is not None else Path.cwd()
        self.cwd = base
        self.config = base / config
        self.socket = base / socket
        self.log_path = base / log
        self.err_path = base / err_log if err_log is not None else None
        self.argv = (
            list(argv)
            if argv is not None
            else [python, "-m", "emlogd", "run", "--config", str(self.config)]
        )
        self._files: list[IO[bytes]] = []
        self.log = self._open(self.log_path)
        self._log_start = self.log.tell()  # the tail quoted is this run's
        err: IO[bytes] | int = subprocess.STDOUT
        if self.err_path is not None:
            err = self._open(self.err_path)
        try:
            self.proc = subprocess.Popen(
                self.argv,
                stdout=self.log,
                stderr=err,
                cwd=base,
                env={**os.environ, **env} if env is not None else None,
            )
        except BaseException:
            self._close_logs()
            raise
        if wait:
            try:
                self.wait_ready(timeout_s)
            except BaseException:
                self.kill()
                raise

    def _open(self, path: Path) -> IO[bytes]:
        f = open(path, "ab")  # noqa: SIM115  # closed by stop/kill
        self._files.append(f)
        return f

    def _close_logs(self) -> None:
        for f in self._files:
            f.close()

    # -- the process ---------------------------------------------------------------

    @property
    def pid(self) -> int:
        """The daemon's process id."""
        return self.proc.pid

    @property
    def returncode(self) -> int | None:
        """The exit code, None while it runs (polled)."""
        return self.proc.poll()

    @property
    def running(self) -> bool:
        """Whether the process has not exited yet."""
        return self.proc.poll() is None

    def send_signal(self, sig: int) -> None:
        """Send ``sig`` (SIGHUP: reload) if the process still runs."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)

    def tail(self, lines: int = TAIL_LINES) -> str:
        """The last ``lines`` lines this run wrote to its log (and its error log)."""
        parts = []
        for path, start in ((self.log_path, self._log_start), (self.err_path, 0)):
            if path is None:
                continue
            with contextlib.suppress(OSError), open(path, "rb") as f:
                f.seek(start)
                text = f.read().decode("utf-8", "replace")
                parts.append("\n".join(text.splitlines()[-lines:]))
        return "\n".join(p for p in parts if p)

    # -- the control socket --------------------------------------------------------

    def answers(self) -> bool:
        """Whether the control socket answers a status request now."""
        try:
            return request(self.socket, {"cmd": "status"}, timeout_s=1.0).get("ok") is True
        except DeviceError:
            return False

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Wait until the control socket answers a status request.

        Raises:
            LaunchError: the process exited first, or ``timeout_s`` passed.
        """
        deadline = time.monotonic() + timeout_s
        while not self.answers():
            rc = self.proc.poll()
            if rc is not None:
                raise LaunchError(
                    f"the daemon exited with {rc} before its control socket {self.socket} "
                    f"answered; the end of {self.log_path}:",
                    self.tail(),
                )
            if time.monotonic() > deadline:
                raise LaunchError(
                    f"the daemon's control socket {self.socket} did not answer within "
                    f"{timeout_s:g} s; the end of {self.log_path}:",
                    self.tail(),
                )
            time.sleep(0.05)

    def ask(self, **req: object) -> dict[str, object]:
        """Send one request (``ask(cmd="freeze", port="emlog1")``) and return the answer.

        Raises:
            DeviceError: the daemon is not reachable or answered garbage.
        """
        return request(self.socket, dict(req))

    def status(self) -> dict[str, object]:
        """The ``status`` part of the daemon's answer to a status request.

        Raises:
            DeviceError: the daemon is not reachable, refused, or answered garbage.
        """
        resp = self.ask(cmd="status")
        st = resp.get("status")
        if resp.get("ok") is not True or not isinstance(st, dict):
            raise DeviceError(f"{self.socket}: status refused: {resp.get('error', resp)}")
        return st

    # -- the end -------------------------------------------------------------------

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = STOP_TIMEOUT_S) -> int:
        """Send ``sig`` (if it still runs), wait for the exit and return its code.

        Raises:
            LaunchError: it did not exit within ``timeout_s`` (it is killed).
        """
        self.send_signal(sig)
        try:
            rc = self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            raise LaunchError(
                f"the daemon did not exit within {timeout_s:g} s of signal {sig}; killed; "
                f"the end of {self.log_path}:",
                self.tail(),
            ) from None
        self._close_logs()
        return rc

    def kill(self) -> int:
        """SIGKILL (if it still runs: nothing more is written) and return the exit code."""
        if self.proc.poll() is None:
            self.proc.kill()
        rc = self.proc.wait()
        self._close_logs()
        return rc

    def close(self) -> None:
        """:meth:`stop`, what leaving a ``with`` block does: a daemon that had to be killed
        raises nothing (its exit code tells)."""
        with contextlib.suppress(LaunchError):
            self.stop()


@contextlib.contextmanager
def fake_sensors(
    capture: str | Path,
    links: str | Path,
    ports: Sequence[str],
    *,
    speed: float | None,
    loop: bool = False,
) -> Iterator[FakeCapture]:
    """Serve ``ports`` of ``capture`` at ``links/<port>`` on one clock, ``speed`` times
    real time (None: as fast as read), while the block runs; stopped and joined after.

    Raises:
        ValueError: a port the capture lacks, or a non-positive speed.
        DeviceError: a virtual port cannot be created.
    """
    fake = FakeCapture(capture, {p: Path(links) / p for p in ports}, speed=speed, loop=loop)
    fake.start()
    try:
        yield fake
    finally:
        fake.stop()
        fake.join(5)
