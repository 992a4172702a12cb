"""The eleventh red team's findings against the live daemon, each pinned.

Rule kept (README, docs/RELIABILITY.md): no lock-out of the autopilot or the operator; a
client costs itself, never the process or the other clients."""

from __future__ import annotations

import dataclasses
import errno
import json
import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest
import structlog

from emlogd.client import request
from emlogd.daemon import statefile
from emlogd.daemon.control import PATH_CHECK_S, Deferred
from emlogd.daemon.loop import Daemon as LoopDaemon
from emlogd.daemon.outputs import OUTPUT_RETRY_S
from emlogd.daemon.statefile import STATE_RETRY_S, StateStore
from emlogd.launch import STOP_TIMEOUT_S
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    free_port,
    make_work,
    raw_pty,
    reaped,
    run_daemon,
    saved_calibration,
    wait,
)
from tests.emlogd.daemon.test_lockout import _first_sentence
from tests.emlogd.daemon.test_redteam import _answers
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon
from tests.emlogd.daemon.test_redteam_reload import TWO_LOGS, _saved, _without_emlog2

STORM_S = 3.0
"""How long the commands and the SIGHUPs storm the daemon."""


def _with_tcp_output(tmp_path: Path) -> tuple[int, Path]:
    """A work folder for :data:`PD0_CONFIG` with a TCP output beside the pty, and its port."""
    port = free_port()
    config = PD0_CONFIG.replace(
        "outputs: {pty: out/emlog0}", f'outputs: {{pty: out/emlog0, tcp: "127.0.0.1:{port}"}}'
    )
    return port, make_work(tmp_path, config)


def test_a_tcp_reader_that_half_closes_is_served(tmp_path: Path) -> None:
    """A reader of the TCP output that ends its sending at once (``shutdown(SHUT_WR)``:
    ``nc -N``, a script whose input is empty) receives the corrected VHW beside a plain
    reader, and the output counts it a client. The daemon took its end of file for a
    close: the reader got nothing, ``client_disconnected`` at once."""
    port, work = _with_tcp_output(tmp_path)
    with _pd0_daemon(work) as (d, emlog):
        half = socket.create_connection(("127.0.0.1", port), timeout=5)
        plain = socket.create_connection(("127.0.0.1", port), timeout=5)
        with half, plain:
            half.shutdown(socket.SHUT_WR)
            time.sleep(0.3)  # the daemon reads the end of file
            for k in range(10):
                os.write(emlog, VHW[k % 2])
                time.sleep(0.1)
            assert _first_sentence(half, 3.0) < 3.0
            assert _first_sentence(plain, 3.0) < 3.0
            outputs = d.ask(cmd="status")["outputs"]
            assert isinstance(outputs, dict)
            assert outputs[f"tcp:127.0.0.1:{port}"]["clients"] == 2
        assert d.stop() == 0


def _commands(sock: Path, until: float, tally: dict[str, int]) -> None:
    """``freeze``, ``learn`` and ``status`` (of emlog2 every other time) and a ``reset``
    of emlog1, one after the other as fast as they are answered, until ``until``."""
    cmds = ["freeze", "learn", "status", "freeze", "reset"]
    k = 0
    while time.monotonic() < until:
        req: dict[str, object] = {"cmd": cmds[k % len(cmds)]}
        req["port"] = "emlog1" if req["cmd"] == "reset" or k % 2 else "emlog2"
        k += 1
        try:
            answer = request(sock, req, timeout_s=5.0)
        except OSError:
            tally["unanswered"] += 1
            continue
        why = str(answer.get("error", ""))
        tally["ok" if answer.get("ok") else "no_uut" if "no UUT" in why else "other"] += 1


def test_commands_and_sighups_at_100_a_second_lose_no_calibration(tmp_path: Path) -> None:
    """For 3 s a client sends ``freeze``/``learn``/``status``/``reset`` as fast as they
    are answered while SIGHUPs come every 10 ms into configs with emlog2 and without it
    (its log away, then back, in turns): every request is answered (ok, or "no UUT" while
    emlog2 is out), the daemon reloads, exits 0, and emlog2's frozen calibration is in
    the state file at the end."""
    work = make_work(tmp_path, TWO_LOGS)
    cfg = work / "emlogd.yaml"
    both = cfg.read_text()
    configs = (both, _without_emlog2(both))
    store = StateStore(work / "state" / "state.yaml")
    one = saved_calibration(0.1, lag_s=0.165)
    two = dataclasses.replace(one, uut="emlog2", estimate=saved_calibration(0.2).estimate)
    store.save({"emlog1": one, "emlog2": two})
    d = Daemon(work)
    try:
        tally = dict.fromkeys(("ok", "no_uut", "other", "unanswered"), 0)
        until = time.monotonic() + STORM_S
        client = threading.Thread(target=_commands, args=(d.socket, until, tally))
        client.start()
        k = 0
        while time.monotonic() < until:
            staged = cfg.with_name("next.yaml")
            staged.write_text(configs[k % 2])
            staged.replace(cfg)  # whole: a reload never reads half a config
            d.send_signal(signal.SIGHUP)
            k += 1
            time.sleep(0.01)
        client.join()
        cfg.write_text(both)
        d.send_signal(signal.SIGHUP)
        time.sleep(1.0)  # the last reload, RELOAD_MIN_S after the one before
        assert tally["other"] == tally["unanswered"] == 0, tally
        assert tally["ok"] > 20, tally
        assert d.events("reloaded") >= 2 and d.events("reload_failed") == 0
        assert d.ask(cmd="freeze", port="emlog2").get("ok") is True, d.tail()
        assert d.stop() == 0
    finally:
        d.kill()
    assert _saved(store).get("emlog2") == 0.2, _saved(store)


