"""The daemon-subprocess harness and the fake sensors, with real processes and ptys."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from emlogd.launch import DaemonProcess, LaunchError, fake_sensors

CONFIG = """\
ports:
  - {name: log, url: missing/log, protocol: nmea0183, role: uut}
  - {name: dvl, url: missing/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: log, reference: dvl}
outputs: {pty: out/emlog0}
state_file: state.yaml
control_socket: run/control.sock
log_format: json
"""


def _python(code: str) -> list[str]:
    return [sys.executable, "-c", code]


def test_a_daemon_is_started_asked_and_stopped(tmp_path: Path) -> None:
    """The harness returns once the control socket answers (the output pty exists by then),
    asks and reads the status, and stop(SIGTERM) returns the daemon's exit code 0."""
    (tmp_path / "emlogd.yaml").write_text(CONFIG)
    d = DaemonProcess("emlogd.yaml", socket="run/control.sock", log="daemon.log", cwd=tmp_path)
    try:
        assert d.running and d.answers()
        assert (tmp_path / "out" / "emlog0").is_symlink()
        assert d.status()["uuts"]["log"]["state"] == "uncalibrated"  # type: ignore[index]
        assert d.ask(cmd="freeze")["ok"] is True
        assert d.ask(cmd="reset", port="nope")["ok"] is False
        assert d.stop() == 0
    finally:
        d.kill()
    assert d.returncode == 0 and not d.answers()
    assert '"event": "ready"' in (tmp_path / "daemon.log").read_text()


def test_the_end_of_a_with_block_stops_the_daemon_with_sigterm(tmp_path: Path) -> None:
    """Leaving the with block (here by an exception) stops the daemon cleanly: exit code 0,
    its pty link removed."""
    (tmp_path / "emlogd.yaml").write_text(CONFIG)
    with pytest.raises(RuntimeError, match="the test's own"):  # noqa: SIM117
        with DaemonProcess(
            tmp_path / "emlogd.yaml", socket="run/control.sock", log="d.log", cwd=tmp_path
        ) as d:
            raise RuntimeError("the test's own")
    assert d.returncode == 0
    assert not (tmp_path / "out" / "emlog0").exists()


def test_a_daemon_that_exits_at_start_fails_with_this_runs_log_tail(tmp_path: Path) -> None:
    """A config the daemon refuses: LaunchError naming the exit code, quoting the end of the
    log this run wrote (not what an earlier run left in it)."""
    (tmp_path / "bad.yaml").write_text(CONFIG.replace("protocol: pd6", "protocol: pd9"))
    (tmp_path / "daemon.log").write_text("an earlier run's last line\n")
    with pytest.raises(LaunchError, match="exited with 1") as info:
        DaemonProcess("bad.yaml", socket="run/control.sock", log="daemon.log", cwd=tmp_path)
    assert "pd9" in info.value.tail and "pd9" in str(info.value)
    assert "earlier run" not in info.value.tail


def test_a_socket_that_never_answers_fails_and_the_process_is_killed(tmp_path: Path) -> None:
    """A command that never opens the socket: LaunchError after the deadline with the tail
    of its output, and no process left behind."""
    pid_file = tmp_path / "pid"
    code = f"import os, time; open({str(pid_file)!r}, 'w').write(str(os.getpid()));"
    code += "print('still starting', flush=True); time.sleep(60)"
    with pytest.raises(LaunchError, match="did not answer within 1 s") as info:
        DaemonProcess(
            "x.yaml", socket="none.sock", log="out.log", cwd=tmp_path, argv=_python(code),
            timeout_s=1.0,
        )  # fmt: skip
    assert "still starting" in info.value.tail
    pid = int(pid_file.read_text())
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # killed and reaped


def test_argv_env_cwd_and_a_separate_error_log(tmp_path: Path) -> None:
    """argv replaces the command, env adds to the environment, cwd is the working directory,
    relative logs are taken from it, and err_log separates stderr from stdout."""
    code = (
        "import os, sys; print(os.getcwd(), os.environ['EMLOGD_X'], 'PATH' in os.environ);"
        "print('to stderr', file=sys.stderr)"
    )
    d = DaemonProcess(
        "c.yaml", socket="s.sock", log="out.log", err_log="err.log", cwd=tmp_path,
        argv=_python(code), env={"EMLOGD_X": "forty-two"}, wait=False,
    )  # fmt: skip
    assert d.proc.wait(20) == 0 and d.stop() == 0  # exited by itself: no signal sent
    assert (tmp_path / "out.log").read_text() == f"{tmp_path} forty-two True\n"
    assert (tmp_path / "err.log").read_text() == "to stderr\n"
    assert d.config == tmp_path / "c.yaml" and d.socket == tmp_path / "s.sock"


def test_stop_kills_a_process_that_ignores_the_signal(tmp_path: Path) -> None:
    """stop() of a process that ignores SIGTERM raises LaunchError once its time is up, and
    the process has been killed (SIGKILL)."""
    code = (
        "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN);"
        "print('armed', flush=True); time.sleep(60)"
    )
    d = DaemonProcess("c.yaml", socket="s.sock", log="o.log", cwd=tmp_path, argv=_python(code),
                      wait=False)  # fmt: skip
    while "armed" not in (tmp_path / "o.log").read_text():
        assert d.running
    with pytest.raises(LaunchError, match=r"did not exit within 0\.5 s"):
        d.stop(timeout_s=0.5)
    assert d.returncode == -signal.SIGKILL


def test_fake_sensors_serve_the_ports_on_one_clock_until_the_block_ends(
    write_capture: Callable[..., Path], tmp_path: Path
) -> None:
    """The ports named are served at links/<port> (the others not), and are gone when the
    block ends."""
    cap = write_capture(
        {"a": "nmea0183", "b": "nmea0183", "c": "nmea0183"},
        [(1.0, "a", b"$A1", False), (1.0, "b", b"$B1", False), (1.0, "c", b"$C1", False)],
    )
    links = tmp_path / "links"
    with fake_sensors(cap, links, ("a", "b"), speed=None) as fake:
        fds = {p: os.open(links / p, os.O_RDONLY | os.O_NOCTTY) for p in ("a", "b")}
        got = dict.fromkeys(fds, b"")
        for port, fd in fds.items():  # serving starts once every link has a reader
            while not got[port].endswith(b"\r\n"):
                got[port] += os.read(fd, 100)
            os.close(fd)
        assert got == {"a": b"$A1\r\n", "b": b"$B1\r\n"}
        assert not (links / "c").exists()
    assert fake.stopped and not (links / "a").exists()
    assert fake.sent == {"a": 1, "b": 1}  # counted once written: read after the join
