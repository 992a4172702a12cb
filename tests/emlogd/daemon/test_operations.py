"""Operating the real daemon (a subprocess): reload, operator actions, one instance per
state file, clients that misbehave, clocks that step. Fake devices on real ptys."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from calib.estimate import Estimate
from emlogd.client import request
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import OUTPUTS, SPEED, Daemon, tcp_port, wait

RUN = [sys.executable, "-m", "emlogd", "run", "--config", "emlogd.yaml"]

CONFIG = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}}
  - {{name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut, baud: 38400}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}}
calibration:
  - {{uut: emlog1, reference: dvl, lag: {3.3 / SPEED:.4f}, max_param_std: {{m: 0.05, b: 0.08}},
     excitation_half_life_samples: 120, persist_interval_s: 0.5,
     validation_s: {120 / SPEED:.3f}, recheck_s: {300 / SPEED:.2f}}}
  - {{uut: emlog2, reference: dvl, lag: {0.5 / SPEED:.4f}, persist_interval_s: 0.5,
     validation_s: {120 / SPEED:.3f}, recheck_s: {300 / SPEED:.2f}, talker: VM}}
{OUTPUTS}"""


def _num(doc: dict[str, object], key: str) -> float:
    v = doc[key]
    assert isinstance(v, int | float), doc
    return float(v)


# -- 1. reload -----------------------------------------------------------------


