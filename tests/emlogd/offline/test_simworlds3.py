"""Sensor faults the simulator leaves out, against the promise of ``test_simphysics.py``
(every 5-min window's RMSE of the emitted speed against the true speed through the
water at most raw's × 1.05), built with its :class:`Case` and measured with its
:func:`measure`.

A log whose gain drops with the heel in turns (0.5 % per degree, the heel growing with
the speed and the turn rate); a log reading 4 % low while the sea is up for 20 min (its
noise up too); fouling that sets in during the learn (the gain 8 % lower over 40 min,
then steady); a log whose gain changes above 2 m/s (a knee, beyond EM4's curve); a
reference DVL whose own scale is 1 % high in one water mass (20 min); a log quantised
to 0.1 kn whose firmware repeats its last value for 3 s; logs without error (the
promise is sharpest where raw is good), one with a dead band of 0.5 m/s, in a harbour's
stops and starts; a current stepping 0.67 m/s at a front crossed every 10 min, and
every 5 min against the GNSS (both open).
``soak``: a simulation and a replay each; every figure is in
docs/RELIABILITY.md, measured by running this file as a script::

    PYTHONPATH=. python tests/emlogd/offline/test_simworlds3.py [CASE ...]
"""

from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import emlogd.offline.simsensors as simsensors
import tests.emlogd.offline.test_simphysics as simphysics
from calib.models import Params
from drivers.nmea0183 import encode_vbw, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline.simkinematics import START_EPOCH_S, Kinematics
from emlogd.offline.simulate import simulate
from tests.emlogd.offline.test_simphysics import RATIO, Case, measure, pinned

HEEL_DEG_PER_MPS_DPS = 1.0
"""``heel-gain``: the heel in a turn, degrees per (m/s × °/s) of speed times turn rate
(8° at 1.85 m/s in the circles' 3 °/s, 10° or more in the figure-8's turns) ..."""

HEEL_GAIN_PER_DEG = -0.005
"""... and the log's gain change per degree of heel (the electrodes' flow disturbed as
the hull leans: −4 % in the circles)."""


def _turn_rate_dps(k: Kinematics) -> np.ndarray:
    return np.asarray(np.degrees(np.gradient(np.unwrap(k.heading), k.t)), dtype=np.float64)


def heel_gain(k: Kinematics) -> Kinematics:
    """A gain falling with the heel (:data:`HEEL_GAIN_PER_DEG` per degree), the heel
    :data:`HEEL_DEG_PER_MPS_DPS` × speed × |turn rate|."""
    heel = HEEL_DEG_PER_MPS_DPS * np.abs(k.surge * _turn_rate_dps(k))
    return dataclasses.replace(k, surge=k.surge * (1.0 + HEEL_GAIN_PER_DEG * heel))


SEA_S = (1800.0, 3000.0)
"""``sea-state-gain``: the trial times while the sea is up, s (20 min) ..."""

SEA_GAIN = 0.96
"""... the log reading this share of the speed (air in the boundary layer) ..."""

SEA_NOISE_MPS = 0.08
"""... and the waves' orbital flow adding this much noise, m/s (1σ)."""


def sea_state_gain(k: Kinematics, t0: float) -> Kinematics:
    """The log reading :data:`SEA_GAIN` of the speed, with :data:`SEA_NOISE_MPS` of
    noise, inside :data:`SEA_S`."""
    t = t0 - START_EPOCH_S + k.t
    on = (t >= SEA_S[0]) & (t < SEA_S[1])
    rng = np.random.default_rng(round(t0))
    noise = rng.normal(0.0, SEA_NOISE_MPS, t.size)
    return dataclasses.replace(k, surge=np.where(on, k.surge * SEA_GAIN + noise, k.surge))


FOULING_S = (900.0, 3300.0)
"""``fouling-onset``: fouling grows between these trial times, s (in the transit, while
the first calibration is learnt, for 40 min) ..."""

FOULING_GAIN = 0.92
"""... to this share of the gain, and stays."""


