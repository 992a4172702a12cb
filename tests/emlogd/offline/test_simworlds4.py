"""A sailing vessel beating to windward in a tide, against the promise of
``test_simphysics.py`` (every 5-min window's RMSE of the emitted speed against the true
speed through the water at most raw's × 1.05), built with its :class:`Case` and
measured with its :func:`measure`.

The vessel sails two headings only, 90° apart (010° and 100°), tacking every 8 min: a
20-s turn in which it loses 0.8 m/s (the hull's response 3 s), leeway 6° to leeward,
gusts moving the speed by about 0.1 m/s, in a tidal ellipse of 0.5 m/s along 060°
(0.15 m/s across it, 12.42 h). With the simulator's logs it holds; with logs that are
nearly right (the promise is sharpest where raw is good) it is open. And the default
trial against a GNSS receiver that repeats its last fix (position, speed and course) with
new times for 10 min, as one that lost its sky while still sending does.
``soak``: a simulation and a replay each; every figure is in docs/RELIABILITY.md,
measured by running this file as a script::

    PYTHONPATH=. python tests/emlogd/offline/test_simworlds4.py [CASE ...]
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import tempfile
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import emlogd.offline.simsensors as simsensors
import tests.emlogd.offline.test_simphysics as simphysics
from calib.models import Params
from drivers.framing import split_nmea, with_checksum
from emlogd.offline.simkinematics import START_EPOCH_S, Kinematics, _lowpass
from emlogd.offline.simulate import simulate
from tests.emlogd.offline.test_simphysics import RATIO, TIDE_S, Case, measure, pinned

TACK_S = 480.0
"""``beating``: a tack every this long, s ..."""

TACK_TURN_S = 20.0
"""... the turn through :data:`TACK_DEG` taking this long, s ..."""

TACK_DEG = 90.0
"""... between the two headings (close-hauled on each tack) ..."""

FIRST_HEADING_DEG = 10.0
"""... the first of them, degrees true ..."""

TACK_LOSS_MPS = 0.8
"""... the speed lost while turning, m/s ..."""

HULL_TAU_S = 3.0
"""... the hull's response to it, s (a light boat) ..."""

BEAT_MPS = 2.3
"""... the speed through the water on each tack, m/s ..."""

LEEWAY_DEG = 6.0
"""... and the leeway (sideslip to leeward, its side changing with the tack)."""


def beating(k: Kinematics) -> Kinematics:
    """Two headings :data:`TACK_DEG` apart, a tack every :data:`TACK_S`; gusts (white
    noise averaged over 30 s, about 0.1 m/s) move the speed."""
    t = k.t
    tack = np.floor(t / TACK_S) % 2
    frac = np.clip(np.mod(t, TACK_S) / TACK_TURN_S, 0.0, 1.0)
    s = (1.0 - tack) + (2.0 * tack - 1.0) * frac  # 0 on the first tack, 1 on the other
    heading = np.mod(math.radians(FIRST_HEADING_DEG) + s * math.radians(TACK_DEG), 2 * math.pi)
    rng = np.random.default_rng(round(float(t[-1])))
    gust = np.convolve(rng.normal(0.0, 0.3, t.size), np.ones(300) / 300, mode="same")
    cmd = BEAT_MPS + 5.0 * gust - TACK_LOSS_MPS * (frac < 1.0)
    surge = _lowpass(np.clip(cmd, 0.8, 3.2), HULL_TAU_S)
    sway = np.where(s > 0.5, 1.0, -1.0) * math.tan(math.radians(LEEWAY_DEG)) * surge
    return dataclasses.replace(k, surge=surge, sway=sway, heading=heading)


TIDE_MAJOR_MPS, TIDE_MINOR_MPS, TIDE_AXIS_DEG = 0.5, 0.15, 60.0
"""The tidal ellipse: its major and minor semi-axes, m/s, and the major axis, degrees."""


