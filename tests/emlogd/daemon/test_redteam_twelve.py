"""The twelfth red team's findings against the live daemon, each pinned: inputs that are
not what their path promises.

Rule kept (README, docs/RELIABILITY.md): no record and no file stops the daemon, the
status tells the truth, nothing worse than raw reaches the autopilot."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

from drivers.io.port import DEVICE_CHECK_S
from tests.emlogd.daemon.harness import Daemon, make_work, raw_pty, wait
from tests.emlogd.daemon.test_redteam_live import VHW

NOT_DEVICES_CONFIG = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}
  - {name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut}
  - {name: dvl, url: links/dvl, protocol: pd0, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.2}
  - {uut: emlog2, reference: dvl, lag: 0.2, talker: VM, pty: out/emlog2}
outputs: {pty: out/emlog0}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
"""
"""Two EMlogs and a DVL, each input's path given a file that is no device."""

IDLE_S = 3.0
"""How long the daemon's CPU time is measured while its inputs are refused."""

IDLE_CPU_S = 0.5
"""The CPU time the daemon may spend over :data:`IDLE_S` (a spin on a refused input
would take all of it; measured 0.02 s over 20 s, 2026-11-28)."""

BACKOFF_MAX_S = 5.0
"""The port's longest retry delay (``SerialSource.backoff_s``' last)."""


def _fds(pid: int) -> int:
    """How many file descriptors process ``pid`` holds."""
    return sum(1 for _ in Path(f"/proc/{pid}/fd").iterdir())


def _cpu_s(pid: int) -> float:
    """The user and system CPU time of process ``pid``, s."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_a_fifo_a_file_or_a_socket_at_an_input_path_is_refused_and_said(
    tmp_path: Path,
) -> None:
    """A FIFO at the first EMlog's path (an operator's ``mkfifo`` to feed a capture), a
    regular file at the second's (a capture copied where the device belongs), a
    listening unix socket at the DVL's: the daemon starts and answers, each port is
    ``not open`` saying what the file is, retried with backoff without spinning (CPU
    time, file descriptors steady, one ``port_disconnected`` line each); the device put
    back at the FIFO's path is read within the backoff. The status said pyserial's
    termios error (``Could not configure port: (25, 'Inappropriate ioctl for
    device')``) for the FIFO and the file."""
    work = make_work(tmp_path, NOT_DEVICES_CONFIG)
    links = work / "links"
    os.mkfifo(links / "emlog1")
    (links / "emlog2").write_bytes(VHW[0] * 100)
    with socket.socket(socket.AF_UNIX) as listener:
        listener.bind(str(links / "dvl"))
        listener.listen(1)
        d = Daemon(work)
        master = -1
        try:
            ports = d.status()["ports"]
            assert isinstance(ports, dict)
            for name, kind in (
                ("emlog1", "a FIFO"),
                ("emlog2", "a regular file"),
                ("dvl", "a socket"),
            ):
                assert ports[name]["state"] == "not open", ports[name]
                assert f"{links / name}: {kind}, not a serial device" in ports[name]["why_closed"]
            cpu0, fds0 = _cpu_s(d.pid), _fds(d.pid)
            time.sleep(IDLE_S)
            assert _cpu_s(d.pid) - cpu0 < IDLE_CPU_S
            assert _fds(d.pid) <= fds0  # a status client may have left
            assert d.events("port_disconnected") == 3
            (links / "emlog1").unlink()
            master = raw_pty(links / "emlog1")

            def read() -> bool:
                os.write(master, VHW[0])
                ports = d.status()["ports"]
                assert isinstance(ports, dict)
                return int(ports["emlog1"]["records"]) > 0

            wait(read, "the EMlog read once its device is back", BACKOFF_MAX_S + DEVICE_CHECK_S)
            assert d.stop() == 0
        finally:
            d.kill()
            if master >= 0:
                os.close(master)
