"""End to end: the real daemon (subprocess) against fake devices on ptys.

Captures are replayed faster than real time, so the configured latencies are the
simulator's divided by the replay speed.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from calib.estimate import Estimate
from drivers.io.capture import CaptureWriter
from drivers.io.fake import FakeDevice
from emlogd.client import request
from emlogd.daemon.statefile import StateStore
from emlogd.launch import DaemonProcess, fake_sensors
from tests.emlogd.daemon.harness import (
    OUTPUTS,
    PORTS,
    SPEED,
    Daemon,
    free_port,
    make_work,
    tcp_port,
    wait,
)

CONFIG = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}}
  - {{name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut, baud: 38400}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, stale_timeout_s: 1,
     rest_s: 0}}  # exact receive times at 20x (resting is a real-time CPU saver)
  - {{name: junk, url: links/junk, protocol: nmea0183, role: aux}}
calibration:
  - {{uut: emlog1, reference: dvl, lag: {3.3 / SPEED:.4f}, max_param_std: {{m: 0.05, b: 0.08}},
     current: false,
     excitation_half_life_samples: 120, persist_interval_s: 0.5,
     validation_s: {120 / SPEED:.3f}, recheck_s: {300 / SPEED:.2f}}}
  - {{uut: emlog2, reference: dvl, lag: {0.5 / SPEED:.4f}, persist_interval_s: 0.5, current: false,
     validation_s: {120 / SPEED:.3f}, recheck_s: {300 / SPEED:.2f}, talker: VM}}
{OUTPUTS}"""


def _setup(tmp_path: Path) -> Path:
    """``tmp_path`` a work directory (:func:`make_work`) and a capture of garbage for the
    ``junk`` port; returns the capture."""
    make_work(tmp_path, CONFIG)
    junk = tmp_path / "junk.cap"
    with CaptureWriter(junk, {"junk": "nmea0183"}) as w:
        for k in range(3000):
            w.write_chunk(1.0 + k * 0.001, "junk", os.urandom(400) + b"\n" + b"A" * 2000)
    return junk