def tidal_ellipse(k: Kinematics, t0: float) -> Kinematics:
    """The current round :data:`TIDE_MAJOR_MPS` × :data:`TIDE_MINOR_MPS` along
    :data:`TIDE_AXIS_DEG` once per :data:`~tests.emlogd.offline.test_simphysics.TIDE_S`."""
    ph = 2.0 * math.pi * (t0 - START_EPOCH_S + k.t) / TIDE_S
    a, b = TIDE_MAJOR_MPS * np.cos(ph), TIDE_MINOR_MPS * np.sin(ph)
    ax = math.radians(TIDE_AXIS_DEG)
    return dataclasses.replace(
        k,
        current_n=a * math.cos(ax) - b * math.sin(ax),
        current_e=a * math.sin(ax) + b * math.cos(ax),
    )


STALE_S = (900.0, 1500.0)
"""``gnss-stale``: the trial times the receiver repeats its last fix, s."""


def repeat_last_fix(lines: list[simsensors.Line], fields: tuple[int, ...] = ()) -> None:
    """Within :data:`STALE_S`, every RMC the first one's but for its time and date (in
    place: the receiver's lines of one trajectory); with ``fields``, only those fields
    the first one's (7, 8: a velocity solution frozen, the position still measured)."""
    held: list[str] | None = None
    for i, ln in enumerate(lines):
        t = ln.t - START_EPOCH_S
        if not ln.data.startswith(b"$GPRMC,") or not STALE_S[0] <= t < STALE_S[1]:
            held = None
            continue
        f = ln.data.decode("ascii").strip().split("*")[0][1:].split(",")
        if held is None:
            held = f
        g = [*held]
        g[1], g[9] = f[1], f[9]  # the time of day and the date: new
        if fields:
            g = [held[j] if j in fields else x for j, x in enumerate(f)]
        lines[i] = dataclasses.replace(ln, data=(with_checksum(",".join(g)) + "\r\n").encode())


def _stale_receiver(orig: Any, fields: tuple[int, ...] = ()) -> Any:
    def gnss_lines(k: Kinematics, t0: float, rng: Any, faults: Any, out: list[Any]) -> int:
        n0 = len(out)
        got = orig(k, t0, rng, faults, out)
        mine = out[n0:]
        repeat_last_fix(mine, fields)
        out[n0:] = mine
        return int(got)

    return gnss_lines


EXACT = tuple(
    dataclasses.replace(e, params=Params("EM4", 0.0, 0.0, 0.0))
    for e in (simsensors.EMLOG1, simsensors.EMLOG2)
)
"""Both logs without error (their noise, lag and rate as simulated)."""

ONE_PERCENT = (
    dataclasses.replace(simsensors.EMLOG1, params=Params("EM4", 0.0, 0.01, 0.0)),
    dataclasses.replace(simsensors.EMLOG2, params=Params("EM4", 0.0, -0.01, 0.0)),
)
"""emlog1 1 % high, emlog2 1 % low, nothing else."""

WORLDS = {
    c.name: c
    for c in (
        Case("beating", beating.__doc__ or "", motion=beating, current=tidal_ellipse),
        Case("beating-exact", "the same, both logs exact", motion=beating, current=tidal_ellipse),
        Case("beating-1pct", "the same, the logs 1 % off", motion=beating, current=tidal_ellipse),
        Case("gnss-stale", repeat_last_fix.__doc__ or "", cfg=simphysics.GNSS_CFG),
        Case("gnss-velocity-frozen", "SOG and COG frozen", cfg=simphysics.GNSS_CFG),
    )
}

SENSORS: dict[str, tuple[int, tuple[simsensors.EmlogSpec, ...]]] = {
    "beating-exact": (1, EXACT),
    "beating-1pct": (2, ONE_PERCENT),
    "gnss-stale": (2, EXACT),
    "gnss-velocity-frozen": (2, EXACT),
}
"""The worlds whose logs are not the simulator's: the seed and the two logs."""