def fouling_onset(k: Kinematics, t0: float) -> Kinematics:
    """The gain falling linearly to :data:`FOULING_GAIN` over :data:`FOULING_S`."""
    t = t0 - START_EPOCH_S + k.t
    f = np.clip((t - FOULING_S[0]) / (FOULING_S[1] - FOULING_S[0]), 0.0, 1.0)
    return dataclasses.replace(k, surge=k.surge * (1.0 - (1.0 - FOULING_GAIN) * f))


KNEE_MPS = 2.0
"""``speed-knee``: above this speed through the water ..."""

KNEE_GAIN = 0.08
"""... the log reads this much more per m/s (the flow over the electrodes changing
regime): a corner no polynomial of EM1–EM4 follows."""


def speed_knee(k: Kinematics) -> Kinematics:
    """The reading ``u + KNEE_GAIN·max(u − KNEE_MPS, 0)``."""
    return dataclasses.replace(k, surge=k.surge + KNEE_GAIN * np.maximum(k.surge - KNEE_MPS, 0.0))


MASS_S = (2100.0, 3300.0)
"""``dvl-water-mass``: the trial times the DVL is in another water mass, s (20 min) ..."""

MASS_SCALE = 1.01
"""... where the speed of sound it assumes is 1 % off: its velocities 1 % high."""


def water_mass(
    encode: Callable[..., list[str]], k: Kinematics, t0: float
) -> Callable[..., list[str]]:
    """The PD6 encoder whose bottom track is :data:`MASS_SCALE` too high inside
    :data:`MASS_S`."""

    def scaled(**kw: Any) -> list[str]:
        t = kw["timestamp"].timestamp() - START_EPOCH_S
        bt = kw.get("bottom_ship_mps")
        if bt is not None and MASS_S[0] <= t < MASS_S[1]:
            kw["bottom_ship_mps"] = tuple(round(v * MASS_SCALE, 3) for v in bt)
        return encode(**kw)

    return scaled


REPEAT_N = 3
"""``quantised-repeat``: emlog1's firmware updates its value every this many sentences
(3 s at 1 Hz), repeating the last one between ..."""

QUANTUM_KN = 0.1
"""... quantised to this, kn."""


class Repeating:
    """The VHW encoder of emlog1's firmware (:data:`REPEAT_N`, :data:`QUANTUM_KN`)."""

    def __init__(self) -> None:
        self.n = 0
        self.held = 0.0

    def __call__(self, v: float, *, talker: str) -> str:
        if talker == simsensors.EMLOG1.talker:
            if self.n % REPEAT_N == 0:
                self.held = round(v / KNOT_MPS / QUANTUM_KN) * QUANTUM_KN * KNOT_MPS
            self.n += 1
            v = self.held
        return encode_vhw(v, talker=talker)


EXACT = tuple(
    dataclasses.replace(e, params=Params("EM4", 0.0, 0.0, 0.0))
    for e in (simsensors.EMLOG1, simsensors.EMLOG2)
)
"""Both logs without error (EM4 with a = m = b = 0), their noise, lag and rate as
simulated: a log calibrated well before the daemon runs on it."""

HARBOUR_S = (240.0, 60.0, 30.0, 120.0)
"""``dead-band-harbour``: a stop and a start every 240 s of each trajectory, s: 60 s at
rest, 30 s speeding up to the trajectory's speed, 120 s under way, 30 s stopping (the
current as simulated carries the vessel at rest)."""


def harbour(k: Kinematics) -> Kinematics:
    """The speed through the water times the manoeuvres' envelope (:data:`HARBOUR_S`)."""
    period, rest, ramp, way = HARBOUR_S
    env = np.interp(
        np.mod(k.t, period),
        [0.0, rest, rest + ramp, rest + ramp + way, period],
        [0.0, 0.0, 1.0, 1.0, 0.0],
    )
    return dataclasses.replace(k, surge=k.surge * env, sway=k.sway * env)


DEAD_BAND_MPS = 0.5
"""``dead-band-harbour``: emlog2 reads zero below this reading, m/s (VHW and VBW);
``dead-band-harbour-1hz``: both logs."""


