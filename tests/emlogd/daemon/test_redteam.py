"""The red team's findings against the live daemon, each pinned: the config and the
state file made hostile (YAML whose constructors raise, nesting past the stack, a FIFO,
a gigabyte), reloads into them, and what the parsers under them must refuse.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon, and bad
input never loses the frozen calibration."""

from __future__ import annotations

import dataclasses
import fcntl
import functools
import json
import os
import signal
import socket
import sys
import time
from pathlib import Path

import pytest

from drivers.errors import ConfigError, DeviceError
from emlogd.calfile import CalibrationFileError, dumps, loads_state
from emlogd.client import request
from emlogd.config import MAX_CONFIG_BYTES, load_config, parse_config
from emlogd.daemon.control import MAX_PIPELINED
from emlogd.daemon.listen import SOURCE_BURST
from emlogd.daemon.logsetup import CLIENT_EVENT_BURST
from emlogd.daemon.statefile import MAX_STATE_BYTES, StateStore
from emlogd.fileio import read_text_bounded
from emlogd.launch import STOP_TIMEOUT_S, fake_sensors
from emlogd.pipeline.calibration import Calibration
from tests.emlogd.daemon.harness import (
    OUTPUTS,
    SPEED,
    Daemon,
    free_port,
    make_work,
    reaped,
    run_daemon,
    saved_calibration,
    tcp_port,
    wait,
)
from tests.sockets import drain, unanswered_port

CONFIG = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}}
calibration:
  - {{uut: emlog1, reference: dvl, lag: 0.165}}
{OUTPUTS}"""
"""One EMlog and a DVL; no sensor needs to be there (the daemon starts without them)."""

F_SETPIPE_SZ = 1031
"""fcntl command setting a pipe's capacity (Linux; not in Python 3.11's fcntl)."""

HOSTILE_YAML = {
    "a date that does not exist": "2001-02-30",
    "a timestamp tag on a word": "!!timestamp x",
    "a hex integer without digits": "!!int 0x",
    "an integer of 5000 digits": "!!int " + "1" * 5000,
    "a float tag on a word": "!!float x",
    "a bool tag on a word": "!!bool x",
    "bad base64": "!!binary x",
    "a python tag": "!!python/object/apply:os.system ['true']",
    "nesting past the stack": "[" * 5000 + "]" * 5000,
}
"""YAML values on which PyYAML's safe loader raises something, most not a YAMLError."""


def _cal(m: float = 0.1) -> Calibration:
    return saved_calibration(m, lag_s=0.165)  # emlog1's configured lag, 3.3 s / SPEED


# -- the parsers: every hostile value is their own error --------------------------------


@pytest.mark.parametrize("value", HOSTILE_YAML.values(), ids=HOSTILE_YAML.keys())
def test_a_hostile_yaml_value_in_a_config_is_a_config_error(value: str) -> None:
    """In a key the config reads, each is a ``ConfigError`` naming the line (it was a
    ValueError, AttributeError, KeyError or RecursionError out of ``parse_config``)."""
    good = CONFIG.replace("{tcp}", "10110")
    parse_config(good)
    text = good.replace("status_log_interval_s: 1", f"status_log_interval_s: {value}")
    with pytest.raises(ConfigError, match=r"^c\.yaml:\d+: (status_log_interval_s|not valid)"):
        parse_config(text, "c.yaml")


@pytest.mark.parametrize("value", HOSTILE_YAML.values(), ids=HOSTILE_YAML.keys())
def test_a_hostile_yaml_value_in_a_state_file_is_damage(value: str) -> None:
    """Anywhere in a state file, each is a ``CalibrationFileError`` (the daemon then uses
    the backup), never another exception."""
    text = dumps({"emlog1": _cal()}).replace("end: true", f"x: {value}\nend: true")
    with pytest.raises(CalibrationFileError):
        loads_state(text)


