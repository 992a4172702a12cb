"""The seventh red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from emlogd.calfile import loads_state
from emlogd.client import request
from emlogd.daemon.control import PATH_CHECK_S
from emlogd.daemon.sinks import LINK_CHECK_S
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import PD0_CONFIG, Daemon, free_port, make_work, wait
from tests.emlogd.daemon.test_redteam import _cal, _log, _work
from tests.emlogd.daemon.test_redteam_live import VHW, _flood, _pd0_daemon, _vhw_within

ECHO = b"$AAXXX,echo*00\r\n" * 256
"""What the reader of the output pty writes back (an autopilot echoing, a program
holding the pty open for writing): 4 KiB a write."""


def test_a_reader_writing_into_the_output_pty_costs_itself(tmp_path: Path) -> None:
    """A process holding the output pty open writes into it as fast as it takes it,
    while the EMlog sends a VHW every 0.1 s: nine in ten corrected VHW leave within
    50 ms of their reading and a status request is answered within 0.5 s. What a reader
    writes is drained and discarded, a bounded amount at each write: the drain read
    until the pty was empty, which a writer as fast as the daemon's reads never let
    it be (a write held 75 ms in the median, 250 ms at worst)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with _pd0_daemon(work) as (d, emlog):
        echo = os.open(work / "out" / "emlog0", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            until = time.monotonic() + 4.0
            flood = _flood(echo, ECHO, 4.0)
            late: list[bool] = []
            slowest = 0.0
            while time.monotonic() < until:
                sent = time.monotonic()
                os.write(emlog, VHW[len(late) % 2])
                late.append(not _vhw_within(d.fd, 0.05))
                if len(late) % 10 == 0:
                    t0 = time.monotonic()
                    d.status()
                    slowest = max(slowest, time.monotonic() - t0)
                time.sleep(max(sent + 0.1 - time.monotonic(), 0.0))
            flood.wait(10.0)
        finally:
            os.close(echo)
        assert sum(late) <= len(late) // 10, f"{sum(late)} of {len(late)} late"
        assert slowest < 0.5, slowest
        assert d.stop() == 0


def _chattr(flag: str, path: Path) -> bool:
    """``chattr flag path``; whether it took (root, a file system with the flag)."""
    try:
        done = subprocess.run(["chattr", flag, str(path)], capture_output=True, check=False)
    except OSError:
        return False
    return done.returncode == 0


@pytest.mark.root
def test_an_immutable_backup_costs_the_backup_alone(tmp_path: Path) -> None:
    """The running daemon's ``.bak`` made immutable (``chattr +i``: its rename fails
    with ``EPERM`` even for root, as another user's file in a sticky directory does for
    anyone else), then a ``reset``: answered ok, the state file holds it,
    ``state_errors`` 0, the log says ``state_backup_failed``. Every save failed (the
    reset answered that the state file was not written): what was learnt or reset from
    then on was lost at the next restart."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal()})
    store.save({"emlog1": _cal(0.11)})
    if not _chattr("+i", store.backup):
        pytest.skip("chattr +i needs root and a file system with the flag")
    try:
        d = Daemon(work)
        try:
            assert d.ask(cmd="reset", port="emlog1").get("ok") is True, d.tail()
            assert loads_state(store.path.read_text())[0]["emlog1"].reset
            assert d.ask(cmd="status")["state_errors"] == 0
            failed = [e for e in _log(d) if e.get("event") == "state_backup_failed"]
            assert failed and str(store.backup) in str(failed[0]["why"]), failed
            assert d.stop() == 0
        finally:
            d.kill()
    finally:
        _chattr("-i", store.backup)


def _answers(sock: Path) -> bool:
    try:
        return request(sock, {"cmd": "status"}, timeout_s=1.0).get("ok") is True
    except DeviceError:
        return False


def test_a_removed_control_socket_file_is_made_again(tmp_path: Path) -> None:
    """The running daemon's control socket file removed (by hand, a clean-up of the run
    directory): ``emlogd status`` answers again within ``PATH_CHECK_S`` and a second,
    the log says ``control_socket_restored``; SIGTERM exits 0 and removes it. The
    listening socket behind the removed name took no connection: the operators were
    locked out until a restart."""
    work = _work(tmp_path)
    sock = work / "run" / "control.sock"
    d = Daemon(work)
    try:
        sock.unlink()
        assert not _answers(sock)
        wait(lambda: _answers(sock), "the control socket made again", PATH_CHECK_S + 1.0)
        assert d.events("control_socket_restored") == 1
        assert d.stop() == 0
        assert not sock.exists()
    finally:
        d.kill()


def test_a_removed_output_pty_link_is_published_again(tmp_path: Path) -> None:
    """The running daemon's output pty link removed: within ``LINK_CHECK_S`` and a second
    it names the pty again, and a reader opening it then (an autopilot after its own
    restart) reads the corrected VHW; the log says ``pty_link_restored``. The reader
    found nothing at the link until the daemon's restart."""
    work = make_work(tmp_path, PD0_CONFIG)
    link = work / "out" / "emlog0"
    with _pd0_daemon(work) as (d, emlog):
        link.unlink()
        wait(link.is_symlink, "the pty link published again", LINK_CHECK_S + 1.0)
        fd = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            got = False
            for k in range(20):
                os.write(emlog, VHW[k % 2])
                if _vhw_within(fd, 0.1):
                    got = True
                    break
            assert got, "no VHW through the link published again"
        finally:
            os.close(fd)
        assert d.events("pty_link_restored") == 1
        assert d.stop() == 0


def test_a_reload_into_a_logs_own_tcp_output_without_a_shared_one(tmp_path: Path) -> None:
    """SIGHUP into a config giving the EMlog a TCP output of its own, with no shared TCP
    output (valid): reloaded, the port takes a client, SIGTERM exits 0. Building the
    outputs raised ``UnboundLocalError``: the daemon ended (``internal error``), and a
    start with that config never got further."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    port = free_port()
    with _pd0_daemon(work) as (d, _):
        cfg.write_text(cfg.read_text().replace("lag: 0.2}", f'lag: 0.2, tcp: "127.0.0.1:{port}"}}'))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") == 1, "the reload", 10.0)
        socket.create_connection(("127.0.0.1", port), 2.0).close()
        assert d.stop() == 0