class DeadBand:
    """The sentences of the logs ``talkers`` reading 0.00 below :data:`DEAD_BAND_MPS`,
    the others' as sent."""

    def __init__(self, talkers: tuple[str, ...]) -> None:
        self.talkers = talkers

    def vhw(self, v: float, *, talker: str) -> str:
        if talker in self.talkers and v < DEAD_BAND_MPS:
            v = 0.0
        return encode_vhw(v, talker=talker)

    def vbw(self, long_: float, trans: float, *, talker: str) -> str:
        if talker in self.talkers and long_ < DEAD_BAND_MPS:
            long_ = 0.0
        return encode_vbw(long_, trans, talker=talker)


DEAD_BANDS = {
    "dead-band-harbour": (simsensors.EMLOG2.talker,),
    "dead-band-harbour-1hz": (simsensors.EMLOG1.talker, simsensors.EMLOG2.talker),
}
"""The worlds whose logs have a dead band: their talkers."""


FRONT_S = 600.0
"""``current-front``: the vessel crosses a front every this many seconds of the trial
(a river plume's edge, a tidal race): the current steps at once between ..."""

FRONT_CURRENTS = ((0.3, -0.1), (-0.3, 0.2))
"""... these two (east, north, m/s), 0.67 m/s apart."""


def _front(k: Kinematics, t0: float, period_s: float) -> Kinematics:
    t = t0 - START_EPOCH_S + k.t
    side = np.floor(t / period_s) % 2 == 1
    (e0, n0), (e1, n1) = FRONT_CURRENTS
    return dataclasses.replace(
        k, current_e=np.where(side, e1, e0), current_n=np.where(side, n1, n0)
    )


def current_front(k: Kinematics, t0: float) -> Kinematics:
    """The current stepping between :data:`FRONT_CURRENTS` every :data:`FRONT_S`."""
    return _front(k, t0, FRONT_S)


def current_front_5min(k: Kinematics, t0: float) -> Kinematics:
    """The same front crossed every 5 min (``current-front-gnss``: GNSS reference)."""
    return _front(k, t0, FRONT_S / 2.0)


WORLDS = {
    c.name: c
    for c in (
        Case("heel-gain", heel_gain.__doc__ or "", log_view=heel_gain),
        Case("sea-state-gain", sea_state_gain.__doc__ or "", log_world=sea_state_gain),
        Case("fouling-onset", fouling_onset.__doc__ or "", log_world=fouling_onset),
        Case("speed-knee", speed_knee.__doc__ or "", log_view=speed_knee),
        Case("dvl-water-mass", water_mass.__doc__ or "", dvl_wrap=water_mass),
        Case("quantised-repeat", Repeating.__doc__ or ""),
        Case("exact-logs", EXACT.__doc__ or "both logs without error"),
        Case("dead-band-harbour", "emlog2 with a dead band, stopping and starting", motion=harbour),
        Case("dead-band-harbour-1hz", "both logs with a dead band, the same", motion=harbour),
        Case("current-front", current_front.__doc__ or "", current=current_front),
        Case(
            "current-front-gnss",
            current_front_5min.__doc__ or "",
            cfg=simphysics.GNSS_CFG,
            current=current_front_5min,
        ),
    )
}

SENSORS: dict[str, tuple[int, tuple[simsensors.EmlogSpec, ...]]] = {
    "exact-logs": (1, EXACT),
    "dead-band-harbour": (2, EXACT),
    "dead-band-harbour-1hz": (2, EXACT),
}
"""The worlds whose logs are not the simulator's: the seed and the two logs. The dead
band is measured on seed 2, whose trial the exact logs pass (seed 1's is open:
:data:`OPEN`)."""