def test_daemon_end_to_end(tmp_path: Path, trial_files: dict[str, Path]) -> None:
    """The daemon learns EMlog1 (corrected RMSE < 0.75 raw), counts a garbage port, survives an
    EMlog unplug and a TCP client that never reads, freezes and keeps emitting when the DVL stops,
    and restarts frozen from the state SIGTERM wrote."""
    junk = _setup(tmp_path)
    capture = trial_files["figure-8"]
    links = tmp_path / "links"
    # one device per port: the test unplugs them one by one
    devices = {p: FakeDevice(capture, p, links / p, speed=SPEED).start() for p in PORTS}
    garbage = FakeDevice(junk, "junk", links / "junk", speed=None, loop=True).start()
    d = Daemon(tmp_path, pty=True)
    try:
        # a TCP client that connects and never reads must not stall the pty output
        lazy = socket.create_connection(("127.0.0.1", tcp_port(tmp_path)))
        lazy.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
        d.pump(6.0)
        # unplug and replug EMlog2 at the same path
        devices["emlog2"].stop()
        devices["emlog2"].join(5)
        d.pump(1.0)
        unplugged = d.status()["ports"]
        assert isinstance(unplugged, dict)
        devices["emlog2"] = FakeDevice(capture, "emlog2", links / "emlog2", speed=SPEED).start()
        # to the end of the capture of EMlog1 and the DVL (the replugged EMlog2 replays
        # its own from the start, and goes on through the rest)
        while not (devices["emlog1"].finished.is_set() and devices["dvl"].finished.is_set()):
            d.pump(0.5)
            assert d.running
        d.pump(0.5)
        st = d.status()
        uuts = st["uuts"]
        ports = st["ports"]
        assert isinstance(uuts, dict) and isinstance(ports, dict)
        e1 = uuts["emlog1"]
        assert e1["params"] is not None, e1
        # ≥ 25 % better than raw over the whole run: this short 20x run is mostly the
        # learning transient, and the raw reading passes through until the first
        # calibration has beaten it over its validation window (0.64 of raw here)
        assert e1["rmse_corrected"] < 0.75 * e1["rmse_raw"], e1
        assert sum(ports["junk"]["rejects"].values()) > 100  # the garbage port is counted
        assert ports["emlog2"]["records"] > unplugged["emlog2"]["records"] > 0  # read again
        vhw = [ln for ln in d.lines if ln[3:6] == b"VHW"]
        status = [ln for ln in d.lines if ln.startswith(b"$PEMLS")]
        assert len(vhw) > 200 and status
        # the DVL stops: the parameters freeze, the output goes on
        devices["dvl"].stop()
        frozen = dict(e1["params"])
        for p in ("emlog1",):
            devices[p].stop()
            devices[p].join(5)
            devices[p] = FakeDevice(capture, p, links / p, speed=SPEED).start()
        d.pump(3.0)
        st2 = d.status()["uuts"]
        assert isinstance(st2, dict)
        assert st2["emlog1"]["state"] == "frozen" and st2["emlog1"]["params"] == frozen
        assert st2["emlog1"]["reference"] in ("stale", "lost")
        ports2 = d.status()["ports"]
        assert isinstance(ports2, dict) and ports2["dvl"]["stale"] is True  # silent > 1 s
        n_before = len([ln for ln in d.lines if ln[3:6] == b"VHW"])
        d.pump(1.0)
        assert len([ln for ln in d.lines if ln[3:6] == b"VHW"]) > n_before
        lazy.close()
        assert d.stop() == 0
    finally:
        d.kill()
        for dev in [*devices.values(), garbage]:
            dev.stop()
            dev.join(5)
    # SIGTERM persisted the frozen calibration; a restart loads it
    states, _report = StateStore(tmp_path / "state" / "state.yaml").load()
    assert "emlog1" in states and not states["emlog1"].reset
    assert states["emlog1"].params.as_dict() == pytest.approx(frozen)
    log = (tmp_path / "daemon.log").read_text()
    assert '"event": "ready"' in log and '"event": "stopped"' in log
    assert "port_disconnected" in log and log.count("port_connected") >= 4
    # a silent port is reported by the pipeline's staleness alone, once
    assert '"event": "port_stale"' not in log
    stale_dvl = [ln for ln in log.splitlines() if '"event": "stale"' in ln and '"dvl"' in ln]
    assert len(stale_dvl) == 1, stale_dvl
    d2 = Daemon(tmp_path, pty=True)
    try:
        d2.pump(0.5)
        st3 = d2.status()["uuts"]
        assert isinstance(st3, dict)
        # restored, the calibration re-earns trust: the filter starts from it, and it is
        # applied once validated (or, with no reference heard, unverified)
        assert st3["emlog1"]["estimate"] == pytest.approx(frozen)
        assert st3["emlog1"]["params"] in (None, pytest.approx(frozen))
        resp = d2.ask(cmd="learn", on=False)
        assert resp["ok"] and resp["learning"] is False
        assert d2.ask(cmd="reset", port="nope")["ok"] is False
    finally:
        assert d2.stop(signal.SIGINT) == 0
    assert not (tmp_path / "out" / "emlog0").exists()  # the pty link is removed on exit


