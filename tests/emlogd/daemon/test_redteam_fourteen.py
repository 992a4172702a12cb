"""The fourteenth red team's findings against the live daemon, each pinned: what its
ports, sockets, outputs, state file and config may do to it from outside.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import stat
import subprocess
import sys
import time
import tty
from pathlib import Path
from typing import cast

import pytest

from emlogd.calfile import loads_state
from emlogd.client import request
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    device_ptys,
    free_port,
    make_work,
    raw_pty,
    saved_calibration,
    wait,
)
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon
from tests.emlogd.daemon.test_redteam_thirteen import OTHER_VHW


def _port(status: dict[str, object], name: str) -> dict[str, object]:
    """One port's entry of a ``status`` answer."""
    inner = status["status"]
    assert isinstance(inner, dict)
    port = inner["ports"][name]
    assert isinstance(port, dict)
    return port


def test_an_open_port_that_never_sent_a_byte_is_never_heard(tmp_path: Path) -> None:
    """The DVL's pty is open and silent, the EMlog sends: the DVL's ``state`` is ``never
    heard`` (its ``last_rx`` None), the EMlog's ``open``. It showed ``open``, as healthy
    as a port whose data flow, for as long as the daemon ran."""
    work = make_work(tmp_path, PD0_CONFIG)
    with _pd0_daemon(work) as (d, emlog):
        for k in range(5):
            os.write(emlog, VHW[k % 2])
            time.sleep(0.05)
        d.pump(0.5)
        status = d.ask(cmd="status")
        dvl, log = _port(status, "dvl"), _port(status, "emlog1")
        assert dvl["state"] == "never heard" and dvl["last_rx"] is None, dvl
        assert dvl["stale"] is False and dvl["open"] is True, dvl
        assert log["state"] == "open", log
        assert d.stop() == 0


def test_a_state_file_that_is_a_symlink_is_written_through_its_link(tmp_path: Path) -> None:
    """``state/state.yaml`` a symlink to ``keep/emlog.yaml`` (a state kept on another
    volume) holding EMlog1's calibration: a ``reset`` saves through the link — the link
    stays a link, its target holds the reset and its ``.bak`` the calibration before it,
    no temporary file is left in either directory — and the lock is taken next to the
    real path. The save renamed a regular file over the link: the target kept the old
    calibration, which the link's next reader (a restart with the link put back, a
    backup of the volume) took for the current one."""
    work = make_work(tmp_path, PD0_CONFIG)
    keep = work / "keep"
    keep.mkdir()
    target = keep / "emlog.yaml"
    StateStore(target).save({"emlog1": saved_calibration(0.1)})
    link = work / "state" / "state.yaml"
    link.symlink_to(Path("..") / "keep" / "emlog.yaml")
    with _pd0_daemon(work) as (d, _):
        assert (keep / "emlog.yaml.lock").exists()
        assert not (work / "state" / "state.yaml.lock").exists()
        assert d.ask(cmd="reset").get("ok") is True, d.tail()
        assert link.is_symlink() and link.resolve() == target.resolve()
        cals, _ = loads_state(target.read_text())
        assert cals["emlog1"].reset, target.read_text()
        old, _ = loads_state((keep / "emlog.yaml.bak").read_text())
        assert not old["emlog1"].reset and old["emlog1"].params.m == 0.1
        assert d.stop() == 0
    assert link.is_symlink()
    leftovers = [p.name for p in [*keep.iterdir(), *link.parent.iterdir()] if ".tmp" in p.name]
    assert not leftovers, leftovers


def _netns() -> bool:
    """Whether ``unshare -rn`` can run a command in a network namespace of its own."""
    try:
        return subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode == 0
    except OSError:
        return False


