"""The fifteenth red team's findings against the live daemon, each pinned: what its
signals, ports, sockets and state file may do to it from outside.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon."""

from __future__ import annotations

import contextlib
import itertools
import os
import signal
import subprocess
import sys
import termios
import threading
import time
import tty
from datetime import UTC, datetime
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from drivers.rdi_pd0 import encode_pd0
from emlogd.calfile import loads_state
from emlogd.client import request
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    device_ptys,
    free_port,
    make_work,
    reaped,
    run_daemon,
    saved_calibration,
    wait,
)
from tests.emlogd.daemon.test_redteam_live import VHW

REPO = Path(__file__).resolve().parents[3]


def _caught(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (``SigCgt`` of its status)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    return False


def _held_early(pid: int) -> bool:
    """Whether process ``pid`` catches SIGHUP but not yet SIGTERM, read at one instant:
    SIGHUP held before the daemon's handlers, which install SIGTERM's and SIGHUP's at
    once (a check on the imports instead, numpy not yet mapped, raced them on a loaded
    machine)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            mask = int(line.split()[1], 16)
            return bool(mask >> (signal.SIGHUP - 1) & 1) and not mask >> (signal.SIGTERM - 1) & 1
    return False


def test_a_sighup_and_a_sigusr1_while_it_starts_do_not_end_it(tmp_path: Path) -> None:
    """``python -m emlogd run`` gets a SIGHUP and a SIGUSR1 as soon as it holds them,
    before its handlers are installed (that the hold comes before the command line's
    imports: ``tests/emlogd/test_entry.py``): it starts, answers, reloads its config once (``reloaded``), logs
    the SIGUSR1 (``signal_ignored``) and exits 0 on SIGTERM. The handlers were installed
    once the config was loaded and the daemon built, a second or more after the process
    started: a ``kill -HUP`` or a stray ``kill -USR1`` meanwhile ended it (exit −1,
    −10), a restart under systemd."""
    work = make_work(tmp_path, PD0_CONFIG)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    argv = [sys.executable, "-m", "emlogd", "run", "--config", str(work / "emlogd.yaml")]
    with (work / "daemon.log").open("wb") as out:
        proc = subprocess.Popen(argv, cwd=work, env=env, stdout=out, stderr=out)
        with reaped(proc):
            wait(lambda: proc.poll() is not None or _caught(proc.pid, signal.SIGHUP), "held")
            assert _held_early(proc.pid), "the signals were held only with the daemon's handlers"
            proc.send_signal(signal.SIGHUP)
            proc.send_signal(signal.SIGUSR1)
            sock = str(work / "run" / "control.sock")

            def answers() -> bool:
                assert proc.poll() is None, (work / "daemon.log").read_text()[-2000:]
                try:
                    return request(sock, {"cmd": "status"}, timeout_s=1.0).get("ok") is True
                except DeviceError:
                    return False

            wait(answers, "the control socket answers")
            log = work / "daemon.log"
            wait(lambda: '"reloaded"' in log.read_text(), "the held SIGHUP reloaded")
            wait(lambda: '"SIGUSR1": 1' in log.read_text(), "the held SIGUSR1 logged")
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(20) == 0
    assert log.read_text().count('"event": "reloaded"') == 1


@pytest.mark.parametrize("host", ["0.0.0.0", "[::ffff:127.0.0.1]"])
def test_a_socket_input_on_its_own_tcp_output_by_another_spelling_is_refused(
    tmp_path: Path, host: str
) -> None:
    """A config whose second EMlog is ``socket://0.0.0.0:P`` or
    ``socket://[::ffff:127.0.0.1]:P``, P the port of the daemon's own TCP output on
    127.0.0.1: ``emlogd run`` refuses it, naming the key, exit 1. Both passed the check
    that refuses ``socket://127.0.0.1:P``, and the daemon read its own output as that
    log's: emlog1's first corrected VHW taken as emlog2's reading, then every sentence
    skipped as an echo, the port ``open`` and the real log never read."""
    port = free_port()
    config = PD0_CONFIG.replace(
        "calibration:",
        f'  - {{name: emlog2, url: "socket://{host}:{port}", protocol: nmea0183, role: uut}}\n'
        "calibration:",
    ).replace(
        "outputs: {pty: out/emlog0}", f'outputs: {{pty: out/emlog0, tcp: "127.0.0.1:{port}"}}'
    )
    work = make_work(tmp_path, config)
    with (work / "daemon.log").open("wb") as out, reaped(run_daemon(work, out)) as proc:
        assert proc.wait(20) == 1
    text = (work / "daemon.log").read_text()
    assert "ports[2].url: the same place as outputs.tcp" in text, text
    assert not (work / "run" / "control.sock").exists()


@pytest.mark.parametrize("planted", ["symlink to the state file", "symlink elsewhere", "hard link"])
def test_a_link_planted_at_the_lock_file_costs_no_file(tmp_path: Path, planted: str) -> None:
    """``state/state.yaml.lock`` made, before a start, a symlink to the state file (a good
    calibration, m = 0.1, and no backup yet), a symlink to another file, or a hard link
    of the state file: the daemon starts, loads the calibration (``calibration_loaded``,
    m 0.1), and leaves the state file and the other file byte-identical; a symlink is
    replaced by a lock file of its own holding the pid. The lock's open followed the link
    and wrote the pid over its target: the state file became ``12345``, reported
    damaged, the daemon uncalibrated and the calibration lost for good (any file the
    daemon may write, the same)."""
    work = make_work(tmp_path, PD0_CONFIG)
    state = work / "state" / "state.yaml"
    StateStore(state).save({"emlog1": saved_calibration(0.1)})
    other = work / "other.txt"
    other.write_text("kept\n")
    lock = work / "state" / "state.yaml.lock"
    if planted == "hard link":
        os.link(state, lock)
    else:
        lock.symlink_to("state.yaml" if "state" in planted else "../other.txt")
    before = state.read_bytes()
    d = Daemon(work)
    try:
        assert state.read_bytes() == before and other.read_text() == "kept\n"
        log = d.log_path.read_text()
        assert '"calibration_loaded"' in log and '"m": 0.1' in log, log[-2000:]
        if planted != "hard link":
            assert not lock.is_symlink() and lock.read_text() == f"{d.pid}\n"
        assert d.stop() == 0
    finally:
        d.kill()
    cals, _ = loads_state(state.read_text())
    assert cals["emlog1"].params.m == 0.1 and not cals["emlog1"].reset


SLOW_FSYNC = """\
import os, sys, time
_fsync = os.fsync
def _slow(fd):
    time.sleep(0.3)
    _fsync(fd)
os.fsync = _slow
from emlogd.entry import main
sys.exit(main(sys.argv[1:]))
"""
"""``emlogd`` with every fsync taking 0.3 s more (a slow SD card, a stalled disk)."""


def test_a_slow_disk_does_not_hold_the_outputs(tmp_path: Path) -> None:
    """Every fsync takes 0.3 s (a slow SD card), the EMlog sends a VHW every 0.1 s and
    a ``freeze`` saves the state file: no VHW waits 0.4 s for the next, and the freeze
    is answered that it persisted. The save (the file's fsync, then its directory's)
    ran in the loop's one thread, and every output waited for it (0.6 s here)."""
    work = make_work(tmp_path, PD0_CONFIG)
    StateStore(work / "state" / "state.yaml").save({"emlog1": saved_calibration(0.1)})
    argv = [sys.executable, "-c", SLOW_FSYNC, "run", "--config", "emlogd.yaml"]
    with device_ptys(work / "links", ("emlog1", "dvl")) as (emlog, _):
        d = Daemon(work, pty=True, argv=argv, env=dict(os.environ, PYTHONPATH=str(REPO)))
        try:
            tty.setraw(d.fd)
            sock = str(work / "run" / "control.sock")
            answers: list[dict[str, object]] = []
            freeze = threading.Timer(
                0.5, lambda: answers.append(request(sock, {"cmd": "freeze"}, timeout_s=10))
            )
            freeze.start()
            out: list[float] = []
            end = time.monotonic() + 1.8
            for k in range(10**6):
                if time.monotonic() > end:
                    break
                os.write(emlog, VHW[k % 2])
                d.lines.clear()
                d.pump(0.1)
                out += [time.monotonic()] * sum(b"VHW" in x for x in d.lines)
            freeze.join()
            assert d.stop() == 0
        finally:
            d.kill()
    gaps = [b - a for a, b in itertools.pairwise(out)]
    assert len(out) > 8 and max(gaps) < 0.4, (len(out), max(gaps, default=None))
    assert answers and answers[0]["ok"] and answers[0]["persisted"] is True, answers


def test_a_reader_that_leaves_the_output_pty_cooked_costs_the_others_nothing(
    tmp_path: Path,
) -> None:
    """A second reader of the output pty sets canonical mode, signal characters with
    ``$`` as the interrupt and echo (``stty -F /run/emlogd/emlog0 icanon isig intr '$'``,
    a program that sets its own modes), then closes it. Within the link check
    (``LINK_CHECK_S``, 2 s) the pty is raw again: the first reader, open all along,
    receives whole corrected VHW, and the log says ``pty_modes_restored``. The modes
    are the line discipline's, shared: they stayed, and every ``$`` the daemon wrote
    flushed the line, so the autopilot got no sentence whole for as long as the pty
    lived."""
    work = make_work(tmp_path, PD0_CONFIG)
    with device_ptys(work / "links", ("emlog1", "dvl")) as (emlog, _):
        d = Daemon(work, pty=True)
        try:
            tty.setraw(d.fd)
            fd = os.open(work / "out" / "emlog0", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            attrs = termios.tcgetattr(fd)
            attrs[3] |= termios.ICANON | termios.ISIG | termios.ECHO
            attrs[6][termios.VINTR] = b"$"
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
            os.close(fd)
            wait(lambda: d.events("pty_modes_restored") == 1, "modes restored", 3.0)
            d.pump(0.1)
            d.lines.clear()
            for k in range(5):
                os.write(emlog, VHW[k % 2])
                d.pump(0.1)
            d.pump(0.2)
            whole = [x for x in d.lines if x.startswith(b"$VWVHW,") and b"*" in x]
            assert len(whole) >= 4, d.lines
            assert d.stop() == 0
        finally:
            d.kill()


def test_a_stty_on_the_dvls_device_costs_it_two_seconds(tmp_path: Path) -> None:
    """Another process sets the PD0 DVL's device canonical, with echo, signal characters,
    CR to NL and bit stripping (``stty -F /dev/dvl sane`` by hand, say): within
    ``DEVICE_CHECK_S`` (2 s) the port's modes are those of its open again
    (``port_modes_restored`` in the log) and its ensembles are decoded; the device is
    sent nothing back after that. The modes stayed: canonical mode held the binary
    ensembles back (none decoded, for good), and echo sent everything the DVL said
    back to it (2472 bytes in 2 s, commands to a real DVL)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with device_ptys(work / "links", ("emlog1", "dvl")) as (_, dvl):
        d = Daemon(work)
        try:
            fd = os.open(work / "links" / "dvl", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            attrs = termios.tcgetattr(fd)
            attrs[0] |= termios.ICRNL | termios.ISTRIP
            attrs[3] |= termios.ICANON | termios.ECHO | termios.ISIG
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
            os.close(fd)
            wait(lambda: d.events("port_modes_restored") == 1, "modes restored", 3.0)
            with contextlib.suppress(BlockingIOError):
                os.read(dvl, 65536)  # what was echoed before
            when = datetime(2026, 11, 29, tzinfo=UTC)
            for k in range(10):
                os.write(dvl, encode_pd0(ensemble_number=k, timestamp=when, heading_deg=10.0))
                time.sleep(0.05)
            wait(lambda: _records(d, "dvl") >= 9, "the ensembles decoded", 2.0)
            with pytest.raises(BlockingIOError):
                os.read(dvl, 65536)  # nothing echoed back to the device
            assert d.stop() == 0
        finally:
            d.kill()


def _records(d: Daemon, port: str) -> int:
    ports = d.status()["ports"]
    assert isinstance(ports, dict)
    return int(ports[port]["records"])