def test_notify_missing_sensors_and_reload(tmp_path: Path) -> None:
    """READY=1 over a real notify socket, sensors absent at start, SIGHUP good and bad."""
    cfg = make_work(tmp_path, CONFIG) / "emlogd.yaml"
    base = cfg.read_text()
    notify = tmp_path / "notify.sock"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind(str(notify))
    srv.settimeout(20)
    d = DaemonProcess(
        cfg,
        socket="run/control.sock",
        log="daemon.log",
        cwd=tmp_path,
        env={"NOTIFY_SOCKET": str(notify), "WATCHDOG_USEC": "1000000"},
    )
    try:
        messages = [srv.recv(4096).decode() for _ in range(2)]
        assert messages[0] == "READY=1"
        assert messages[1].startswith("STATUS=emlog1 uncalibrated")
        # no sensor exists: the daemon runs and says so
        st = d.status()
        assert st["uuts"]["emlog1"]["state"] == "uncalibrated"  # type: ignore[index]
        # WATCHDOG_USEC=1 s: a keep-alive every half second, whatever else is sent
        deadline = time.monotonic() + 5
        got = b""
        while got != b"WATCHDOG=1":
            assert time.monotonic() < deadline, "no WATCHDOG=1 within 5 s"
            got = srv.recv(4096)
        # a good reload moves the control socket
        cfg.write_text(base.replace("run/control.sock", "run/control2.sock"))
        d.send_signal(signal.SIGHUP)
        deadline = time.monotonic() + 10
        while not (tmp_path / "run" / "control2.sock").exists():
            assert time.monotonic() < deadline, (tmp_path / "daemon.log").read_text()
            time.sleep(0.05)
        assert request(tmp_path / "run" / "control2.sock", {"cmd": "status"})["ok"]
        # a bad reload keeps the running config
        cfg.write_text(
            base.replace("protocol: pd6", "protocol: pd9").replace(
                "run/control.sock", "run/control2.sock"
            )
        )
        d.send_signal(signal.SIGHUP)
        log = tmp_path / "daemon.log"
        wait(lambda: '"event": "reload_failed"' in log.read_text(), "no reload_failed", 10.0)
        assert request(tmp_path / "run" / "control2.sock", {"cmd": "status"})["ok"]
        assert d.running
        assert d.stop() == 0
        rest = []
        srv.settimeout(1)
        try:
            while True:
                rest.append(srv.recv(4096).decode())
        except TimeoutError:
            pass
        assert "STOPPING=1" in rest
    finally:
        d.kill()
        srv.close()
    text = (tmp_path / "daemon.log").read_text()
    assert '"event": "reloaded"' in text and '"event": "reload_failed"' in text
    assert "port_disconnected" in text


def _can_mount(where: Path) -> bool:
    if os.geteuid() != 0:
        return False
    where.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], capture_output=True
    )
    return r.returncode == 0


@pytest.mark.root
@pytest.mark.parametrize("fault", ["read-only", "full"])
def test_state_directory_read_only_or_full(
    tmp_path: Path, trial_files: dict[str, Path], fault: str
) -> None:
    """The state directory fails under the running daemon: it keeps running, reports
    it, and the previous state file stays intact (a real tmpfs, remounted read-only or
    filled up)."""
    state_dir = tmp_path / "state"
    if not _can_mount(state_dir):
        pytest.skip("needs root and mount (tmpfs) to make a directory read-only or full")
    try:
        for sub in ("links", "out", "run"):
            (tmp_path / sub).mkdir()
        (tmp_path / "emlogd.yaml").write_text(CONFIG.replace("{tcp}", str(free_port())))
        store = StateStore(state_dir / "state.yaml")
        from calib.models import Params
        from emlogd.pipeline.calibration import Calibration

        store.save({"emlog1": Calibration("emlog1", Estimate(Params("EM3"), {}), None)})
        before = store.path.read_bytes()
        if fault == "read-only":
            subprocess.run(["mount", "-o", "remount,ro", str(state_dir)], check=True)
        else:
            fd = os.open(state_dir / "filler", os.O_WRONLY | os.O_CREAT, 0o600)
            try:
                while True:
                    os.write(fd, b"\0" * 4096)
            except OSError:
                pass  # ENOSPC: the file system is full
            finally:
                os.close(fd)
        links = tmp_path / "links"
        capture = trial_files["figure-8"]
        with (
            fake_sensors(capture, links, PORTS, speed=SPEED) as fake,
            Daemon(tmp_path, pty=True) as d,
        ):
            while not fake.finished.is_set():
                d.pump(0.5)
                assert d.running  # keeps running
            resp = d.ask(cmd="status")
            assert (
                resp["ok"] and isinstance(resp["state_errors"], int) and resp["state_errors"] >= 1
            )
            assert d.stop() == 0  # the final persist fails too: still a clean exit
        assert store.path.read_bytes() == before  # never corrupted, never half-written
        assert "state_write_failed" in (tmp_path / "daemon.log").read_text()
    finally:
        subprocess.run(["umount", "-l", str(state_dir)], capture_output=True)