@pytest.mark.skipif(not _netns(), reason="needs unshare -rn (a network namespace)")
def test_a_udp_output_with_no_route_is_failing_and_the_pty_goes_on(tmp_path: Path) -> None:
    """The daemon in a network namespace with no interface up (``unshare -rn``), a UDP
    output to 192.0.2.9 beside the pty: every ``sendto`` fails with ``ENETUNREACH``. The
    corrected VHW go out on the pty all the same; the UDP output's ``state`` is ``failing:
    ENETUNREACH: Network is unreachable (N sends in a row)``, its ``errors`` count them, and
    the log says ``output_failing`` once. The status said ``open``: the only sign of an
    autopilot's network output sending nothing was a counter."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    cfg.write_text(cfg.read_text().replace("{pty: out/emlog0}", UDP_BESIDE_PTY))
    argv = ["unshare", "-rn", sys.executable, "-m", "emlogd", "run", "--config", str(cfg)]
    with device_ptys(work / "links", ("emlog1", "dvl")) as masters:
        d = Daemon(work, pty=True, argv=argv)
        try:
            tty.setraw(d.fd)
            for k in range(10):
                os.write(masters[0], VHW[k % 2])
                d.pump(0.1)
            assert sum(line.startswith(b"$VWVHW") for line in d.lines) >= 5, d.lines
            udp = d.ask(cmd="status")["outputs"]["udp:192.0.2.9:10110"]  # type: ignore[index]
            state = str(udp["state"])
            assert state.startswith("failing: ENETUNREACH: Network is unreachable ("), udp
            assert udp["errors"] >= 5 and udp["sentences"] == 0, udp
            assert d.events("output_failing") == 1, d.tail()
            assert d.stop() == 0
        finally:
            d.kill()


UDP_BESIDE_PTY = '{pty: out/emlog0, udp: "192.0.2.9:10110"}'
"""The outputs of that test: the pty and a UDP destination with no route to it."""


def test_a_reload_swapping_the_control_and_status_sockets_swaps_them(tmp_path: Path) -> None:
    """SIGHUP into a config whose ``control_socket`` is the old ``status_socket``'s path
    and the other way round: afterwards the control socket's path takes ``reset`` and the
    status socket's path refuses it (read-only, mode 0666 against 0660), both answer, and
    no ``reload_control_failed`` is logged. Each new socket found its path held by the
    daemon's own other socket, taken for another instance (``in use by another process``):
    both kept at their old paths, the read-only socket where the config named the control
    socket."""
    work = make_work(tmp_path, PD0_CONFIG + "status_socket: run/status.sock\n")
    cfg = work / "emlogd.yaml"
    text = cfg.read_text()
    control, status = work / "run" / "control.sock", work / "run" / "status.sock"
    with _pd0_daemon(work) as (d, _):
        assert request(status, {"cmd": "reset"}).get("ok") is False
        swapped = text.replace("run/control.sock", "run/SWAP").replace(
            "run/status.sock", "run/control.sock"
        )
        cfg.write_text(swapped.replace("run/SWAP", "run/status.sock"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 1, "the reload", 10.0)
        assert d.events("reload_control_failed") == 0, d.tail()
        assert request(status, {"cmd": "reset"}).get("ok") is True, d.tail()
        refused = request(control, {"cmd": "reset"})
        assert refused == {"ok": False, "error": "unknown cmd; valid here: status"}, refused
        assert request(control, {"cmd": "status"}).get("ok") is True
        assert stat.S_IMODE(control.stat().st_mode) == 0o666
        assert stat.S_IMODE(status.stat().st_mode) == 0o660
        d.socket = status
        assert d.stop() == 0
    assert not control.exists() and not status.exists()


TWO_TCP = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}
  - {name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut}
  - {name: dvl, url: links/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
  - {uut: emlog2, reference: dvl, talker: VD, tcp: "127.0.0.1:{two}"}
outputs: {tcp: "127.0.0.1:{tcp}"}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
"""
"""Two EMlogs: emlog1's sentences on the shared TCP output, emlog2's on its own."""


def _talkers(port: int, masters: list[int], want: bytes) -> bytes:
    """What a client of the TCP output at ``port`` receives while both EMlogs send: 3
    sentences each once ``want`` came (the other log's, sent with them, would have come
    too), at most 10."""
    with socket.create_connection(("127.0.0.1", port), timeout=5.0) as c:
        c.setblocking(False)
        got = b""
        for k in range(10):  # at 5 Hz: under each log's plausible rate
            os.write(masters[0], VHW[k % 2])
            os.write(masters[1], OTHER_VHW[k % 2])
            time.sleep(0.2)
            with contextlib.suppress(BlockingIOError):
                got += c.recv(65536)
            if k >= 2 and want in got:
                break
        return got