OPEN = {
    "exact-logs": "open: emlog2's window from 1201 s 1.558x raw (0.0784 vs 0.0503 m/s): a "
    "scale of -0.03 learnt on the transit's one heading while the simulated current "
    "turned (0.2 m/s in 20 min, the speed falling with it), applied at 1268 s after a "
    "turn; raw's own current and the common sea, fitted over 30 min of a current that "
    "moved, left raw 0.09 and 0.12 m/s against the candidate's 0.06 and 0.07 (a "
    "constant current: 1.000; seeds 2-5 with logs 1 % off: 1.000) (docs/RELIABILITY.md)",
    "current-front": "open: emlog1's window from 604 s 1.149x raw (0.686 vs 0.597 m/s): a "
    "scale of -0.115 (b 0; the sensor's +0.23) applied at 727 s for 65 s, validated against "
    "raw (0.487 vs 0.518) after each one's own current fitted over the supervisor's memory, "
    "whose samples span both sides of the front crossed at 600 s. The memory forgetting "
    "its samples at every jump of the sea fixed it (1.000, and a front every 5 min: 1.102 "
    "-> 1.000) but not the real recordings (Astra's worst window 1.586, Irene 2013 1.104, "
    "Psaros 1.074); at a jump on a heading held 60 s only: Irene 2013 1.104, Psaros 1.074, "
    "the 5-min front's emlog2 1.754 (docs/RELIABILITY.md)",
    "current-front-gnss": "open: emlog1's window from 904 s 1.330x raw: a scale of -0.213 "
    "(b 0; the sensor's +0.23) applied at 1111 s, validated against raw after each one's own "
    "current (0.087 vs 0.186) and in the common sea (1.08 vs 1.71), both fitted across the "
    "fronts at 900 and 1200 s; withdrawn at 1176 s by the re-check (docs/RELIABILITY.md)",
    "dead-band-harbour-1hz": "open: emlog1's window from 604 s 1.090x raw (0.0717 vs 0.0658 "
    "m/s): a scale of 0.041 (b 0) learnt and applied at 455 s while its lag was not yet "
    "measured (0 s used against 3.2 s; found at 1017 s), each ramp's readings paired 3.2 s "
    "off the reference; withdrawn at 656 s (docs/RELIABILITY.md)",
}
"""The worlds that break the promise, pinned as strict xfails until fixed."""

VHW_WORLDS: dict[str, Callable[[], Callable[..., str]]] = {"quantised-repeat": Repeating}
"""The worlds whose EMlogs' VHW encoder is replaced."""


def _measure(name: str, tmp: Path, mp: pytest.MonkeyPatch) -> dict[str, Any]:
    make = VHW_WORLDS.get(name)
    if make is not None:
        mp.setattr(simsensors, "encode_vhw", make())
    if name in DEAD_BANDS:
        band = DeadBand(DEAD_BANDS[name])
        mp.setattr(simsensors, "encode_vhw", band.vhw)
        mp.setattr(simsensors, "encode_vbw", band.vbw)
    if name in SENSORS:
        seed, logs = SENSORS[name]

        def with_logs(outdir: str | Path, **kw: Any) -> Any:
            return simulate(outdir, **(kw | {"seed": seed}), emlogs=(logs[0], logs[1]))

        mp.setattr(simphysics, "simulate", with_logs)
    return measure(WORLDS[name], tmp, mp)


def _k(n: int = 40000) -> Kinematics:
    t = np.arange(n, dtype=np.float64) * 0.1
    return Kinematics(
        t=t,
        surge=np.full(n, 2.5),
        sway=np.zeros(n),
        heading=np.radians(3.0) * t,  # 3 °/s
        current_e=np.zeros(n),
        current_n=np.zeros(n),
    )


