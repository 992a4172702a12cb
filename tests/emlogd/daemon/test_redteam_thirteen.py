"""The thirteenth red team's findings, each pinned: the live daemon, and sensors that
lie in ways the twelfth did not try, edited into the simulated trial's captures and
replayed against the truth.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon, nothing
worse than raw reaches the autopilot (every 5-min window's RMSE of the emitted speed
against the true speed through the water at most raw's × ``RATIO``). The worlds
(:data:`WORLDS13`, built and judged as
:func:`tests.emlogd.daemon.test_redteam_twelve.measure_world` does) are ``soak``; their
figures are in docs/RELIABILITY.md, measured by running this file as a script::

    PYTHONPATH=. python tests/emlogd/daemon/test_redteam_thirteen.py [WORLD ...]
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import sys
import tempfile
import threading
import time
import tty
from pathlib import Path
from typing import cast

import pytest

from emlogd.client import request
from emlogd.daemon.outputs import OUTPUT_RETRY_S
from emlogd.launch import STOP_TIMEOUT_S
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    make_work,
    raw_pty,
    reaped,
    run_daemon,
    wait,
)
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon
from tests.emlogd.daemon.test_redteam_reload import TWO_LOGS
from tests.emlogd.daemon.test_redteam_twelve import (
    FAULT_S,
    RATIO,
    Edit,
    Record,
    World,
    _fields,
    _nmea,
    measure_world,
)
from tests.sockets import drain


def test_a_watchdog_interval_of_a_digit_int_cannot_read_is_no_watchdog(tmp_path: Path) -> None:
    """``WATCHDOG_USEC=²`` (a unit's ``Environment=`` line, a superscript typed for a
    square): the daemon starts, says ``READY=1``, decodes its EMlog and exits 0, with no
    watchdog. ``str.isdigit`` takes ``²`` for a digit and ``int`` refused it: the start
    ended with ``internal error: ValueError`` (exit 1, a restart loop under systemd)."""
    work = make_work(tmp_path, PD0_CONFIG)
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify:
        notify.bind(str(work / "notify.sock"))
        notify.settimeout(5.0)
        env = {**os.environ, "NOTIFY_SOCKET": str(work / "notify.sock"), "WATCHDOG_USEC": "²"}
        with _pd0_daemon(work, env) as (d, emlog):
            assert notify.recv(4096) == b"READY=1"
            for k in range(5):
                os.write(emlog, VHW[k % 2])
            d.pump(1.0)
            assert any(line.startswith(b"$VWVHW") for line in d.lines)
            assert d.stop() == 0
            notify.setblocking(False)
            said = []
            while True:
                try:
                    said.append(notify.recv(4096))
                except BlockingIOError:
                    break
            assert b"WATCHDOG=1" not in said, said


OTHER_VHW = (b"$VWVHW,,T,,M,7.00,N,,K*4D\r\n", b"$VWVHW,,T,,M,7.01,N,,K*4C\r\n")
"""The second EMlog's two readings (7 kn against the first's 5)."""


def test_a_log_whose_own_pty_is_not_open_sends_nothing_to_the_shared_one(
    tmp_path: Path,
) -> None:
    """emlog2 has a pty of its own (``calibration[].pty``), a regular file in its way at
    the start; emlog1 goes out on the shared pty, both under talker ``VW`` (the config's
    check lets two logs share a talker when one has outputs of its own: it writes only
    there). The shared pty carries emlog1's sentences only; once the file is gone emlog2's
    own pty is published and carries emlog2's. emlog2's sentences went to the shared
    outputs while its own was not open: the autopilot on the shared pty read `$VWVHW`
    at 7 kn and 5 kn in turns, two logs it cannot tell apart."""
    work = make_work(tmp_path, TWO_LOGS.replace("talker: VD}", "pty: out/two}"))
    (work / "out" / "two").write_text("in the way\n")
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "emlog2", "dvl")]
    try:
        d = Daemon(work, pty=True)
        own = -1
        try:
            tty.setraw(d.fd)
            for k in range(10):
                os.write(masters[0], VHW[k % 2])
                os.write(masters[1], OTHER_VHW[k % 2])
                d.pump(0.1)
            shared = [line for line in d.lines if b"VHW" in line or b"PEMLS" in line]
            assert any(line.startswith(b"$VWVHW,,T,,M,5.0") for line in shared), shared
            assert not [x for x in shared if b"7.0" in x or b"emlog2" in x], shared
            (work / "out" / "two").unlink()
            wait(lambda: (work / "out" / "two").is_symlink(), "emlog2's pty", OUTPUT_RETRY_S + 3)
            own = os.open(work / "out" / "two", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
            tty.setraw(own)
            got = b""
            for k in range(10):
                os.write(masters[1], OTHER_VHW[k % 2])
                time.sleep(0.1)
                with contextlib.suppress(BlockingIOError):
                    got += os.read(own, 4096)
            assert b"$VWVHW,,T,,M,7.0" in got, got
            assert d.stop() == 0
        finally:
            d.kill()
            if own >= 0:
                os.close(own)
    finally:
        for fd in masters:
            os.close(fd)


def test_a_reload_turning_stdout_on_moves_the_log_to_stderr(tmp_path: Path) -> None:
    """The daemon started without ``outputs.stdout`` logs to stdout (a pipe here); a
    SIGHUP into a config with ``outputs.stdout: true`` moves the log to stderr before
    the NMEA comes to stdout, which then carries sentences only (``control_reset`` and
    the rest on stderr); a SIGHUP turning it off moves the log back. The log stayed on
    stdout, its JSON lines between the corrected sentences of the autopilot's stream."""
    work = make_work(tmp_path, PD0_CONFIG)
    cfg = work / "emlogd.yaml"
    plain = cfg.read_text()
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    out_r, out_w = os.pipe()
    os.set_blocking(out_r, False)
    try:
        with (work / "stderr.log").open("wb") as err:
            proc = run_daemon(work, stdout=out_w, stderr=err.fileno())
        os.close(out_w)
        with reaped(proc):
            wait(lambda: (work / "run" / "control.sock").exists(), "the control socket")
            cfg.write_text(plain.replace("{pty: out/emlog0}", "{pty: out/emlog0, stdout: true}"))
            proc.send_signal(signal.SIGHUP)
            stderr = work / "stderr.log"
            wait(lambda: b'"reloaded"' in stderr.read_bytes(), "the reload logged on stderr")
            drain(out_r)  # the log's lines before the reload
            for k in range(10):
                os.write(masters[0], VHW[k % 2])
                time.sleep(0.05)
            request(work / "run" / "control.sock", {"cmd": "reset"})
            time.sleep(0.5)
            lines = drain(out_r).splitlines()
            assert [x for x in lines if x.startswith(b"$VWVHW")], lines
            assert all(x.startswith(b"$") for x in lines), lines
            assert b'"control_reset"' in stderr.read_bytes()
            cfg.write_text(plain)
            proc.send_signal(signal.SIGHUP)
            wait(lambda: b'"reloaded"' in drain(out_r), "the log back on stdout")
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(STOP_TIMEOUT_S) == 0
    finally:
        os.close(out_r)
        for fd in masters:
            os.close(fd)