def test_a_reload_swapping_two_tcp_outputs_addresses_swaps_them(tmp_path: Path) -> None:
    """SIGHUP into a config whose shared TCP output takes emlog2's own TCP port and emlog2
    the shared one's: afterwards each port carries the other log's sentences (emlog1's
    ``$VWVHW`` at 5 kn on the old own port, emlog2's ``$VDVHW`` at 7 kn on the old shared
    one), no output failed to bind."""
    a, b = free_port(), free_port()
    work = make_work(tmp_path, TWO_TCP.replace("{two}", str(b)).replace("{tcp}", str(a)))
    cfg = work / "emlogd.yaml"
    with device_ptys(work / "links", ("emlog1", "emlog2", "dvl")) as masters:
        d = Daemon(work)
        try:
            got = _talkers(a, masters, b"$VWVHW,,T,,M,5.0")
            assert b"$VWVHW,,T,,M,5.0" in got and b"VDVHW" not in got, got
            cfg.write_text(
                cfg.read_text().replace(str(a), "A").replace(str(b), str(a)).replace("A", str(b))
            )
            d.send_signal(signal.SIGHUP)
            wait(lambda: d.events("reloaded") >= 1, "the reload", 10.0)
            assert d.events("reload_outputs_failed") == 0, d.tail()
            got = _talkers(a, masters, b"$VDVHW,,T,,M,7.0")
            assert b"$VDVHW,,T,,M,7.0" in got and b"VWVHW" not in got, got
            got = _talkers(b, masters, b"$VWVHW,,T,,M,5.0")
            assert b"$VWVHW,,T,,M,5.0" in got and b"VDVHW" not in got, got
            assert d.stop() == 0
        finally:
            d.kill()


STATUS_OFTEN = "{pty: out/emlog0, status_sentence_interval_s: 0.2}"
"""The outputs of the echo tests: the status sentence, the proof of a loop, five times a
second."""


def _own_lines(d: Daemon, emlog: int) -> tuple[bytes, bytes]:
    """A corrected VHW the daemon has just written (within :data:`ECHO_S`) and a status
    sentence it wrote (the EMlog sent readings for them): what a loop brings back."""
    d.lines.clear()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:  # a reading every 0.3 s until both came out
        seen = len(d.lines)
        os.write(emlog, VHW[0])
        d.pump(0.3)
        vhw = [x for x in d.lines[seen:] if x.startswith(b"$VWVHW")]
        status = [x for x in d.lines if x.startswith(b"$PEMLS")]
        if vhw and status:
            return vhw[-1], status[-1]
    raise AssertionError(f"no VHW and status sentence out: {d.lines}")


def _settled(d: Daemon, records: int, echoes: int) -> tuple[int, int]:
    """EMlog1's records and echoes 0.2 s after they reach ``records`` and ``echoes``
    (within 10 s)."""

    def reached() -> bool:
        got = _records(d)
        return got[0] >= records and got[1] >= echoes

    wait(reached, f"{records} records and {echoes} echoes", 10.0)
    time.sleep(0.2)
    return _records(d)


def _records(d: Daemon) -> tuple[int, int]:
    """EMlog1's port: its records decoded and its lines skipped as echoes."""
    port = cast(dict[str, dict[str, int]], d.status()["ports"])["emlog1"]
    return port["records"], port["echoes"]


def test_a_sentence_before_the_proof_of_a_loop_is_read(tmp_path: Path) -> None:
    """The EMlog's line carries a line equal to the daemon's last VHW, then the daemon's
    status sentence, in one read: the VHW before the proof is read as the log's (one
    record more), the status sentence skipped (one echo); the same VHW line after the
    proof is an echo. Nothing before the proof is judged an echo: a log whose sentence
    equals the corrected one (a raw reading passed through) is never mistaken for it."""
    work = make_work(tmp_path, PD0_CONFIG.replace("{pty: out/emlog0}", STATUS_OFTEN))
    with _pd0_daemon(work) as (d, emlog):
        vhw, status = _own_lines(d, emlog)
        before = _records(d)
        os.write(emlog, vhw + b"\r\n" + status + b"\r\n")
        assert _settled(d, before[0] + 1, before[1] + 1) == (before[0] + 1, before[1] + 1)
        vhw, _ = _own_lines(d, emlog)
        before = _records(d)
        os.write(emlog, vhw + b"\r\n")
        assert _settled(d, before[0], before[1] + 1) == (before[0], before[1] + 1)
        assert d.stop() == 0


def test_a_proof_of_a_loop_split_across_reads_is_seen(tmp_path: Path) -> None:
    """The daemon's status sentence comes back in two pieces, read apart (a serial line at
    4800 Bd delivers a sentence over 60 ms, a few bytes a read), the first ending in
    ``$PEM``: the loop is proven (``output_read_back`` logged, the sentence counted an
    echo) and the corrected VHW coming back after it is skipped. Only a read holding the
    whole ``$PEMLS,`` was seen as the proof: on a slow line the loop was never noticed
    and every echo was read as the log's reading."""
    work = make_work(tmp_path, PD0_CONFIG.replace("{pty: out/emlog0}", STATUS_OFTEN))
    with _pd0_daemon(work) as (d, emlog):
        vhw, status = _own_lines(d, emlog)
        before = _records(d)
        os.write(emlog, b"$VWVHW,,T,,M,5.01,N,,K*4E\r\n" + status[:4])
        time.sleep(0.3)
        os.write(emlog, status[4:] + b"\r\n" + vhw + b"\r\n")
        wait(lambda: _records(d)[0] >= before[0] + 1, "the reading before the proof", 10.0)
        assert _settled(d, before[0] + 1, before[1] + 2) == (before[0] + 1, before[1] + 2)
        assert d.events("output_read_back") == 1, d.tail()
        assert d.stop() == 0