class TestWorlds:
    """What each world changes, on a small grid (fast)."""

    def test_the_log(self) -> None:
        """Heel: 7.5° at 2.5 m/s and 3 °/s, −3.75 %; the sea: 4 % low inside its 20 min
        only; fouling: 4 % low half-way, 8 % after; the knee: +4 cm/s at 2.5 m/s."""
        k = _k()
        assert heel_gain(k).surge == pytest.approx(2.5 * (1.0 - 0.005 * 7.5))
        s = sea_state_gain(k, START_EPOCH_S + 1000.0)
        inside = (k.t + 1000.0 >= SEA_S[0]) & (k.t + 1000.0 < SEA_S[1])
        assert np.all(s.surge[~inside] == 2.5)
        assert float(np.mean(s.surge[inside])) == pytest.approx(2.4, abs=0.005)
        f = fouling_onset(k, START_EPOCH_S)
        at = [int(x * 10) for x in (800.0, 2100.0, 3500.0)]
        assert f.surge[at] == pytest.approx([2.5, 2.4, 2.3])
        assert speed_knee(k).surge == pytest.approx(2.54)
        assert speed_knee(dataclasses.replace(k, surge=k.surge - 1.0)).surge == pytest.approx(1.5)

    def test_the_dvl_and_the_firmware(self) -> None:
        """The water mass: the bottom track 1 % high inside :data:`MASS_S` only; the
        firmware: emlog1's value quantised and held for 3 sentences, emlog2's as sent."""
        seen: list[tuple[float, float, float]] = []

        def record(**kw: Any) -> list[str]:
            seen.append(kw["bottom_ship_mps"])
            return []

        enc = water_mass(record, _k(), START_EPOCH_S)
        for at in (100.0, 2500.0):
            stamp = datetime.fromtimestamp(START_EPOCH_S + at, UTC)
            enc(timestamp=stamp, heading_deg=0.0, bottom_ship_mps=(0.1, 2.0, 0.0))
        assert seen == [(0.1, 2.0, 0.0), (0.101, 2.02, 0.0)]
        rep = Repeating()
        talker = simsensors.EMLOG1.talker
        kn = [float(rep(v * KNOT_MPS, talker=talker).split(",")[5]) for v in (2.34, 2.5, 2.6, 2.71)]
        assert kn == [2.3, 2.3, 2.3, 2.7]
        assert ",2.34,N," in rep(2.34 * KNOT_MPS, talker=simsensors.EMLOG2.talker)

    def test_the_front(self) -> None:
        """The current one side of the front for :data:`FRONT_S`, then the other's, then
        back."""
        k = current_front(_k(), START_EPOCH_S + 100.0)
        at = [int(x * 10) for x in (0.0, 499.0, 500.0, 1099.0, 1100.0)]
        assert k.current_e[at] == pytest.approx([0.3, 0.3, -0.3, -0.3, 0.3])
        assert k.current_n[at] == pytest.approx([-0.1, -0.1, 0.2, 0.2, -0.1])
        k5 = current_front_5min(_k(), START_EPOCH_S + 100.0)
        assert k5.current_e[[0, 1990, 2000, 4990, 5000]] == pytest.approx(
            [0.3, 0.3, -0.3, -0.3, 0.3]
        )

    def test_the_harbour_and_the_dead_band(self) -> None:
        """The manoeuvres: at rest, half-way up, under way, half-way down, at rest; the dead
        band zeroes emlog2's readings below 0.5 m/s only, emlog1's never; the exact
        logs read what they see."""
        k = dataclasses.replace(_k(), surge=np.full(40000, 2.0))
        h = harbour(k).surge
        assert h[[300, 750, 1500, 2250, 2700]] == pytest.approx([0.0, 1.0, 2.0, 1.0, 0.0])
        t1, t2 = simsensors.EMLOG1.talker, simsensors.EMLOG2.talker
        band = DeadBand(DEAD_BANDS["dead-band-harbour"])
        assert ",0.00,N," in band.vhw(0.49, talker=t2)
        assert ",0.97,N," in band.vhw(0.5, talker=t2)
        assert ",0.95,N," in band.vhw(0.49, talker=t1)
        assert band.vbw(0.3, 0.1, talker=t2).startswith(f"${t2}VBW,0.00,")
        assert ",0.00,N," in DeadBand(DEAD_BANDS["dead-band-harbour-1hz"]).vhw(0.49, talker=t1)
        assert all(e.params.forward(2.0) == 2.0 for e in EXACT)


@pytest.mark.soak
@pytest.mark.parametrize("name", pinned(WORLDS, OPEN))
def test_every_window_within_raw(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    """Both logs: every 5-min window within 1.05 × raw's RMSE against the truth."""
    got = _measure(name, tmp_path, monkeypatch)
    assert max(v["worst"] for v in got.values()) <= RATIO, got


if __name__ == "__main__":
    for arg in sys.argv[1:] or sorted(WORLDS):
        with tempfile.TemporaryDirectory() as d, pytest.MonkeyPatch.context() as m:
            sys.stdout.write(json.dumps({arg: _measure(arg, Path(d), m)}, default=str) + "\n")
            sys.stdout.flush()