LOOP_TEST_S = 3.0
"""How long the EMlog sends while its line carries the daemon's output back."""

STATUS_OFTEN = "{pty: out/emlog0, status_sentence_interval_s: 0.2}"
"""The outputs of that test: the status sentence, the proof of a loop, five times a second."""


def _echo(d: Daemon, emlog: int, until: float) -> None:
    """The output pty read (its lines into ``d.lines``) and written back into the EMlog's
    line, until ``until``: a multiplexer forwarding the autopilot's bus to the log's input."""
    buf = b""
    while time.monotonic() < until:
        if not select.select([d.fd], [], [], 0.05)[0]:
            continue
        with contextlib.suppress(BlockingIOError):
            buf += os.read(d.fd, 4096)
        *lines, buf = buf.split(b"\r\n")
        for line in lines:
            d.lines.append(line)
            with contextlib.suppress(BlockingIOError):
                os.write(emlog, line + b"\r\n")


def test_the_daemons_output_read_back_on_the_logs_input_is_skipped(tmp_path: Path) -> None:
    """Everything the daemon writes on its pty comes back on the EMlog's line (an NMEA
    multiplexer forwarding every talker to every listener), the log sending a VHW every
    0.1 s for 3 s: nearly every reading goes out (a few before the first ``$PEMLS`` came
    back), none is dropped for the rate, and the port counts the echoes it skipped. Each
    echo was read as a reading: the doubled rate was a babble, every reading dropped
    (``implausible_rate``), 4 VHW out in 6 s."""
    work = make_work(tmp_path, PD0_CONFIG.replace("{pty: out/emlog0}", STATUS_OFTEN))
    with _pd0_daemon(work) as (d, emlog):
        until = time.monotonic() + LOOP_TEST_S
        echo = threading.Thread(target=_echo, args=(d, emlog, until + 0.5))
        echo.start()
        k = 0
        while time.monotonic() < until:
            os.write(emlog, VHW[k % 2])
            k += 1
            time.sleep(0.1)
        echo.join()
        out = [x for x in d.lines if x.startswith(b"$VWVHW")]
        assert len(out) >= k - 5, (k, len(out))
        u = d.uut("emlog1")
        assert cast(dict[str, int], u["counters"])["implausible_rate"] == 0
        ports = cast(dict[str, dict[str, int]], d.status()["ports"])
        assert ports["emlog1"]["echoes"] > k // 2
        assert d.events("output_read_back") == 1
        assert d.stop() == 0


