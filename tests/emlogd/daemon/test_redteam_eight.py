"""The eighth red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import functools
import os
import signal
import socket
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest

from emlogd.calfile import loads_state
from emlogd.client import request
from emlogd.daemon.statefile import StateStore
from tests.emlogd.cli.test_common import ROOT, close_std
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    make_work,
    raw_pty,
    reaped,
    saved_calibration,
    wait,
)
from tests.emlogd.daemon.test_redteam_live import VHW, _vhw_within


def _answers(sock: Path) -> bool:
    try:
        return bool(request(sock, {"cmd": "status"}, timeout_s=2.0)["ok"])
    except Exception:
        return False


def test_a_daemon_started_with_its_standard_descriptors_closed_runs(tmp_path: Path) -> None:
    """``emlogd run`` started with descriptors 0, 1 and 2 closed (``>&- 2>&-``, a script
    or a service manager closing them): it starts, answers, reads its EMlog and exits 0
    on SIGTERM, its log going to ``/dev/null``. The log's set-up asked ``sys.stdout``
    (None) whether it was a terminal: ``AttributeError`` before anything was opened,
    exit 1."""
    work = make_work(tmp_path, PD0_CONFIG)
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    argv = [sys.executable, "-m", "emlogd", "run", "--config", str(work / "emlogd.yaml")]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    try:
        proc = subprocess.Popen(argv, cwd=work, preexec_fn=close_std, env=env)
        with reaped(proc):
            sock = work / "run" / "control.sock"
            wait(lambda: proc.poll() is not None or _answers(sock), "the control socket")
            assert proc.poll() is None, proc.returncode
            os.write(masters[0], b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n")
            wait(functools.partial(_emlog_records, sock), "the EMlog's sentence decoded", 10.0)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(20.0) == 0
    finally:
        for fd in masters:
            os.close(fd)


def _emlog_records(sock: Path) -> bool:
    ports = request(sock, {"cmd": "status"})["status"]["ports"]  # type: ignore[index]
    return bool(ports["emlog1"]["records"])


def test_a_notify_socket_nobody_reads_holds_no_output(tmp_path: Path) -> None:
    """``NOTIFY_SOCKET`` a datagram socket whose reader never reads (a stuck or foreign
    receiver), ``WATCHDOG_USEC`` 0.1 s: for 4 s every VHW is out within 0.5 s and every
    status request answered within 1 s. The daemon's notification blocked once the
    socket's queue was full (10 datagrams, about half a second in): no output and no
    answer from then on."""
    work = make_work(tmp_path, PD0_CONFIG)
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(work / "notify.sock"))
    env = {**os.environ, "NOTIFY_SOCKET": str(work / "notify.sock"), "WATCHDOG_USEC": "100000"}
    try:
        d = Daemon(work, pty=True, env=env)
        try:
            tty.setraw(d.fd)
            late, slowest, until = 0, 0.0, time.monotonic() + 4.0
            while time.monotonic() < until:
                sent = time.monotonic()
                os.write(masters[0], VHW[late % 2])
                late += not _vhw_within(d.fd, 0.5)
                t0 = time.monotonic()
                d.status()
                slowest = max(slowest, time.monotonic() - t0)
                time.sleep(max(sent + 0.1 - time.monotonic(), 0.0))
            assert late == 0 and slowest < 1.0, (late, slowest)
            assert d.stop() == 0
        finally:
            d.kill()
    finally:
        notify.close()
        for fd in masters:
            os.close(fd)


def _saved_m(path: Path) -> float | None:
    """EMlog1's scale in the state file at ``path`` (None: no file)."""
    if not path.exists():
        return None
    return float(loads_state(path.read_text())[0]["emlog1"].params.m)


def test_a_state_file_removed_or_replaced_under_the_daemon_is_written_again(
    tmp_path: Path,
) -> None:
    """The running daemon's state file removed (a clean-up, an operator), then replaced by
    another process's (another calibration, m = 0.3): the next ``freeze`` writes the
    daemon's calibration (m = 0.1) again, and so does the stop. A save whose records had
    not changed was skipped whatever the file had become: the file stayed removed, or
    another's, and the next start loaded nothing, or that one."""
    work = make_work(tmp_path, PD0_CONFIG)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": saved_calibration(0.1)})
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    try:
        d = Daemon(work)
        try:
            assert d.ask(cmd="freeze")["ok"] is True
            assert _saved_m(store.path) == pytest.approx(0.1)
            store.path.unlink()
            assert d.ask(cmd="freeze")["ok"] is True
            assert _saved_m(store.path) == pytest.approx(0.1)
            other = StateStore(work / "other.yaml")
            other.save({"emlog1": saved_calibration(0.3)})
            other.path.replace(store.path)
            assert d.stop() == 0
            assert _saved_m(store.path) == pytest.approx(0.1)
        finally:
            d.kill()
    finally:
        for fd in masters:
            os.close(fd)