class _Source:
    """A source whose reads return the given chunks (the daemon's view of a port)."""

    has_events = False
    is_open = True

    def __init__(self, name: str, chunks: list[tuple[float, bytes]], fd: int = -1) -> None:
        self.name = name
        self.chunks = chunks
        self.fd = fd

    def fileno(self) -> int | None:
        return self.fd if self.fd >= 0 else None

    def read(self) -> tuple[float, bytes] | None:
        if not self.chunks:
            return None
        return self.chunks.pop(0)


class _SpyPipeline:
    def __init__(self) -> None:
        self.uuts = {"emlog1": None}
        self.decoders = {"emlog1": None, "dvl": None}
        self.calls: list[tuple[float, str, bytes]] = []

    def feed(self, t: float, port: str, data: bytes) -> object:
        from emlogd.pipeline.core import Output

        self.calls.append((t, port, data))
        return Output()


def test_a_readable_reference_port_rests_then_is_read_once_and_armed_again(
    tmp_path: Path,
) -> None:
    """A readable reference port with rest_s is read, then disarmed while it rests (the UUT never
    rests), read once with its whole burst when due, and armed again."""
    from emlogd.daemon import loop as dmod

    _setup(tmp_path)
    d = dmod.Daemon(tmp_path / "emlogd.yaml", log=None)
    spy = _SpyPipeline()
    d.pipeline = spy  # type: ignore[assignment]
    d.rest_s = {"dvl": 0.02, "emlog1": 0.02}
    r, w = os.pipe()
    r2, w2 = os.pipe()
    dvl = _Source("dvl", [(1.02, b":SA\r\n:TS\r\n:BD\r\n"), (1.12, b":SA\r\n")], fd=r)
    emlog = _Source("emlog1", [(1.01, b"$VWVHW\r\n")], fd=r2)
    d.sources = {"dvl": dvl, "emlog1": emlog}  # type: ignore[dict-item]
    d._sync_registrations()
    assert d.registered == {"dvl": r, "emlog1": r2} and d.rest_fds == {r: "dvl"}

    for fd in (w, w2):
        os.write(fd, b"x")  # both readable, and stay so (the fake sources never drain)
    d._round(0)  # one round of the loop's wait
    assert [c[2] for c in spy.calls] == [b"$VWVHW\r\n"]
    assert d.resting.keys() == {"dvl"} and len(dvl.chunks) == 2  # the UUT never rests
    d._unregister("emlog1")  # only the DVL from here on
    del d.sources["emlog1"]
    assert d.registered == {"dvl": r}
    assert d.poll.poll(0) == []  # disarmed: no wake-up while it rests, though readable
    assert d.unselectable == []  # nor read on every round as if it had no descriptor
    d._wake_rested(d.monotonic())
    assert len(dvl.chunks) == 2  # not due yet: nothing read
    d.resting["dvl"] = 0.0  # due
    d._wake_rested(d.monotonic())
    assert len(dvl.chunks) == 1 and d.resting == {} and d.registered == {"dvl": r}
    assert [c[2] for c in spy.calls] == [
        b"$VWVHW\r\n",
        b":SA\r\n:TS\r\n:BD\r\n",  # the burst in one read
    ]
    d._round(0)
    assert d.resting.keys() == {"dvl"}  # armed again: still readable, so resting again
    d._unregister("dvl")
    assert d.registered == {} and d.rest_fds == {}
    for fd in (r, w, r2, w2, d._wake_r, d._wake_w):
        os.close(fd)
    d.sel.close()
    d.poll.close()


