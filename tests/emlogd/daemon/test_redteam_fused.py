"""The fifth red team's findings against the live daemon with a fused output, each
pinned: two EMlogs on ptys the test serves itself, no reference.

Rule kept (README, docs/RELIABILITY.md): nothing worse than raw reaches the autopilot."""

from __future__ import annotations

import contextlib
import os
import random
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.framing import split_nmea
from drivers.nmea0183 import encode_vhw
from drivers.records import KNOT_MPS
from emlogd.pipeline.fusion import FLAT_S
from tests.emlogd.daemon.harness import Daemon, make_work, raw_pty

CONFIG = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}
  - {name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut}
  - {name: dvl, url: links/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.0}
  - {uut: emlog2, reference: dvl, lag: 0.0}
outputs: {pty: out/emlog0, status_sentence_interval_s: 0.1, speed: fused}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
"""
"""Two EMlogs fused, a DVL that never speaks: no reference arbitrates."""

STEP_S = 0.1
"""The EMlogs' interval, s (10 Hz)."""


def _vhw(v: float) -> bytes:
    return (encode_vhw(max(v, 0.0)) + "\r\n").encode()


def _fields(line: bytes) -> list[str]:
    return split_nmea(line).decode().split(",")


def _both_agree(daemon: Daemon, m1: int, m2: int, rng: random.Random) -> None:
    """Both logs at 10 Hz for 3 s, reading the same slowly ramping speed with 0.02 m/s
    of noise each."""
    t0 = time.monotonic()
    k = 0
    while time.monotonic() - t0 < 3.0:
        v = 2.9 + 0.1 * ((k % 30) / 30.0)
        os.write(m1, _vhw(v + rng.gauss(0.0, 0.02)))
        os.write(m2, _vhw(v + rng.gauss(0.0, 0.02)))
        daemon.pump(STEP_S)
        k += 1


@contextlib.contextmanager
def _two_logs(tmp_path: Path, seed: int) -> Iterator[tuple[Daemon, int, int, random.Random]]:
    """The daemon on CONFIG with both logs' ptys, after :func:`_both_agree` (the random
    draws seeded with ``seed``); stopped and the ptys closed at the end."""
    work = make_work(tmp_path, CONFIG)
    m1 = raw_pty(work / "links" / "emlog1")
    m2 = raw_pty(work / "links" / "emlog2")
    rng = random.Random(seed)
    daemon = Daemon(work, pty=True)
    try:
        _both_agree(daemon, m1, m2, rng)
        yield daemon, m1, m2, rng
    finally:
        daemon.stop()
        os.close(m1)
        os.close(m2)


def test_a_log_babbling_in_bursts_never_becomes_the_fused_speed(tmp_path: Path) -> None:
    """Both logs at 10 Hz for 3 s; then emlog1 falls silent and emlog2 babbles, 20
    sentences of 0–14 kn in one write every 0.1 s, for 4 s. No fused speed goes out
    after the babble began (nothing is left to fuse) and every read of emlog2 is
    counted as rate. Each read held 20 readings with one receive time and only the
    newest was judged, at the log's own rate: those within the acceleration bound of
    the last accepted went out as the valid fused speed, emlog2 alone (taken back as
    the one log left though it had just been refused)."""
    with _two_logs(tmp_path, 1) as (daemon, _m1, m2, rng):
        before = len(daemon.lines)
        t1 = time.monotonic()
        while time.monotonic() - t1 < 4.0:
            os.write(m2, b"".join(_vhw(rng.uniform(0.0, 14.0) * KNOT_MPS) for _ in range(20)))
            daemon.pump(STEP_S)
        after = daemon.lines[before + 4 :]  # what was in flight when the babble began
        fused = [_fields(x)[5] for x in after if x.startswith(b"$IIVHW")]
        assert [f for f in fused if f] == []
        counters = daemon.uut("emlog2")["counters"]
        assert isinstance(counters, dict) and counters["implausible_rate"] > 20, counters


@pytest.mark.soak
def test_a_stuck_log_beside_a_babbler_is_marked_invalid_live(tmp_path: Path) -> None:
    """Both logs at 10 Hz for 3 s; then emlog1 reads 3.00 m/s flat and emlog2 babbles
    in bursts, for 14 s: within FLAT_S and a second of the stuck reading the fused VHW
    goes out without a speed and ``$PEMLF`` says V, naming emlog1 still; emlog2 is
    never used. (Slow: the still rule needs FLAT_S of a flat log alone.)"""
    with _two_logs(tmp_path, 2) as (daemon, m1, m2, rng):
        before = len(daemon.lines)
        t1 = time.monotonic()
        marks: list[int] = []
        while time.monotonic() - t1 < 14.0:
            os.write(m1, _vhw(3.0))
            os.write(m2, b"".join(_vhw(rng.uniform(0.0, 14.0) * KNOT_MPS) for _ in range(20)))
            daemon.pump(STEP_S)
            if time.monotonic() - t1 > FLAT_S + 1.0 and not marks:
                marks.append(len(daemon.lines))
        status = [_fields(x) for x in daemon.lines[before + 4 :] if x.startswith(b"$PEMLF")]
        assert status and all("emlog2" not in f[4].split(";") for f in status)
        late = daemon.lines[marks[0] :]
        fused = [_fields(x)[5] for x in late if x.startswith(b"$IIVHW")]
        assert len(fused) > 20 and all(f == "" for f in fused), fused
        last = [_fields(x) for x in late if x.startswith(b"$PEMLF")][-1]
        assert last[3:6] == ["0", "", "V"] and "emlog1:still" in last[6], last