def test_a_config_caught_half_written_by_a_reload_is_read_once_whole(tmp_path: Path) -> None:
    """The config rewritten as a deployment tool writes it — a third (cut in the middle of
    the port list), SIGHUP, then the rest in four pieces 0.1 s apart, the new config
    adding a status socket: the reload waits for the file to stay unchanged for
    ``SETTLE_S`` and applies the whole new config (the status socket answers), with no
    ``reload_failed``. The half file was parsed at the SIGHUP: ``reload_failed`` and the
    old config kept, the new one ignored until another SIGHUP."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    new = cfg.read_text().encode() + b"status_socket: run/status.sock\n"
    cut = len(new) // 3
    pieces = [
        new[cut + k * (len(new) - cut) // 4 : cut + (k + 1) * (len(new) - cut) // 4]
        for k in range(4)
    ]
    with _pd0_daemon(work) as (d, _):
        fd = os.open(cfg, os.O_WRONLY | os.O_TRUNC)
        try:
            os.write(fd, new[:cut])
            d.send_signal(signal.SIGHUP)
            for piece in pieces:
                time.sleep(0.1)
                os.write(fd, piece)
        finally:
            os.close(fd)
        assert cfg.read_bytes() == new
        wait(lambda: d.events("reloaded") + d.events("reload_failed") >= 1, "the reload", 10.0)
        assert d.events("reload_failed") == 0, d.tail()
        status = work / "run" / "status.sock"
        assert request(status, {"cmd": "status"}).get("ok") is True
        assert d.stop() == 0


def test_a_port_that_cannot_be_opened_at_the_start_is_listed_and_tried_again(
    tmp_path: Path,
) -> None:
    """The DVL's link names a regular file when the daemon starts: it starts, the status
    lists ``ports_not_open: {dvl: why}`` and the EMlog's corrected VHW go out; once the
    link names a pty the DVL is opened (its backoff, at most 5 s) and the list is empty.
    The status gave the reason in the port's own entry only: nothing said at the top that
    a sensor the config names was not there."""
    work = make_work(tmp_path, PD0_CONFIG)
    emlog = raw_pty(work / "links" / "emlog1")
    link = work / "links" / "dvl"
    link.write_text("not a device\n")
    dvl = -1
    try:
        d = Daemon(work, pty=True)
        try:
            tty.setraw(d.fd)
            missing = cast(dict[str, str], d.status()["ports_not_open"])
            assert list(missing) == ["dvl"] and "a regular file" in missing["dvl"], missing
            for k in range(5):
                os.write(emlog, VHW[k % 2])
                d.pump(0.1)
            assert any(line.startswith(b"$VWVHW") for line in d.lines), d.lines
            link.unlink()
            dvl = raw_pty(link)
            wait(lambda: not d.status()["ports_not_open"], "the DVL opened", 10.0)
            assert d.status()["ports"]["dvl"]["open"] is True  # type: ignore[index]
            assert d.stop() == 0
        finally:
            d.kill()
    finally:
        for fd in (emlog, dvl):
            if fd >= 0:
                os.close(fd)


def test_a_reload_swapping_the_pty_and_the_control_socket_swaps_them(tmp_path: Path) -> None:
    """SIGHUP into a config whose ``control_socket`` is the old pty's path and whose pty
    is published at the old control socket's: within the reload the control socket
    answers at its new path and the pty is published at its own (its link names a pty),
    no ``reload_outputs_failed``. The pty found the old control socket in its way and
    failed (``reload_outputs_failed``), published only by the retry 2 s later: no output
    for the autopilot meanwhile, and an error in the log for a config that was good."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    text = cfg.read_text().replace("out/emlog0", "SWAP").replace("run/control.sock", "out/emlog0")
    pty, control = work / "run" / "control.sock", work / "out" / "emlog0"
    with _pd0_daemon(work) as (d, _):
        cfg.write_text(text.replace("SWAP", "run/control.sock"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 1, "the reload", 10.0)
        assert d.events("reload_outputs_failed") == 0, d.tail()
        assert pty.is_symlink() and str(pty.readlink()).startswith("/dev/pts/")
        assert request(control, {"cmd": "status"}).get("ok") is True
        d.socket = control
        assert d.stop() == 0