def test_a_rested_port_is_read_at_the_next_wake_up_first_and_stamped_at_its_rest_end(
    tmp_path: Path,
) -> None:
    """A resting port is not read before its rest is over; after, at the loop's next wake-up
    (a UUT's sentence), before the UUT and stamped with the end of its rest; the loop waits
    for it at the latest REST_MERGE_S past that end."""
    from emlogd.daemon import loop as dmod

    _setup(tmp_path)
    now = [100.0]
    d = dmod.Daemon(
        tmp_path / "emlogd.yaml", log=None, clock=lambda: 5000.0, monotonic=lambda: now[0]
    )
    spy = d.pipeline = _SpyPipeline()  # type: ignore[assignment]
    d.rest_s = {"dvl": 0.02}
    r, w = os.pipe()
    r2, w2 = os.pipe()
    dvl = _Source("dvl", [(9.0, b":SA\r\n:BD\r\n")], fd=r)
    emlog = _Source("emlog1", [(5000.01, b"$VWVHW,1\r\n"), (5000.05, b"$VWVHW,2\r\n")], fd=r2)
    d.sources = {"dvl": dvl, "emlog1": emlog}  # type: ignore[dict-item]
    d._sync_registrations()
    assert d._wait_s() == dmod.SELECT_TIMEOUT_S  # nothing rests
    os.write(w, b"x")
    d._round(0)  # the DVL readable: it rests until 100.02
    assert d._wait_s() == pytest.approx(0.02 + dmod.REST_MERGE_S)
    now[0] = 100.01
    os.write(w2, b"x")  # a UUT's sentence while the DVL rests
    d._round(0)
    now[0] = 100.025  # the rest is over; the UUT readable again (the pipe is not drained)
    assert d._wait_s() == pytest.approx(100.02 + dmod.REST_MERGE_S - now[0])
    d._round(0)
    assert spy.calls == [
        (5000.01, "emlog1", b"$VWVHW,1\r\n"),
        (pytest.approx(5000.02), "dvl", b":SA\r\n:BD\r\n"),
        (5000.05, "emlog1", b"$VWVHW,2\r\n"),
    ]
    for fd in (r, w, r2, w2, d._wake_r, d._wake_w):
        os.close(fd)
    d.sel.close()
    d.poll.close()


def test_a_resting_reference_port_is_replugged_and_every_ensemble_counted(
    tmp_path: Path,
) -> None:
    """Real time, default rest_s: ensembles whose lines come 3 ms apart, an unplug
    while the port rests, a new pty at the same path: all ensembles are decoded."""
    from datetime import UTC, datetime

    from drivers.io.vpty import VirtualPort
    from drivers.rdi_ascii import encode_pd6

    _setup(tmp_path)
    cfg = tmp_path / "emlogd.yaml"
    text = cfg.read_text()
    assert "rest_s: 0}" in text
    cfg.write_text(text.replace("rest_s: 0}", "rest_s: 0.02}"))  # the default, real time
    link = tmp_path / "links" / "dvl"
    lines = [
        (x + "\r\n").encode()
        for x in encode_pd6(
            timestamp=datetime(2026, 1, 1, tzinfo=UTC), heading_deg=10.0,
            bottom_ship_mps=(0.0, 1.5, 0.0), range_m=20.0,
        )
    ]  # fmt: skip

    def ensembles(vp: VirtualPort, n: int) -> None:
        for _ in range(n):
            for ln in lines:
                vp.write(ln)
                time.sleep(0.003)  # the serial spacing of the simulator at 115200 Bd
            time.sleep(0.05)

    def dvl_records() -> int:
        st = d.status()["ports"]
        assert isinstance(st, dict)
        return int(st["dvl"]["records"])

    vp = VirtualPort(link)
    d = Daemon(tmp_path, pty=True)
    try:
        deadline = time.monotonic() + 10
        while "port_connected" not in (tmp_path / "daemon.log").read_text():
            assert time.monotonic() < deadline, "the daemon never opened the DVL"
            d.pump(0.05)
        ensembles(vp, 20)
        d.pump(0.3)
        assert dvl_records() == 20
        connected = (tmp_path / "daemon.log").read_text().count("port_connected")
        for ln in lines[:2]:  # unplugged mid-ensemble, while the port rests
            vp.write(ln)
        vp.close()
        d.pump(0.5)
        vp = VirtualPort(link)
        deadline = time.monotonic() + 10
        while (tmp_path / "daemon.log").read_text().count("port_connected") <= connected:
            assert time.monotonic() < deadline, "the DVL was not reopened"
            d.pump(0.1)
        ensembles(vp, 20)
        d.pump(0.3)
        assert dvl_records() == 40
        assert d.stop() == 0
    finally:
        d.kill()
        vp.close()