SPIKE_EVERY = 20
"""One EMlog sentence in this many reads :data:`SPIKE_FACTOR` times its value."""

SPIKE_FACTOR = 2.5
"""How far a spiking log's absurd reading is off (within the range at the trial's speeds)."""

OTHER_LOG_FACTOR = 1.3
"""The second log on the first log's line reads this many times the first's speed."""

FLOOD_TYPES = 20
"""Unknown sentence types each EMlog sentence is followed by (a talker's whole repertoire)."""


def _heading_flips(rel: float, t: float, port: str, s: str) -> list[Record]:
    """The DVL's heading 180° off in every other second (a heading source that flips:
    two compasses behind one port, a sign lost in a converter)."""
    sa = _fields(s, 4) if port == "dvl" and s.startswith(":SA,") else None
    if sa is None or int(rel) % 2 == 0:
        return [(t, port, s)]
    try:
        h = float(sa[3])
    except ValueError:
        return [(t, port, s)]
    return [(t, port, ",".join([*sa[:3], f"{(h + 180.0) % 360.0:06.2f}"]))]


def _vhw_speed(s: str) -> tuple[list[str], float] | None:
    """A VHW sentence's fields and its speed in knots (None for another sentence)."""
    if not s.startswith("$VWVHW,"):
        return None
    body = s[1 : s.find("*")].split(",")
    try:
        return body, float(body[5])
    except (ValueError, IndexError):
        return None


def _with_knots(body: list[str], kn: float, talker: str = "VW") -> str:
    """A VHW of ``body`` reading ``kn`` knots (and the km/h to match), from ``talker``."""
    out = [talker + body[0][2:], *body[1:]]
    out[5] = f"{kn:.2f}"
    out[7] = f"{kn * 1.852:.2f}"
    return _nmea(",".join(out))


def _spikes() -> Edit:
    """One EMlog VHW in :data:`SPIKE_EVERY` reading :data:`SPIKE_FACTOR` × its value."""
    seen = [0]

    def edit(rel: float, t: float, port: str, s: str) -> list[Record]:
        vhw = _vhw_speed(s) if port.startswith("emlog") else None
        if vhw is None:
            return [(t, port, s)]
        seen[0] += 1
        if seen[0] % SPIKE_EVERY:
            return [(t, port, s)]
        return [(t, port, _with_knots(vhw[0], vhw[1] * SPIKE_FACTOR))]

    return edit