OPEN = {
    "beating-exact": "open: emlog1's windows from 1504 s up to 15.1x raw (0.418 vs 0.028 "
    "m/s): m 0.106, b -0.740 applied at 1593 s, withdrawn at 2078 s when the sea memory "
    "told raw from it (w -0.01 +/- 0.11). Two headings leave the offset and the current "
    "along their bisector apart only in the tacks: at 1593 s it beat raw after each one's "
    "own current (0.046 vs 0.067) and in the common sea (0.230 vs 0.653), and the memory "
    "did not yet refute it (w 0.30 +/- 0.11) (docs/RELIABILITY.md)",
    "gnss-velocity-frozen": "open: 2.905x / 1.626x raw (emlog1's window from 1504 s, "
    "emlog2's from 1501 s), as gnss-stale's before 2a8b6d6: SOG and COG frozen for 10 min "
    "while the position moves on are taken as references (a repeated position is what "
    "stalefix judges); the distance between the fixes against their SOG would tell "
    "(docs/RELIABILITY.md)",
    "beating-1pct": "open: emlog1's windows from 1504 s up to 12.1x raw (0.429 vs 0.035 "
    "m/s), as beating-exact's: m 0.106, b -0.714 applied at 1593 s (w 0.26 +/- 0.11), "
    "withdrawn at 2078 s (w -0.07 +/- 0.11); emlog2's window from 601 s 2.25x raw (0.122 "
    "vs 0.054 m/s) (docs/RELIABILITY.md)",
}
"""The worlds that break the promise, pinned as strict xfails until fixed."""

STALE_FIELDS = {"gnss-stale": (), "gnss-velocity-frozen": (7, 8)}
"""The worlds whose receiver repeats its first fix of :data:`STALE_S`: the RMC fields
held (none: all but the time and the date)."""


def _measure(name: str, tmp: Path, mp: pytest.MonkeyPatch) -> dict[str, Any]:
    if name in STALE_FIELDS:
        stale = _stale_receiver(simsensors.gnss_lines, STALE_FIELDS[name])
        mp.setattr(simsensors, "gnss_lines", stale)
    if name in SENSORS:
        seed, (log1, log2) = SENSORS[name]
        mp.setattr(simphysics, "simulate", partial(_simulate_with, seed=seed, logs=(log1, log2)))
    return measure(WORLDS[name], tmp, mp)


def _simulate_with(
    outdir: str | Path,
    *,
    seed: int,
    logs: tuple[simsensors.EmlogSpec, simsensors.EmlogSpec],
    **kw: Any,
) -> Any:
    """:func:`simulate` of ``seed`` with the two logs ``logs`` (the rest as asked)."""
    return simulate(outdir, **{**kw, "seed": seed, "emlogs": logs})


def _k(n: int = 20000) -> Kinematics:
    t = np.arange(n, dtype=np.float64) * 0.1
    z = np.zeros(n)
    return Kinematics(t=t, surge=np.full(n, 1.0), sway=z, heading=z, current_e=z, current_n=z)