def test_repeating_events_are_rate_limited_per_port() -> None:
    """A flapping reference logs one `reference` line per port per 10 s, the next saying how
    many were left out; other events and other ports are not held back."""
    from emlogd.daemon.logsetup import EventLimiter

    lim = EventLimiter(10.0)
    assert lim.allow("dvl", "reference", 0.0) == 0
    assert lim.allow("dvl", "reference", 1.0) is None
    assert lim.allow("dvl", "reference", 2.0) is None
    assert lim.allow("gps", "reference", 2.0) == 0
    assert lim.allow("dvl", "calibrated", 2.5) == 0
    assert lim.allow("dvl", "calibrated", 2.6) == 0
    assert lim.allow("dvl", "reference", 10.5) == 2


def test_a_log_with_its_own_pty_and_talker(tmp_path: Path, trial_files: dict[str, Path]) -> None:
    """A log given its own pty and talker sends its sentences there only: the shared pty
    carries the other log's, the log's own pty none but its own."""
    junk = _setup(tmp_path)
    cfg = tmp_path / "emlogd.yaml"
    text = cfg.read_text()
    assert "  - {uut: emlog2, reference: dvl," in text
    # its readings at 20x real time: held to the replay's rate and acceleration, not
    # dropped as a babble (the log's own pty would carry its first sentences only)
    cfg.write_text(
        text.replace(
            "  - {uut: emlog2, reference: dvl,",
            "  - {uut: emlog2, reference: dvl, pty: out/emlog2, max_rate_hz: 10000,"
            f" max_reading_accel_mps2: {SPEED**2:g},",
        )
    )
    links = tmp_path / "links"
    capture = trial_files["figure-8"]
    with (
        fake_sensors(capture, links, PORTS, speed=SPEED),
        fake_sensors(junk, links, ("junk",), speed=None, loop=True),
        Daemon(tmp_path, pty=True) as d,
    ):
        link = tmp_path / "out" / "emlog2"
        end = time.monotonic() + 20.0
        while not link.exists() and time.monotonic() < end:
            d.pump(0.1)
        own = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        got = b""
        try:
            # 4 s of both outputs, and on a loaded machine until the log's own pty has
            # carried a few of its sentences (at most 20 s)
            end, least = time.monotonic() + 20.0, time.monotonic() + 4.0
            while time.monotonic() < end and (time.monotonic() < least or got.count(b"$VMVHW") < 3):
                d.pump(0.2)
                with contextlib.suppress(BlockingIOError, OSError):
                    got += os.read(own, 65536)
        finally:
            os.close(own)
        assert d.stop() == 0
    shared = [ln for ln in d.lines if ln.startswith(b"$")]
    mine = [ln for ln in got.split(b"\r\n") if ln.startswith(b"$")]
    assert any(ln.startswith(b"$VWVHW") for ln in shared)
    assert not any(ln.startswith(b"$VM") or b",emlog2," in ln for ln in shared)
    assert any(ln.startswith(b"$VMVHW") for ln in mine)
    assert not any(ln.startswith(b"$VWVHW") or b",emlog1," in ln for ln in mine)


