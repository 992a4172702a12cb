"""The fourteenth red team's findings against the live daemon, each pinned: what its
ports, sockets, outputs, state file and config may do to it from outside.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest

from emlogd.calfile import loads_state
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import (
    PD0_CONFIG,
    Daemon,
    make_work,
    raw_pty,
    saved_calibration,
)
from tests.emlogd.daemon.test_redteam_live import VHW, _pd0_daemon


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
    masters = [raw_pty(work / "links" / name) for name in ("emlog1", "dvl")]
    argv = ["unshare", "-rn", sys.executable, "-m", "emlogd", "run", "--config", str(cfg)]
    try:
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
    finally:
        for fd in masters:
            os.close(fd)


UDP_BESIDE_PTY = '{pty: out/emlog0, udp: "192.0.2.9:10110"}'
"""The outputs of that test: the pty and a UDP destination with no route to it."""