@pytest.mark.parametrize(
    ("old", "new", "why"),
    [
        ("  m: 0.1\n", "  m: " + "9" * 400 + "\n", "finite number"),
        ("    - - 0.0001\n", "    - - 0.0001\n      - 0.0\n", "square"),
        ("  m: 0.1\n", "  m: 0.1\n      1: 0.0\n", "params"),
        ("    extra: {}\n", "    extra: {}\n    two_axis: {1: 0.0, m_t: 0.0}\n", "two_axis"),
    ],
    ids=[
        "an integer past a float",
        "a ragged covariance",
        "a number for a parameter name",
        "a number for a two-axis name",
    ],
)
def test_a_state_record_of_the_wrong_shape_is_damage(old: str, new: str, why: str) -> None:
    """An integer no float holds (OverflowError), a covariance row longer than the others
    (numpy's ValueError in the check), a parameter or a two-axis figure named by a number
    (TypeError when sorted): each a ``CalibrationFileError`` naming what is wrong."""
    text = dumps({"emlog1": _cal()})
    assert old in text
    with pytest.raises(CalibrationFileError, match=why):
        loads_state(text.replace(old, new, 1))


def test_the_bounded_read_refuses_a_fifo_a_directory_and_a_long_file(tmp_path: Path) -> None:
    """No wait on a FIFO without a writer, no gigabyte read; a regular file within the
    bound reads whole."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big"
    with open(big, "wb") as f:
        f.truncate(1 << 30)  # sparse: a gigabyte that costs no disk
    for path, why in ((fifo, "not a regular file"), (tmp_path, "not a regular file")):
        with pytest.raises(OSError, match=why):
            read_text_bounded(path, 100)
    with pytest.raises(OSError, match="longer than 100 bytes"):
        read_text_bounded(big, 100)
    (tmp_path / "ok").write_text("x" * 100)
    assert read_text_bounded(tmp_path / "ok", 100) == "x" * 100


def test_a_config_too_long_or_a_fifo_is_refused_by_load_config(tmp_path: Path) -> None:
    """``load_config`` reads through the bound (:data:`MAX_CONFIG_BYTES`)."""
    long = tmp_path / "long.yaml"
    long.write_text(CONFIG.replace("{tcp}", "10110") + "#" * MAX_CONFIG_BYTES)
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    for path in (long, fifo):
        with pytest.raises(ConfigError, match="cannot read the config"):
            load_config(path)


# -- the live daemon ---------------------------------------------------------------------


def _log(d: Daemon) -> list[dict[str, object]]:
    """The daemon's JSON log lines."""
    return [json.loads(x) for x in d.log_path.read_text().splitlines() if x.startswith("{")]


def _failed_reloads(d: Daemon, n: int) -> bool:
    return d.events("reload_failed") >= n


def _work(tmp_path: Path) -> Path:
    return make_work(tmp_path, CONFIG)