@pytest.mark.usefixtures("sensors")
def test_reload_keeps_what_did_not_change(work: Path) -> None:
    """SIGHUP changing one UUT keeps the pty (same link, an open pyserial reader reads on),
    the TCP client, and the other UUT's learning state and operator freeze."""
    d = Daemon(work)
    link = work / "out" / "emlog0"
    cfg = work / "emlogd.yaml"
    port = tcp_port(work)
    try:
        target = link.readlink()
        reader = serial.Serial(str(link), timeout=0.2)
        client = socket.create_connection(("127.0.0.1", port), timeout=5)
        wait(lambda: _num(d.uut("emlog1"), "scored_samples") > 50, "emlog1 never scored")
        assert d.ask(cmd="freeze", port="emlog1")["ok"]
        before1, before2 = d.uut("emlog1"), d.uut("emlog2")
        assert before1["learning_enabled"] is False and before2["learning_enabled"] is True
        assert reader.read(200) and client.recv(200)
        # emlog2's lag changes; nothing else does
        cfg.write_text(cfg.read_text().replace(f"lag: {0.5 / SPEED:.4f}", "lag: 0.05"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") == 1, "no reload")
        after1, after2 = d.uut("emlog1"), d.uut("emlog2")
        assert after1["learning_enabled"] is False  # the operator's freeze survives
        assert _num(after1, "scored_samples") >= _num(before1, "scored_samples")
        assert after1["lag_s"] == before1["lag_s"]
        assert after2["lag_s"] == 0.05
        # emlog2 starts afresh (its scored count may pass the old one on a loaded machine)
        reloaded = [
            json.loads(line)
            for line in d.log_path.read_text().splitlines()
            if '"event": "reloaded"' in line
        ]
        assert reloaded[0]["uuts_restarted"] == ["emlog2"], reloaded
        assert "emlog1" in reloaded[0]["uuts_kept"], reloaded
        assert link.readlink() == target  # the same pty
        reader.reset_input_buffer()
        got = b""
        while got.count(b"VHW") < 3:
            chunk = reader.read(256)  # the reader that stayed open reads on, without error
            assert chunk, "the pty went silent"
            got += chunk
        got = b""
        while got.count(b"VHW") < 3:
            chunk = client.recv(4096)  # and so does the TCP client
            assert chunk, "the TCP client was dropped"
            got += chunk
        reader.close()
        client.close()
        assert d.stop() == 0
    finally:
        d.kill()


# -- 2. operator actions ---------------------------------------------------------


def _seed(work: Path) -> None:
    """A state file with a calibration for emlog1 (the daemon starts frozen on it)."""
    from calib.models import Params
    from emlogd.pipeline.calibration import Calibration

    cal = Calibration(
        "emlog1", Estimate(Params("EM3", m=0.05, b_mps=0.1), {"m": 0.01, "b": 0.01}), 0.165
    )
    StateStore(work / "state" / "state.yaml").save({"emlog1": cal})


def test_reset_is_on_disk_before_the_reply(work: Path) -> None:
    """After a reset answered ok and a kill -9, the old calibration does not load again."""
    _seed(work)
    d = Daemon(work)
    try:
        assert d.uut("emlog1")["estimate"] == {"m": 0.05, "b": 0.1}  # restored, re-earning trust
        resp = d.ask(cmd="reset", port="emlog1")
        assert resp["ok"] and resp["persisted"] is True
    finally:
        d.kill()  # SIGKILL: nothing more is written
    states, _ = StateStore(work / "state" / "state.yaml").load()
    assert states["emlog1"].reset
    d2 = Daemon(work)
    try:
        u = d2.uut("emlog1")
        assert u["params"] is None and u["state"] == "uncalibrated"
        assert d2.stop() == 0
    finally:
        d2.kill()


def test_a_freeze_or_reset_that_cannot_be_saved_answers_an_error(work: Path) -> None:
    """The state file's directory is a regular file: freeze and reset reply ok false with
    the reason, and the daemon runs on."""
    cfg = work / "emlogd.yaml"
    cfg.write_text(cfg.read_text().replace("state/state.yaml", "blocker/state.yaml"))
    (work / "blocker").write_text("not a directory")
    d = Daemon(work)
    try:
        for cmd in ("freeze", "reset"):
            resp = d.ask(cmd=cmd)
            assert resp["ok"] is False, resp
            assert "not" in str(resp["error"]) and "blocker" in str(resp["error"]), resp
        assert d.uut("emlog1")["learning_enabled"] is False  # the freeze itself applied
        assert d.ask(cmd="status")["state_errors"] == 2
        assert d.stop() == 0
    finally:
        d.kill()


def test_repeated_operator_commands_do_not_storm_the_disk(work: Path) -> None:
    """A hundred freezes, resets and learns in a row write the state file at most twice
    (the reset and the first freeze): identical calibrations are not written again."""
    _seed(work)
    d = Daemon(work)
    try:
        for _ in range(100):
            for req in ({"cmd": "freeze"}, {"cmd": "reset"}, {"cmd": "learn", "on": True}):
                assert d.ask(**req)["ok"]
        st = d.ask(cmd="status")
        assert isinstance(st["persists"], int) and 1 <= st["persists"] <= 2, st["persists"]
        assert d.stop() == 0
    finally:
        d.kill()


def test_each_model_keeps_its_calibration_across_reloads_and_restarts(work: Path) -> None:
    """With the lag automatic: EM3 → EM4 → EM3 by reloads gets the EM3 calibration and the
    lag back, and so does a restart after a stop in EM4; a reset replies what it kept and
    cleared, and the lag survives it across a kill -9 and a restart."""
    cfg = work / "emlogd.yaml"
    text = cfg.read_text().replace(f"lag: {3.3 / SPEED:.4f}", "lag: auto")  # emlog1's
    cfg.write_text(text)
    em4 = text.replace("uut: emlog1, reference: dvl,", "uut: emlog1, reference: dvl, model: EM4,")
    _seed(work)  # EM3 m = 0.05, b = 0.1, lag 0.165 s
    em3_params = {"m": 0.05, "b": 0.1}

    def seen(d: Daemon) -> tuple[object, object, object]:
        # the calibration kept for the model (a restored one is applied once validated)
        u = d.uut("emlog1")
        return u["model"], u["kept"], u["lag_s"]

    d = Daemon(work)
    try:
        assert seen(d) == ("EM3", em3_params, 0.165)
        for n, (config, want) in enumerate(
            [
                (em4, ("EM4", None, 0.165)),
                (text, ("EM3", em3_params, 0.165)),
                (em4, ("EM4", None, 0.165)),
            ],
            start=1,
        ):
            cfg.write_text(config)
            d.send_signal(signal.SIGHUP)
            wait(lambda n=n: d.events("reloaded") == n, f"no reload {n}")  # type: ignore[misc]
            assert seen(d) == want, n
        assert d.stop() == 0
    finally:
        d.kill()
    states, others, report = StateStore(work / "state" / "state.yaml").load_state()
    assert report == []
    assert states["emlog1"].params.model == "EM4" and states["emlog1"].reset
    assert [(c.params.model, c.params.as_dict()) for c in others] == [("EM3", em3_params)]
    cfg.write_text(text)
    d2 = Daemon(work)
    try:
        assert seen(d2) == ("EM3", em3_params, 0.165)
        resp = d2.ask(cmd="reset", port="emlog1")
        assert resp["ok"] and resp["persisted"] is True
        assert resp["reset"]["emlog1"]["kept"] == {"lag_s": 0.165, "learning_enabled": True}  # type: ignore[index]
        cleared = resp["reset"]["emlog1"]["cleared"]  # type: ignore[index]
        assert "EM3 calibration" in cleared and "EM4 calibration (another model)" in cleared
    finally:
        d2.kill()  # SIGKILL: the reset was on disk before the reply
    d3 = Daemon(work)
    try:
        assert seen(d3) == ("EM3", None, 0.165)
        assert d3.stop() == 0
    finally:
        d3.kill()


# -- 3. one instance -------------------------------------------------------------


def test_a_second_instance_exits_and_leaves_the_first_alone(work: Path) -> None:
    """A second daemon on the same config exits 1 with one line naming the first's pid;
    one on another state file but the same control socket exits 1 too; the first keeps
    its pty link and control socket."""
    d = Daemon(work)
    try:
        link = work / "out" / "emlog0"
        target = link.readlink()
        second = subprocess.run(
            RUN,
            cwd=work,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert second.returncode == 1, second
        assert second.stderr.count("\n") == 1 and f"pid {d.pid}" in second.stderr, second
        assert "state.yaml" in second.stderr
        other = subprocess.run(
            [*RUN, "--state", str(work / "state" / "other.yaml")],
            cwd=work,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert other.returncode == 1 and "in use" in other.stderr, other
        assert other.stderr.count("\n") == 1, other
        assert not (work / "state" / "other.yaml").exists()  # a failed start writes nothing
        assert link.readlink() == target and d.socket.is_socket()
        assert d.ask(cmd="status")["ok"]
        assert d.stop() == 0
    finally:
        d.kill()
    # once the first has exited, the lock is free again (a stale lock file is no obstacle)
    assert (work / "state" / "state.yaml.lock").exists()
    d2 = Daemon(work)
    try:
        assert d2.stop() == 0
    finally:
        d2.kill()


# -- 4. clients that misbehave ---------------------------------------------------


def _exchange(path: Path, data: bytes) -> bytes:
    """Send raw bytes, read until the daemon closes or a second passes quiet."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.connect(str(path))
        s.settimeout(1.0)
        s.sendall(data)
        out = b""
        try:
            while chunk := s.recv(65536):
                out += chunk
                if out.count(b"\n") >= data.count(b"\n") and data.endswith(b"\n"):
                    break
        except TimeoutError:
            pass
    return out


def test_no_request_knocks_the_daemon_over(work: Path) -> None:
    """Every malformed request, whatever its JSON type or nesting, gets an error reply,
    and the daemon answers a good request afterwards."""
    d = Daemon(work)
    bad = [
        b'{"cmd":"status","port":[1]}',
        b"[" * 3000,
        b'{"a":' * 3000,
        b'{"cmd":"status","port":{"x":1}}',
        b'{"cmd":"learn","on":1}',
        b'{"cmd":["status"]}',
        b'{"cmd":"status","extra":true}',
        b'{"cmd":null}',
        b'"status"',
        b"null",
        b"1e999999",
        b'{"cmd":"status","port":"\\ud800"}',
        b"\xff\xfe\x00",
        b"",
    ]
    try:
        for line in bad:
            answer = _exchange(d.socket, line + b"\n")
            assert answer.count(b"\n") == 1 and b'"ok": false' in answer, (line[:40], answer)
        tail = _exchange(d.socket, b"[" * 5000)  # no newline, over the line cap
        assert b"request too long" in tail
        assert d.running
        assert d.ask(cmd="status")["ok"]
        assert d.stop() == 0
    finally:
        d.kill()


def test_client_caps_and_a_read_only_status_socket(work: Path) -> None:
    """The 17th control client is served and closes the one that waited longest (told so),
    the 33rd TCP client evicts the latest before it; the status socket answers status and
    refuses freeze."""
    cfg = work / "emlogd.yaml"
    cfg.write_text(cfg.read_text() + "status_socket: run/status.sock\n")
    port = tcp_port(work)
    d = Daemon(work)
    held: list[socket.socket] = []
    try:
        status_sock = work / "run" / "status.sock"
        assert (status_sock.stat().st_mode & 0o777) == 0o666
        assert request(status_sock, {"cmd": "status"})["ok"]
        refused = request(status_sock, {"cmd": "freeze"})
        assert refused["ok"] is False and "status" in str(refused["error"])
        assert d.uut("emlog1")["learning_enabled"] is True
        for _ in range(16):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(str(d.socket))
            held.append(s)
        held[1].sendall(b'{"cmd":"status"}\n')  # a connected client is served
        held[1].settimeout(5)
        assert b'"ok": true' in held[1].recv(65536)
        extra = _exchange(d.socket, b'{"cmd":"status"}\n')  # the 17th is served too
        assert b'"ok": true' in extra
        held[0].settimeout(5)  # the one waiting longest made room for it
        assert b"too many clients" in held[0].recv(65536)
        tcp = [socket.create_connection(("127.0.0.1", port), timeout=5) for _ in range(40)]
        held += tcp
        closed = 0
        for c in tcp[31:39]:  # each newcomer past 32 evicted the latest before it
            try:
                closed += c.recv(1) == b""
            except ConnectionResetError:
                closed += 1
        assert closed == 8
        for s in held[:16]:
            s.close()
        wait(d.answers, "the control socket did not free its slots")
        assert d.stop() == 0
    finally:
        for s in held:
            s.close()
        d.kill()


def test_out_of_descriptors_the_daemon_pauses_accepting_and_recovers(work: Path) -> None:
    """With its descriptor limit lowered under it (prlimit), TCP clients exhaust the
    daemon's descriptors: accept fails with EMFILE, is reported rate-limited, no busy
    loop kills it, and once the clients leave the control socket answers again."""
    import resource

    d = Daemon(work)
    port = tcp_port(work)
    held: list[socket.socket] = []
    try:
        in_use = len(list(Path(f"/proc/{d.pid}/fd").iterdir()))
        resource.prlimit(d.pid, resource.RLIMIT_NOFILE, (in_use + 4, in_use + 4))
        for _ in range(20):  # connected or not: a paused listener's backlog fills up
            s = socket.socket()
            s.setblocking(False)
            s.connect_ex(("127.0.0.1", port))
            held.append(s)
        time.sleep(1.5)  # many accept failures: pauses, not a busy loop
        assert d.running
        assert not d.answers()  # the control socket's accept fails too: it pauses
        for s in held:  # the clients leave by reset: gone at the daemon's next read
            # (one that ends by FIN is kept TCP_ENDED_QUIET_S as a half-closed reader,
            # tests/emlogd/daemon/test_sinks.py)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            s.close()
        held = []
        wait(d.answers, "the control socket never came back")
        log = d.log_path.read_text()
        assert 1 <= log.count('"event": "accept_error"') <= 2  # reported, rate-limited
        assert log.count('"event": "control_accept_error"') == 1
        assert d.stop() == 0
    finally:
        for s in held:
            s.close()
        d.kill()


def test_an_unbindable_tcp_output_is_a_status_not_a_failure(work: Path) -> None:
    """The TCP output's port is taken at start: the daemon runs, reports it unbound, and
    binds it in the background once the port is free."""
    port = tcp_port(work)
    squatter = socket.socket()
    squatter.bind(("127.0.0.1", port))
    squatter.listen(1)
    d = Daemon(work)
    try:

        def tcp_state() -> str:
            outputs = d.ask(cmd="status")["outputs"]
            assert isinstance(outputs, dict)
            return str(outputs[f"tcp:127.0.0.1:{port}"]["state"])

        assert tcp_state().startswith("unbound: ")
        squatter.close()
        wait(lambda: tcp_state() == "open", "the TCP output was never bound")
        socket.create_connection(("127.0.0.1", port), timeout=5).close()
        assert d.stop() == 0
    finally:
        squatter.close()
        d.kill()


# -- 5. clocks -------------------------------------------------------------------

_STEPPING_DAEMON = """
import sys, time
import structlog
from emlogd.daemon.logsetup import configure_logging
from emlogd.daemon.loop import Daemon

t0 = time.monotonic()

def wall() -> float:  # the wall clock steps back 120 s one second after start
    return time.time() - (120.0 if time.monotonic() - t0 > 1.0 else 0.0)

configure_logging("json")
sys.exit(Daemon("emlogd.yaml", structlog.get_logger("emlogd"), clock=wall).run())
"""


def test_a_wall_clock_stepped_back_stops_no_schedule(work: Path) -> None:
    """The wall clock steps back 120 s under the running daemon (an injected clock):
    WATCHDOG=1 pings go on and the control socket answers."""
    notify = work / "notify.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind(str(notify))
        srv.settimeout(5)
        env = {**os.environ, "NOTIFY_SOCKET": str(notify), "WATCHDOG_USEC": "200000"}
        d = Daemon(work, argv=[sys.executable, "-c", _STEPPING_DAEMON], env=env)
        try:
            time.sleep(1.5)  # past the step
            while True:  # what was sent before now
                srv.settimeout(0.01)
                try:
                    srv.recv(4096)
                except TimeoutError:
                    break
            srv.settimeout(5)
            pings = 0
            end = time.monotonic() + 2.0
            while time.monotonic() < end:
                if srv.recv(4096) == b"WATCHDOG=1":
                    pings += 1
            assert pings >= 5  # every 0.1 s: at least a quarter of them over 2 s
            assert d.ask(cmd="status")["ok"]
            assert d.stop() == 0
        finally:
            d.kill()