def _other_log(rel: float, t: float, port: str, s: str) -> list[Record]:
    """A second log on emlog1's line (talker ``II``), reading :data:`OTHER_LOG_FACTOR` ×
    emlog1's speed, each of its VHW 0.3 s after emlog1's, during :data:`FAULT_S`."""
    vhw = _vhw_speed(s) if port == "emlog1" else None
    if vhw is None or not FAULT_S[0] <= rel < FAULT_S[1]:
        return [(t, port, s)]
    return [(t, port, s), (t + 0.3, port, _with_knots(vhw[0], vhw[1] * OTHER_LOG_FACTOR, "II"))]


def _type_flood(rel: float, t: float, port: str, s: str) -> list[Record]:
    """Each EMlog sentence followed by :data:`FLOOD_TYPES` sentences of unknown types."""
    if not port.startswith("emlog"):
        return [(t, port, s)]
    extra = [(t + 1e-5 * (k + 1), port, _nmea(f"VWX{k:02d},1,2,3")) for k in range(FLOOD_TYPES)]
    return [(t, port, s), *extra]


def _gnss_time_backwards(rel: float, t: float, port: str, s: str) -> list[Record]:
    """The GNSS's RMC time of day running backwards from the trial's start (its clock
    stepped back each fix), the speed and course right."""
    if port != "gnss" or not s.startswith("$GPRMC,"):
        return [(t, port, s)]
    body = s[1 : s.find("*")].split(",")
    back = (8 * 3600.0 - rel) % 86400.0
    body[1] = f"{int(back // 3600):02d}{int(back % 3600 // 60):02d}{back % 60:05.2f}"
    return [(t, port, _nmea(",".join(body)))]


TORN_S = 0.5
"""How late the end of each torn DVL ensemble comes after its beginning."""


def _torn_ensembles() -> Edit:
    """Every DVL ensemble torn across reads: its lines after ``:TS`` held back and
    received :data:`TORN_S` after them (a converter releasing its buffer in chunks;
    stamped with the record they come before, so the capture stays in time order), each
    ensemble's end after the next one's ``:SA`` at 10 Hz: none whole."""
    held: list[tuple[float, str]] = []

    def edit(rel: float, t: float, port: str, s: str) -> list[Record]:
        due = [(t, "dvl", line) for at, line in held if at <= t]
        del held[: len(due)]
        if port == "dvl" and s[:4] in (":BI,", ":BS,", ":BE,", ":BD,"):
            held.append((t + TORN_S, s))
            return due
        return [*due, (t, port, s)]

    return edit


WORLDS13: dict[str, World] = {
    "heading-flips": (lambda: _heading_flips, "dvl"),
    "heading-flips-gnss": (lambda: _heading_flips, "gnss"),
    "uut-spikes": (_spikes, "dvl"),
    "other-log-on-the-line": (lambda: _other_log, "dvl"),
    "sentence-type-flood": (lambda: _type_flood, "dvl"),
    "gnss-time-backwards": (lambda: _gnss_time_backwards, "gnss"),
    "torn-ensembles": (_torn_ensembles, "dvl"),
}
"""Each world: its edit (made fresh per run) and the reference learnt against."""


@pytest.mark.soak
@pytest.mark.parametrize("world", list(WORLDS13))
def test_a_lying_sensor_never_makes_the_emitted_speed_worse_than_raw(
    world: str, tmp_path: Path
) -> None:
    """Every 5-min window of both logs within ``RATIO`` of raw, both scored."""
    figures = measure_world(world, tmp_path, WORLDS13)
    for u in ("emlog1", "emlog2"):
        f = figures[u]
        assert f["windows"] >= 10, (u, f)
        assert f["worst"] <= RATIO, (u, f)


if __name__ == "__main__":
    for name in sys.argv[1:] or list(WORLDS13):
        with tempfile.TemporaryDirectory() as tmp:
            figures = measure_world(name, Path(tmp), WORLDS13)
            sys.stdout.write(json.dumps({name: figures}) + "\n")
            sys.stdout.flush()