def test_reloads_into_hostile_configs_keep_the_running_one(tmp_path: Path) -> None:
    """SIGHUP into each hostile value, a FIFO, a config past the bound, one with a URL
    pyserial does not know (``socet://``) and ones with a NUL character in the pty's,
    the control socket's or the status socket's path: every one a ``reload_failed`` with
    the running config kept and the daemon answering (a date ``2001-02-30`` made it exit
    1, a FIFO would have hung it, the URL and the NULs ended it with exit code 1 once
    the new config was taken); a NUL in ``pty_group`` (which ended it too) is a
    ``reload_outputs_failed`` of that pty; a good config after them reloads."""
    work = _work(tmp_path)
    cfg = work / "emlogd.yaml"
    good = cfg.read_text()
    d = Daemon(work)
    try:
        bad = [
            good.replace("status_log_interval_s: 1", f"status_log_interval_s: {v}")
            for v in HOSTILE_YAML.values()
        ]
        bad.append(good + "#" * MAX_CONFIG_BYTES)
        bad.append(good.replace("url: links/dvl", "url: 'socet://127.0.0.1:1'"))
        for path in ("pty: out/emlog0", "control_socket: run/control.sock"):
            key, value = path.split(": ")
            bad.append(good.replace(path, f'{key}: "{value}\\0"'))
        bad.append(good + 'status_socket: "run/status\\0.sock"\n')
        for n, text in enumerate([*bad, None], start=1):
            cfg.unlink()
            if text is None:
                os.mkfifo(cfg)
            else:
                cfg.write_text(text)
            d.send_signal(signal.SIGHUP)
            wait(functools.partial(_failed_reloads, d, n), f"reload_failed #{n}", 10.0)
            assert d.running and d.answers(), d.tail()
        cfg.unlink()
        cfg.write_text(good.replace("pty: out/emlog0", 'pty: out/emlog0, pty_group: "a\\0"'))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reload_outputs_failed") >= 1, "the pty refused", 10.0)
        assert d.running and d.answers(), d.tail()
        cfg.write_text(good.replace("status_log_interval_s: 1", "status_log_interval_s: 2"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 2, "the good config reloaded", 10.0)
        assert d.stop() == 0
    finally:
        d.kill()


@pytest.mark.parametrize(
    "damage",
    ["a date that does not exist", "nesting past the stack", "fifo", "a gigabyte"],
)
def test_a_hostile_state_file_starts_from_the_backup(tmp_path: Path, damage: str) -> None:
    """The state file damaged so that its parser raised (a date ``2001-02-30``: the daemon
    exited 1 at start, its good backup unused) or its read would block (a FIFO) or take
    a gigabyte: the daemon starts on the backup's calibration, then moves the bad file
    aside at its first save, the backup kept."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal(0.1)})
    store.save({"emlog1": _cal(0.2)})  # the backup: m = 0.1; the current file: m = 0.2
    backup = store.backup.read_bytes()
    store.path.unlink()
    if damage == "fifo":
        os.mkfifo(store.path)
    elif damage == "a gigabyte":
        with open(store.path, "wb") as f:
            f.truncate(1 << 30)
    else:
        text = dumps({"emlog1": _cal(0.2)})
        store.path.write_text(text.replace("end: true", f"x: {HOSTILE_YAML[damage]}\nend: true"))
    assert store.path.lstat().st_size <= 1 << 30
    d = Daemon(work)
    try:
        assert d.events("state_file") >= 1
        assert "using the backup" in d.log_path.read_text()
        loaded = [e for e in _log(d) if e.get("event") == "calibration_loaded"]
        assert [(e["uut"], e["m"]) for e in loaded] == [("emlog1", 0.1)], loaded
        assert d.ask(cmd="freeze", port="emlog1").get("ok") is True, d.tail()
        assert store.refused.exists() and store.backup.read_bytes() == backup
        assert d.stop() == 0
    finally:
        d.kill()


@pytest.mark.parametrize("planted", ["fifo", "directory"])
def test_a_fifo_planted_as_the_state_file_of_the_running_daemon(
    tmp_path: Path, planted: str
) -> None:
    """A FIFO put where the running daemon's state file is: its next save (a ``reset``)
    does not block on it (it hung the daemon for good), moves it aside and writes.

    A directory holding a file put there instead: the ``reset`` answers that the state
    file was not written and ``state_errors`` counts it; the directory and its file stay
    where they are, the daemon runs on and exits 0. The save moved the directory aside
    to ``.refused`` with its files, as it does a damaged file, and wrote the state file
    in its place (a ``state_file`` ending in ``/`` moved the directory it named)."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal()})
    d = Daemon(work)
    try:
        store.path.unlink()
        if planted == "fifo":
            os.mkfifo(store.path)
        else:
            store.path.mkdir()
            (store.path / "notes.txt").write_text("kept")
        answer = d.ask(cmd="reset", port="emlog1")  # a material change: written at once
        if planted == "fifo":
            assert answer.get("ok") is True, answer
            assert store.path.is_file() and store.refused.exists()
            assert loads_state(store.path.read_text())[0]["emlog1"].reset
        else:
            assert answer.get("ok") is False and "not written" in str(answer["error"]), answer
            assert (store.path / "notes.txt").read_text() == "kept"
            assert not store.refused.exists()
            assert d.ask(cmd="status")["state_errors"] == 1
        assert d.stop() == 0
    finally:
        d.kill()


def test_a_directory_planted_as_the_backup_costs_the_backup_alone(tmp_path: Path) -> None:
    """A directory holding a file put where the running daemon's ``.bak`` goes: a
    ``reset`` is written all the same (answered ok, the state file holds it,
    ``state_errors`` 0), the log says ``state_backup_failed`` with the directory, which
    stays with its file. Before, every save failed for good (``state_errors`` counted
    each), and what was learnt after was lost at the next restart."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal()})
    d = Daemon(work)
    try:
        store.backup.unlink(missing_ok=True)
        store.backup.mkdir()
        (store.backup / "notes.txt").write_text("kept")
        assert d.ask(cmd="reset", port="emlog1").get("ok") is True, d.tail()
        assert loads_state(store.path.read_text())[0]["emlog1"].reset
        assert d.ask(cmd="status")["state_errors"] == 0
        failed = [e for e in _log(d) if e.get("event") == "state_backup_failed"]
        assert failed and str(store.backup) in str(failed[0]["why"]), failed
        assert (store.backup / "notes.txt").read_text() == "kept"
        assert d.stop() == 0
    finally:
        d.kill()


def test_the_state_bound_holds_a_full_state_file() -> None:
    """The bound is far above what a state file holds: eight UUTs with their records of
    all four models."""
    cals = {f"u{k}": dataclasses.replace(_cal(), uut=f"u{k}") for k in range(8)}
    assert len(dumps(cals).encode()) * 4 < MAX_STATE_BYTES


def test_the_log_reader_gone_costs_log_lines_not_the_daemon(tmp_path: Path) -> None:
    """The daemon's stdout and stderr a pipe whose reader closes (journald stopped,
    ``emlogd run | tee`` killed): it runs on, answers, counts the lines it could not write
    (``log_lines_lost``) and stops with 0 on SIGTERM. A ``BrokenPipeError`` out of the
    next log line ended it with exit code 0, which systemd does not restart."""
    work = _work(tmp_path)
    r, w = os.pipe()
    sock = work / "run" / "control.sock"
    try:
        with reaped(run_daemon(work, w)) as proc:
            os.close(w)
            wait(functools.partial(_answers, sock), "the control socket")
            os.close(r)
            r = -1
            wait(lambda: _lost(sock) >= 3, "three status lines lost", 10.0)  # one a second
            assert proc.poll() is None
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(STOP_TIMEOUT_S) == 0
    finally:
        if r >= 0:
            os.close(r)


def _answers(sock: Path) -> bool:
    try:
        return request(sock, {"cmd": "status"}, timeout_s=1.0).get("ok") is True
    except DeviceError:
        return False


def _lost(sock: Path) -> int:
    n = request(sock, {"cmd": "status"}, timeout_s=1.0).get("log_lines_lost")
    assert isinstance(n, int)
    return n


def _sentences(sock: Path) -> dict[str, tuple[int, int]]:
    """(sentences, errors) of each output."""
    outputs = request(sock, {"cmd": "status"}, timeout_s=1.0)["outputs"]
    assert isinstance(outputs, dict)
    return {k: (v["sentences"], v["errors"]) for k, v in outputs.items()}


def test_a_stdout_reader_that_stops_reading_costs_its_sentences_only(
    tmp_path: Path, trial_files: dict[str, Path]
) -> None:
    """``outputs.stdout`` into a pipe (one page) that nobody reads: once it is full the
    stdout sentences are dropped and counted as errors, and the pty output and the
    control socket go on. The blocking write hung the whole daemon within seconds."""
    work = make_work(tmp_path, CONFIG.replace("outputs: {", "outputs: {stdout: true, "))
    r, w = os.pipe()
    fcntl.fcntl(w, F_SETPIPE_SZ, 4096)  # one page: full from its first sentence on
    sock = work / "run" / "control.sock"
    with (
        fake_sensors(trial_files["figure-8"], work / "links", ("emlog1", "dvl"), speed=SPEED),
        open(work / "daemon.log", "wb") as log,
    ):
        try:
            with reaped(run_daemon(work, w, log)) as proc:
                os.close(w)
                wait(functools.partial(_answers, sock), "the control socket")
                flags = os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK
                reader = os.open(work / "out" / "emlog0", flags)
                try:
                    wait(lambda: _sentences(sock)["stdout"][1] > 0, "stdout full", 30.0)
                    drain(reader)
                    time.sleep(2.0)
                    assert drain(reader).count(b"\r\n") >= 10  # the pty goes on
                finally:
                    os.close(reader)
                assert _answers(sock)
                proc.send_signal(signal.SIGTERM)
                assert proc.wait(STOP_TIMEOUT_S) == 0
        finally:
            os.close(r)


def test_a_tcp_connect_loop_costs_a_bounded_number_of_log_lines(tmp_path: Path) -> None:
    """``SOURCE_BURST`` TCP clients (64, what one address may open at once) connecting and
    closing in a loop: at most ``CLIENT_EVENT_BURST`` lines of each client event per
    interval (each of the 128 was a line: a journal that rate-limits the service then
    drops the daemon's other lines too); the daemon answers."""
    work = _work(tmp_path)
    d = Daemon(work)
    try:
        for _ in range(SOURCE_BURST):
            socket.create_connection(("127.0.0.1", tcp_port(work))).close()
            time.sleep(0.002)  # within the listen backlog: no SYN dropped and retried
        wait(lambda: d.events("client_disconnected") >= CLIENT_EVENT_BURST, "disconnects", 10.0)
        assert d.answers()
        assert d.events("client_connected") == CLIENT_EVENT_BURST
        assert d.events("client_disconnected") == CLIENT_EVENT_BURST
        assert d.stop() == 0
    finally:
        d.kill()


FULL_DISK = """\
import resource, runpy, sys
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
sys.argv = ["emlogd", "run", "--config", "emlogd.yaml"]
runpy.run_module("emlogd", run_name="__main__")
"""
"""``emlogd run`` whose files cannot grow past ``limit`` bytes (``EFBIG``, as a full disk
gives ``ENOSPC``; Python ignores the SIGXFSZ that comes with it)."""


def test_a_full_disk_for_the_log_and_the_state_without_root(tmp_path: Path) -> None:
    """No file of the daemon may pass 400 bytes (RLIMIT_FSIZE: a full disk without root or
    a tmpfs): the log stops growing and the state file cannot be written. The daemon runs
    on and answers; a ``reset`` says the state was not written; the status counts
    ``state_errors`` and ``log_lines_lost``; the state file is byte-identical and SIGTERM
    exits 0. The log's ``EFBIG`` ended the daemon before log writes were contained."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal()})
    saved = store.path.read_bytes()
    assert len(saved) > 400
    argv = [sys.executable, "-c", FULL_DISK.format(limit=400)]
    d = Daemon(work, argv=argv, env={"PYTHONPATH": os.pathsep.join(sys.path)})
    try:
        answer = d.ask(cmd="reset", port="emlog1")
        assert answer.get("ok") is False and "not written" in str(answer.get("error")), answer
        resp = d.ask(cmd="status")
        assert resp["state_errors"] == 1
        wait(lambda: _lost(d.socket) > 0, "log lines lost", 10.0)
        assert store.path.read_bytes() == saved
        assert d.stop() == 0
    finally:
        d.kill()


def test_pipelined_status_requests_cannot_hold_the_loop(tmp_path: Path) -> None:
    """240 ``status`` requests in one write (any local user can, on the status socket):
    at most ``MAX_PIPELINED`` answers, then an error line and the close, the daemon
    answering on. All 240 were answered from one read, about a millisecond each, the
    loop — and the logs' corrected sentences — held meanwhile (265 ms measured)."""
    work = _work(tmp_path)
    d = Daemon(work)
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(5.0)
            s.connect(str(d.socket))
            s.sendall(b'{"cmd":"status"}\n' * 240)
            data = b""
            while chunk := s.recv(1 << 16):
                data += chunk
        lines = [json.loads(x) for x in data.splitlines()]
        assert [x["ok"] for x in lines] == [True] * MAX_PIPELINED + [False], lines[-1]
        assert "requests at once" in lines[-1]["error"]
        assert d.answers()
        assert d.stop() == 0
    finally:
        d.kill()


def test_a_socket_input_whose_connect_goes_unanswered_stalls_nothing(tmp_path: Path) -> None:
    """The EMlog on ``socket://`` and the DVL on ``SOCKET://`` to a port whose listen
    queue is full (a SYN dropped, as by a host that is off): the daemon answers every
    status request at once for 3 s, both ports ``connecting``. pyserial's connect waited
    up to 5 s in the daemon's one thread at each retry (5.01 s measured), every output
    with it. The scheme in capitals (pyserial takes any case) went to pyserial's open:
    status requests 5.04 s, the start 11 s."""
    with unanswered_port() as port:
        config = CONFIG.replace("url: links/emlog1", f"url: 'socket://127.0.0.1:{port}'")
        config = config.replace("url: links/dvl", f"url: 'SOCKET://127.0.0.1:{port}'")
        work = make_work(tmp_path, config)
        d = Daemon(work)
        try:
            worst = 0.0
            end = time.monotonic() + 3.0
            while time.monotonic() < end:
                t0 = time.monotonic()
                state = d.status()["ports"]
                worst = max(worst, time.monotonic() - t0)
                time.sleep(0.05)
            assert worst < 1.0, worst
            assert isinstance(state, dict)
            for name in ("emlog1", "dvl"):
                assert "connecting" in str(state[name]["why_closed"]), state[name]
            assert d.stop() == 0
        finally:
            d.kill()


def test_a_reload_whose_pty_cannot_be_published_still_opens_the_other_outputs(
    tmp_path: Path,
) -> None:
    """SIGHUP into a config whose pty path cannot be published (under a file) and that adds
    a UDP output after it: ``reload_outputs_failed`` for the pty (the status says why it
    is not open), and the UDP output open all the same. The pty's failure left every
    output after it closed until the next reload."""
    work = _work(tmp_path)
    d = Daemon(work)
    try:
        cfg = work / "emlogd.yaml"
        tcp = f'tcp: "127.0.0.1:{tcp_port(work)}"'
        udp = f"127.0.0.1:{free_port()}"
        text = cfg.read_text().replace("pty: out/emlog0", "pty: emlogd.yaml/emlog0")
        cfg.write_text(text.replace(tcp, f'{tcp}, udp: "{udp}"'))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reload_outputs_failed") == 1, "reload_outputs_failed", 10.0)
        outputs = d.ask(cmd="status")["outputs"]
        assert isinstance(outputs, dict)
        pty = f"pty:{work / 'emlogd.yaml' / 'emlog0'}"
        assert sorted(outputs) == [pty, f"tcp:127.0.0.1:{tcp_port(work)}", f"udp:{udp}"], outputs
        assert outputs[f"udp:{udp}"]["state"] == "open"
        assert str(outputs[pty]["state"]).startswith("not open: cannot publish")
        assert d.stop() == 0
    finally:
        d.kill()


def test_a_reload_to_an_unusable_control_socket_keeps_the_running_one(tmp_path: Path) -> None:
    """SIGHUP into a config whose control socket cannot be created (under a file): the
    running socket answers on (``reload_control_failed``; it was closed first, leaving
    the operators no socket at all); a reload to a usable path then moves it there."""
    work = _work(tmp_path)
    d = Daemon(work)
    try:
        cfg = work / "emlogd.yaml"
        good = cfg.read_text()
        cfg.write_text(
            good.replace("control_socket: run/control.sock", "control_socket: emlogd.yaml/c")
        )
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reload_control_failed") == 1, "reload_control_failed", 10.0)
        assert d.answers()
        cfg.write_text(good.replace("control_socket: run/control.sock", "control_socket: run/c2"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") == 2, "the second reload", 10.0)
        assert not d.socket.exists()
        assert _answers(work / "run" / "c2")
        d.socket = work / "run" / "c2"
        assert d.stop() == 0
    finally:
        d.kill()