def test_a_file_at_the_pty_path_costs_the_pty_alone(tmp_path: Path) -> None:
    """A regular file at the output pty's path when the daemon starts (an operator's
    ``echo … > /run/emlogd/emlog0`` while it was stopped): the daemon starts, the TCP
    output serves the corrected VHW, the status says why the pty is not open; once the
    file is gone the pty is published within ``OUTPUT_RETRY_S`` (``output_opened``).
    The start ended with exit code 1, ``cannot publish …: exists and is not a symlink``:
    under systemd a restart loop, no output at all, for as long as the file was there."""
    port, work = _with_tcp_output(tmp_path)
    link = work / "out" / "emlog0"
    link.write_text("$VWVHW,,T,,M,5.00,N,,K*00\n")
    emlog, dvl = (raw_pty(work / "links" / name) for name in ("emlog1", "dvl"))
    d = Daemon(work)
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as reader:
            for k in range(10):
                os.write(emlog, VHW[k % 2])
                time.sleep(0.1)
            assert _first_sentence(reader, 3.0) < 3.0
        outputs = d.ask(cmd="status")["outputs"]
        assert isinstance(outputs, dict)
        assert "exists and is not a symlink" in outputs[f"pty:{link}"]["state"], outputs
        link.unlink()
        wait(lambda: link.is_symlink(), "the pty published", OUTPUT_RETRY_S + 5.0)
        assert d.events("output_opened") == 1
        outputs = d.ask(cmd="status")["outputs"]
        assert isinstance(outputs, dict) and outputs[f"pty:{link}"]["state"] == "open"
        assert d.stop() == 0
    finally:
        d.kill()
        os.close(emlog)
        os.close(dvl)


def test_a_file_at_the_control_socket_path_costs_the_socket_alone(tmp_path: Path) -> None:
    """A regular file at the control socket's path when the daemon starts (an operator's
    ``echo '{"cmd":"status"}' > /run/emlogd/control.sock`` while it was stopped): the
    daemon starts and its TCP output serves the corrected VHW, the log says why there is
    no socket (``control_socket_path``); once the file is gone the socket is made within
    ``PATH_CHECK_S`` and answers, and SIGTERM exits 0. The start ended with exit code 1
    (``control socket …: Address already in use``): a restart loop, no output at all."""
    port, work = _with_tcp_output(tmp_path)
    sock = work / "run" / "control.sock"
    sock.write_text('{"cmd":"status"}\n')
    emlog, dvl = (raw_pty(work / "links" / name) for name in ("emlog1", "dvl"))
    try:
        with (work / "daemon.log").open("wb") as log, reaped(run_daemon(work, log)) as proc:
            wait(lambda: (work / "out" / "emlog0").is_symlink(), "the daemon started", 20.0)
            with socket.create_connection(("127.0.0.1", port), timeout=5) as reader:
                for k in range(10):
                    os.write(emlog, VHW[k % 2])
                    time.sleep(0.1)
                assert _first_sentence(reader, 3.0) < 3.0
            assert "control_socket_path" in (work / "daemon.log").read_text()
            sock.unlink()
            # answering, not only there: the daemon binds (the file appears) then listens
            wait(lambda: _answers(sock), "the control socket made", PATH_CHECK_S + 5.0)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(STOP_TIMEOUT_S) == 0
    finally:
        os.close(emlog)
        os.close(dvl)


def test_a_save_that_failed_is_tried_again_until_it_is_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The state file's writes failing with ``ENOSPC`` (injected where the file is
    written) when a ``reset`` is asked: answered that it was not written; once writes
    work again the state file holds the reset within ``STATE_RETRY_S`` of housekeeping,
    with nothing more asked. The save was never tried again before the stop: a power
    cut meanwhile, and the next start loaded what the operator had reset (the same for
    a ``freeze``: the calibration frozen in memory only)."""
    work = make_work(tmp_path, TWO_LOGS)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": saved_calibration(0.1, lag_s=0.165)})
    clock = [1000.0]
    daemon = LoopDaemon(work / "emlogd.yaml", structlog.get_logger("t"), monotonic=lambda: clock[0])
    daemon._start()
    try:

        def full(path: Path, data: bytes, mode: int = 0o640) -> None:
            raise OSError(errno.ENOSPC, "No space left on device")

        def landed() -> None:  # the loop's part: the writer thread's results handled
            assert daemon.saves is not None and daemon.saves.saver.wait_idle(5.0)
            daemon.saves.landed()

        monkeypatch.setattr(statefile, "write_synced", full)
        answer = daemon._control({"cmd": "reset", "port": "emlog1"})
        assert isinstance(answer, Deferred)
        assert not answer.line  # it waits for the save
        landed()
        line = answer.line or b"{}"
        assert b"not written" in line and json.loads(line)["ok"] is False, line
        daemon._housekeep()  # the pipeline hands the reset out to persist: it fails too
        landed()
        assert daemon.state_errors == 2
        monkeypatch.undo()
        daemon._housekeep()  # nothing more asks for a save
        landed()
        assert _saved(store).get("emlog1") == 0.1
        clock[0] += STATE_RETRY_S
        daemon._housekeep()
        landed()
        assert "emlog1" not in _saved(store), _saved(store)  # the reset is on disk
        assert daemon.state_errors == 2
    finally:
        daemon._shutdown()
        os.close(daemon._wake_r)
        os.close(daemon._wake_w)