class _Log:
    """The daemon's logger, keeping what it is given."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str, dict[str, object]]] = []

    def info(self, event: str, **kw: object) -> None:
        self.lines.append(("info", event, kw))

    def warning(self, event: str, **kw: object) -> None:
        self.lines.append(("warning", event, kw))


def test_a_chunk_that_fails_in_the_pipeline_is_contained(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A chunk whose handling raises in the pipeline does not leave the loop: it is counted as an
    internal reject of its port, logged once per 10 s per port and exception type (the next line
    with how many were left out), the chunks after it are handled, and a failing tick is contained
    the same way."""
    from emlogd.daemon import loop as dmod
    from emlogd.pipeline.core import Pipeline
    from emlogd.pipeline.settings import PortSettings

    _setup(tmp_path)
    clock = [100.0]
    log = _Log()
    d = dmod.Daemon(tmp_path / "emlogd.yaml", log=log, monotonic=lambda: clock[0])
    p = Pipeline([PortSettings("compass", "nmea0183")], [])
    d.pipeline = p
    real_route = p._route

    def route(t: float, port: str, items: list[object], out: object) -> None:
        if t in (1.0, 2.0, 3.0):
            raise ValueError("math domain error")
        real_route(t, port, items, out)  # type: ignore[arg-type]

    monkeypatch.setattr(p, "_route", route)
    hdt = b"$HEHDT,10.0,T*1E\r\n"
    for t in (1.0, 1.5, 2.0, 3.0):
        d._feed(t, "compass", hdt)
        clock[0] += 1.0
    counters = p.decoders["compass"].counters
    assert counters.rejects["internal"] == 3 and counters.records == 4
    warned = [kw for level, ev, kw in log.lines if level == "warning" and ev == "internal"]
    assert warned == [
        {
            "port": "compass",
            "error": "ValueError: math domain error",
            "data": "$HEHDT,10.0,T*1E\\r\\n",
        }
    ]
    clock[0] += 10.0
    d._feed(4.0, "compass", hdt)  # handled
    monkeypatch.setattr(p, "tick", lambda t: 1 / 0)
    d._tick()
    d._tick()
    warned = [kw for level, ev, kw in log.lines if level == "warning" and ev == "internal"]
    assert [w["error"] for w in warned] == [
        "ValueError: math domain error",
        "ZeroDivisionError: division by zero",
    ]
    assert d.contain.count == 5 and counters.records == 5
    d.sel.close()
    d.poll.close()
    for fd in (d._wake_r, d._wake_w):
        os.close(fd)


HOSTILE_HDG = b"$HCHDG,10.0,1e308,E,1e308,E*73"
"""The red team's sentence: a valid checksum, a deviation and a variation whose sum overflows."""


def test_the_hostile_hdg_sentence_is_counted_and_the_daemon_goes_on(
    tmp_path: Path, trial_files: dict[str, Path]
) -> None:
    """`emlogd run` (a subprocess reading ptys) given the overflowing HDG sentence on an NMEA port,
    again and again between good headings, counts each as an out_of_range reject of that port,
    never exits, and keeps emitting the EMlog's VHW afterwards."""
    from drivers.framing import split_nmea

    split_nmea(HOSTILE_HDG, required=True)  # the checksum is valid
    _setup(tmp_path)
    junk = tmp_path / "hostile.cap"
    with CaptureWriter(junk, {"junk": "nmea0183"}) as w:
        for k in range(100):
            w.write_line(1.0 + 0.1 * k, "junk", b"$HEHDT,10.0,T*1E")
            w.write_line(1.05 + 0.1 * k, "junk", HOSTILE_HDG)
    links = tmp_path / "links"
    emlog = FakeDevice(trial_files["figure-8"], "emlog1", links / "emlog1", speed=SPEED).start()
    hostile = FakeDevice(junk, "junk", links / "junk", speed=1.0, loop=True).start()
    d = Daemon(tmp_path, pty=True)
    try:
        deadline = time.monotonic() + 20
        while True:
            d.pump(0.5)
            assert d.running
            ports = d.status()["ports"]
            assert isinstance(ports, dict)
            if ports["junk"]["rejects"]["out_of_range"] >= 5:
                break
            assert time.monotonic() < deadline, ports["junk"]
        assert ports["junk"]["records"] >= 5 and ports["junk"]["rejects"]["internal"] == 0
        n_before = len([ln for ln in d.lines if ln[3:6] == b"VHW"])
        d.pump(2.0)
        assert d.running
        assert len([ln for ln in d.lines if ln[3:6] == b"VHW"]) > n_before
        ports = d.status()["ports"]
        assert isinstance(ports, dict)
        assert ports["junk"]["rejects"]["out_of_range"] >= 7
        assert d.stop() == 0
    finally:
        d.kill()
        for dev in (emlog, hostile):
            dev.stop()
            dev.join(5)
    assert "internal error" not in (tmp_path / "daemon.log").read_text()


def test_the_rest_key_documents_how_late_a_rested_port_is_read() -> None:
    """``rest_s``'s documentation (and README's key table) names REST_MERGE_S's value."""
    from emlogd.config import PortConfig
    from emlogd.daemon.loop import REST_MERGE_S
    from emlogd.pipeline.keys import entries

    doc = next(e.key.doc for e in entries(PortConfig) if e.name == "rest_s")
    assert doc.count(f"{REST_MERGE_S:g} s") == 2