class TestWorlds:
    """What each world changes, on a small grid (fast)."""

    def test_the_receiver_repeats_its_last_fix(self) -> None:
        """Inside :data:`STALE_S` each RMC is the span's first but for its time and
        date, its checksum right; outside, as sent."""
        from drivers.nmea0183 import encode_rmc

        def rmc(at: float, sog: float) -> simsensors.Line:
            stamp = datetime.fromtimestamp(START_EPOCH_S + at, UTC)
            s = encode_rmc(stamp, sog, 10.0 * sog, lat_deg=43.0 + at * 1e-5, lon_deg=5.9)
            return simsensors.Line(START_EPOCH_S + at, "gnss", (s + "\r\n").encode(), False)

        lines = [rmc(at, 1.0 + at / 1000.0) for at in (800.0, 900.0, 901.0, 1499.0, 1500.0)]
        sent = list(lines)
        repeat_last_fix(lines)
        f = [ln.data.decode().split("*")[0].split(",") for ln in lines]
        assert lines[0] == sent[0] and lines[1] == sent[1] and lines[4] == sent[4]
        for i in (2, 3):
            assert f[i][1] == sent[i].data.decode().split(",")[1]
            assert f[i][3:9] == f[1][3:9]  # position, speed, course: the first's
            assert split_nmea(lines[i].data.strip()) is not None
        assert f[2][7] != sent[2].data.decode().split(",")[7]
        moving = list(sent)
        repeat_last_fix(moving, (7, 8))
        g = [ln.data.decode().split("*")[0].split(",") for ln in moving]
        assert g[2][7:9] == g[1][7:9] and g[3][7:9] == g[1][7:9]
        assert g[2][3] == sent[2].data.decode().split(",")[3] != g[1][3]

    def test_two_headings_a_tack_every_eight_minutes(self) -> None:
        """On each tack one heading (010° or 100°), the turn between them 20 s long with
        the speed down by up to 0.8 m/s, leeway to the tack's leeward side."""
        b = beating(_k())
        deg = np.degrees(b.heading)
        at = [int(x * 10) for x in (100.0, 470.0, 600.0, 950.0, 1100.0)]
        assert deg[at] == pytest.approx([10.0, 10.0, 100.0, 100.0, 10.0], abs=1e-9)
        legs = (np.mod(b.t, TACK_S) >= 60.0) & (np.mod(b.t, TACK_S) < 470.0)
        assert float(np.mean(b.surge[legs])) == pytest.approx(BEAT_MPS, abs=0.05)
        turn = (np.mod(b.t, TACK_S) > 10.0) & (np.mod(b.t, TACK_S) < TACK_TURN_S)
        assert float(np.max(b.surge[legs] - np.mean(b.surge[legs]))) < 0.4
        assert float(np.mean(b.surge[turn])) < BEAT_MPS - 0.5
        assert b.sway[at[0]] / b.surge[at[0]] == pytest.approx(-math.tan(math.radians(6.0)))
        assert b.sway[at[2]] / b.surge[at[2]] == pytest.approx(math.tan(math.radians(6.0)))
        mid = int(480.0 * 10 + 100)  # 10 s into the second tack's turn: half-way round
        assert deg[mid] == pytest.approx(55.0, abs=1.0)

    def test_the_tidal_ellipse(self) -> None:
        """0.5 m/s along 060° at the trial's start, 0.15 m/s across it a quarter of a
        tide later."""
        e = tidal_ellipse(_k(), START_EPOCH_S)
        assert (e.current_n[0], e.current_e[0]) == pytest.approx(
            (0.5 * math.cos(math.radians(60.0)), 0.5 * math.sin(math.radians(60.0)))
        )
        q = tidal_ellipse(_k(), START_EPOCH_S + TIDE_S / 4.0)
        assert math.hypot(q.current_n[0], q.current_e[0]) == pytest.approx(0.15)
        assert all(p.params.forward(2.0) == 2.0 for p in EXACT)


@pytest.mark.soak
@pytest.mark.parametrize("name", pinned(WORLDS, OPEN))
def test_no_window_of_either_log_worse_than_raw(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    """Both logs: every 5-min window within 1.05 × raw's RMSE against the truth."""
    worst = {u: v["worst"] for u, v in _measure(name, tmp_path, monkeypatch).items()}
    assert max(worst.values()) <= RATIO, worst


def main(names: list[str]) -> None:
    """Print each world's figures as a JSON line (every world without ``names``)."""
    for name in names or sorted(WORLDS):
        with tempfile.TemporaryDirectory() as d, pytest.MonkeyPatch.context() as m:
            row = {name: _measure(name, Path(d), m)}
        sys.stdout.write(f"{json.dumps(row, default=str)}\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main(sys.argv[1:])
