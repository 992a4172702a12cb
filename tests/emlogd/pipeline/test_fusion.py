"""The fused speed: inverse-variance weighting, failover, and what reaches the outputs."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from calib.estimate import Estimate
from calib.models import Params
from drivers.framing import split_nmea
from drivers.nmea0183 import encode_rmc, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import FUSED_PORT, Emit, Output, Pipeline
from emlogd.pipeline.fusion import FLAT_S, STILL_S, Fused, Fusion, FusionSettings
from emlogd.pipeline.integrity import STUCK_BLOCK_S
from emlogd.pipeline.sentences import encode_fused_status
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.supervisor import RESTORE_WAIT_S


class TestFusion:
    """The weighted mean of the latest speeds."""

    def test_inverse_variance_weights(self) -> None:
        """Two logs that agree, σ 0.1 and 0.2: the mean leans 4:1 to the first; σ is
        1/√(Σ 1/σ²)."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        f.update("a", 0.0, 2.0, 0.1)
        fused = f.update("b", 0.1, 2.1, 0.2)
        assert fused is not None
        assert fused.speed_mps == pytest.approx((4 * 2.0 + 1 * 2.1) / 5)
        assert fused.std_mps == pytest.approx(1 / math.sqrt(100 + 25))
        assert fused.sources == ("a", "b")

    def test_a_silent_log_drops_out(self) -> None:
        """A log not heard for max_age_s no longer counts: the other carries on alone."""
        f = Fusion(FusionSettings(max_age_s=2.0, min_interval_s=0.0))
        f.update("a", 0.0, 2.0, 0.1)
        f.update("b", 0.0, 3.0, 0.1)
        fused = f.update("b", 2.5, 3.0, 0.1)
        assert fused is not None and fused.sources == ("b",) and fused.speed_mps == 3.0

    def test_rate_limit_and_bad_values(self) -> None:
        """At most one fused speed per min_interval_s; a non-finite speed is not kept."""
        f = Fusion(FusionSettings(min_interval_s=1.0))
        assert f.update("a", 0.0, 2.0, 0.1) is not None
        assert f.update("a", 0.5, 2.0, 0.1) is None
        f.update("b", 1.0, math.nan, 0.1)
        assert "b" not in f.latest


class TestStatusSentence:
    """$PEMLF: speed, σ, the number of sources and their names, within 82 characters."""

    def test_fields_and_length(self) -> None:
        """Knots with two decimals; names cut to fit; the count stays the true count."""
        fused = Fused(2.0 * KNOT_MPS, 0.05 * KNOT_MPS, tuple(f"emlog{i:02d}xx" for i in range(9)))
        s = encode_fused_status(fused, "EML")
        assert len(s) + 2 <= 82
        fields = split_nmea(s.encode()).decode().split(",")
        assert fields[:4] == ["PEMLF", "2.00", "0.05", "9"]
        assert fields[4].split(";")[0] == "emlog00xx"


def _pipeline(
    speed_only: bool = True,
    calibrated: str | tuple[str, ...] | None = None,
    param_std: dict[str, float] | None = None,
) -> Pipeline:
    names = (calibrated,) if isinstance(calibrated, str) else calibrated or ()
    cals = {
        u: Calibration(u, Estimate(Params("EM3", m=0.0, b_mps=0.0), param_std or {}), None)
        for u in names
    }
    return Pipeline(
        [PortSettings("a", "nmea0183"), PortSettings("b", "nmea0183"), PortSettings("dvl", "pd6")],
        [
            UutSettings(port="a", reference_port="dvl", lag_s=0.0),
            UutSettings(port="b", reference_port="dvl", lag_s=0.0),
        ],
        cals,
        fusion=FusionSettings(only=speed_only, min_interval_s=0.0),
    )


def _speeds(emits: list[Emit], port: str) -> list[float]:
    out = []
    for e in emits:
        if e.port == port and e.sentence[3:6] == "VHW":
            out.append(float(split_nmea(e.sentence.encode()).decode().split(",")[5]) * KNOT_MPS)
    return out


class TestPipeline:
    """What the autopilot receives with ``outputs.speed: fused``."""

    def test_one_stream_with_failover(self) -> None:
        """Only fused VHW (and status) go out; when log b falls silent, a carries on."""
        p = _pipeline()
        out = Output()
        t0 = 1_750_000_000.0
        for k in range(10):
            out.add(p.feed(t0 + k, "a", (encode_vhw(2.0) + "\r\n").encode()))
            if k < 5:
                out.add(p.feed(t0 + k + 0.5, "b", (encode_vhw(2.2) + "\r\n").encode()))
        assert not [e for e in out.emits if e.port in ("a", "b") and e.sentence[3:6] == "VHW"]
        fused = _speeds(out.emits, FUSED_PORT)
        # both uncalibrated: σ² = r_raw + (0.1·v)² + 0.1², the slower log weighs more
        wa, wb = 1 / (0.0514**2 + 0.04 + 0.01), 1 / (0.0514**2 + 0.0484 + 0.01)
        assert fused[1] == pytest.approx((2.0 * wa + 2.2 * wb) / (wa + wb), abs=0.01)
        assert fused[-1] == pytest.approx(2.0, abs=0.01)  # b silent for > 2 s
        assert any(e.sentence.startswith("$PEMLF") for e in out.emits)
        assert p.status()["fused"]["sources"] == ("a",)  # type: ignore[index]

    def test_a_calibrated_log_outweighs_an_uncalibrated_one(self) -> None:
        """Log a has a calibration (σ from its noise), b none (10 % + 0.1 m/s). (Restored
        without a reference, it is applied unverified RESTORE_WAIT_S after the first reading.)"""
        p = _pipeline(calibrated="a")
        out = Output()
        t0 = 1_750_000_000.0
        for k in range(3 * int(RESTORE_WAIT_S)):
            v = 2.0 + 0.02 * (k % 2)  # live: one flat for FLAT_S is left out as stuck
            out.add(p.feed(t0 + k, "a", (encode_vhw(v) + "\r\n").encode()))
        t0 += 3 * RESTORE_WAIT_S
        out.add(p.feed(t0, "a", (encode_vhw(2.0) + "\r\n").encode()))
        out.add(p.feed(t0 + 0.1, "b", (encode_vhw(3.0) + "\r\n").encode()))
        assert _speeds(out.emits, FUSED_PORT)[-1] == pytest.approx(2.0, abs=0.1)

    def test_both_keeps_each_logs_sentences(self) -> None:
        """``speed: both`` sends the logs' corrected sentences and the fused one."""
        p = _pipeline(speed_only=False)
        out = Output()
        out.add(p.feed(1_750_000_000.0, "a", (encode_vhw(2.0) + "\r\n").encode()))
        assert _speeds(out.emits, "a") and _speeds(out.emits, FUSED_PORT)

    def test_a_uut_called_fused_is_refused(self) -> None:
        """The fused output's port name cannot be a UUT's."""
        with pytest.raises(ValueError, match="fused"):
            Pipeline(
                [PortSettings("fused", "nmea0183"), PortSettings("dvl", "pd6")],
                [UutSettings(port="fused", reference_port="dvl")],
                fusion=FusionSettings(),
            )


# -- arbitration and plausibility on seeded synthetic streams -------------------------

T0 = 1_750_000_000.0
NOISE_MPS = 0.05
"""The simulated logs' reading noise, m/s (the DX900+'s 0.1 kn)."""


def _truth(t: np.ndarray) -> np.ndarray:
    """The true speed through the water: 2.8 m/s with slow 0.5 m/s swings."""
    return 2.8 + 0.5 * np.sin(2.0 * np.pi * t / 600.0) + 0.2 * np.sin(2.0 * np.pi * t / 97.0)


def _slow(t: np.ndarray) -> np.ndarray:
    """A slow true speed through the water: 0.36–0.41 m/s (the red team's)."""
    return 0.385 + 0.025 * np.sin(2.0 * np.pi * t / 600.0)


def _vhw(v: float) -> bytes:
    return (encode_vhw(max(v, 0.0)) + "\r\n").encode()


def _rmc(sog: float) -> bytes:
    return (encode_rmc(None, sog, 0.0) + "\r\n").encode()


def _gnss_pipeline() -> Pipeline:
    return Pipeline(
        [
            PortSettings("a", "nmea0183"),
            PortSettings("b", "nmea0183"),
            PortSettings("dvl", "pd6"),
            PortSettings("gps", "nmea0183"),
        ],
        [
            UutSettings(port="a", reference_port="dvl", lag_s=0.0),
            UutSettings(port="b", reference_port="dvl", lag_s=0.0),
        ],
        fusion=FusionSettings(only=True, min_interval_s=0.0),
    )


def _run_two_logs(
    p: Pipeline,
    duration_s: float,
    b_scale: Callable[[float], float],
    *,
    sog_offset: float | None = None,
    seed: int = 7,
    truth: Callable[[np.ndarray], np.ndarray] = _truth,
) -> tuple[Output, np.ndarray]:
    """Log a healthy, log b read × ``b_scale(t)``, both at 1 Hz (b 0.5 s after a), and
    optionally a GNSS speed over ground (truth + a current along the hull) at 1 Hz.
    Returns the output and log a's (t, raw reading) rows."""
    rng = np.random.default_rng(seed)
    out = Output()
    rows = []
    for k in range(int(duration_s)):
        t = float(k)
        va = float(truth(np.array([t]))[0] + rng.normal(0.0, NOISE_MPS))
        rows.append((t, round(va / KNOT_MPS, 2) * KNOT_MPS))
        out.add(p.feed(T0 + t, "a", _vhw(va)))
        tb = t + 0.5
        vb = float(truth(np.array([tb]))[0] * b_scale(tb) + rng.normal(0.0, NOISE_MPS))
        out.add(p.feed(T0 + tb, "b", _vhw(vb)))
        if sog_offset is not None:
            sog = float(truth(np.array([t + 0.7]))[0] + sog_offset + rng.normal(0.0, 0.1))
            out.add(p.feed(T0 + t + 0.7, "gps", _rmc(sog)))
    return out, np.array(rows)


def _fused(emits: list[Emit]) -> list[tuple[float, float | None]]:
    """The fused VHW's (time since T0, speed m/s or None when invalid)."""
    rows: list[tuple[float, float | None]] = []
    for e in emits:
        if e.port == FUSED_PORT and e.sentence[3:6] == "VHW":
            kn = split_nmea(e.sentence.encode()).decode().split(",")[5]
            rows.append((e.t - T0, float(kn) * KNOT_MPS if kn else None))
    return rows


def _pemlf(emits: list[Emit]) -> list[list[str]]:
    return [
        split_nmea(e.sentence.encode()).decode().split(",")
        for e in emits
        if e.sentence.startswith("$PEMLF")
    ]


def _window_check(
    fused: list[tuple[float, float | None]],
    a_rows: np.ndarray,
    end: float,
    truth: Callable[[np.ndarray], np.ndarray] = _truth,
) -> int:
    """Every 5-min window: the fused speed's RMSE against the truth is within 1.05 × log
    a's raw RMSE, or the fused output is marked invalid in that window. Returns the
    number of windows marked invalid."""
    invalid = 0
    for w0 in np.arange(0.0, end, 300.0):
        sel = [(t, v) for t, v in fused if w0 <= t < w0 + 300.0]
        if any(v is None for _, v in sel):
            invalid += 1
            continue
        tf = np.array([t for t, _ in sel])
        vf = np.array([v for _, v in sel])
        rmse_f = float(np.sqrt(np.mean((vf - truth(tf)) ** 2)))
        ra = a_rows[(a_rows[:, 0] >= w0) & (a_rows[:, 0] < w0 + 300.0)]
        rmse_a = float(np.sqrt(np.mean((ra[:, 1] - truth(ra[:, 0])) ** 2)))
        assert rmse_f <= 1.05 * rmse_a, (w0, rmse_f, rmse_a)
    return invalid


class TestArbitration:
    """Logs that disagree are never averaged: the fusion follows the log whose history
    is unchanged (or GNSS decides), or the output is marked invalid."""

    def test_a_log_that_goes_wrong_is_left_out(self) -> None:
        """Log b reads 1.78× from minute 10 on (no reference): in every 5-min window the
        fused speed is within 1.05× of the healthy log's raw RMSE; $PEMLF names b excluded
        (its break) and a alone used."""
        p = _pipeline()
        out, rows = _run_two_logs(p, 1800.0, lambda t: 1.78 if t >= 600.0 else 1.0)
        fused = _fused(out.emits)
        assert _window_check(fused, rows, 1800.0) == 0
        last = _pemlf(out.emits)[-1]
        assert last[3:7] == ["1", "a", "A", "b:break"]
        st = p.status()["fused"]
        assert st["sources"] == ("a",) and st["excluded"] == {"b": "break"}  # type: ignore[index]

    def test_disagreement_from_the_start_is_marked_invalid(self) -> None:
        """Log b reads 1.78× from the start, nothing tells which is right: the fused VHW
        has no speed and $PEMLF says V with both logs excluded — never their average."""
        p = _pipeline()
        out, rows = _run_two_logs(p, 600.0, lambda t: 1.78)
        fused = _fused(out.emits)
        # the smoothed difference crosses the gate within seconds; nothing averaged after
        assert all(v is None for t, v in fused if t > 10.0)
        assert _window_check(fused, rows, 600.0) == 2
        last = _pemlf(out.emits)[-1]
        assert last[1] == "" and last[3:7] == ["0", "", "V", "a:disagree;b:disagree"]
        assert p.status()["fused"]["valid"] is False  # type: ignore[index]

    def test_gnss_decides_between_disagreeing_logs(self) -> None:
        """Log b reads 2× from the start; GNSS speed over ground (0.3 m/s of current)
        is within the current's bound of a only: the fusion follows a."""
        p = _gnss_pipeline()
        out, rows = _run_two_logs(p, 900.0, lambda t: 2.0, sog_offset=0.3)
        fused = _fused(out.emits)
        assert all(v is not None for t, v in fused if t > 10.0)
        _window_check(fused, rows, 900.0)
        assert _pemlf(out.emits)[-1][3:7] == ["1", "a", "A", "b:gnss"]

    def test_a_plausible_step_at_slow_speed_is_left_out(self) -> None:
        """The red team's case: 0.36–0.41 m/s, log b reads 1.78× from minute 10 on — a
        0.3 m/s jump, plausible as a reading, but a step from its own prediction that
        log a does not make: b is left out from its first stepped sample, and every
        window holds to 1.05× the healthy log's raw RMSE."""
        p = _pipeline()
        out, rows = _run_two_logs(p, 1800.0, lambda t: 1.78 if t >= 600.0 else 1.0, truth=_slow)
        fused = _fused(out.emits)
        assert _window_check(fused, rows, 1800.0, _slow) == 0
        assert _pemlf(out.emits)[-1][3:7] == ["1", "a", "A", "b:step"]
        a_at = dict(zip(rows[:, 0], rows[:, 1], strict=True))
        after = [(t, v) for t, v in fused if t >= 601.0]
        assert len(after) > 2000
        for t, v in after:  # log a's own reading, to the knots field's 0.01
            assert v is not None and abs(v - a_at[math.floor(t)]) < 0.006

    def test_a_stuck_log_is_left_out(self) -> None:
        """Log b freezes at its reading of t = 300.5 s while a keeps moving: b is left
        out as stuck within 10 s, and every window holds to 1.05× a's raw RMSE."""
        p = _pipeline()
        rng = np.random.default_rng(5)
        out = Output()
        rows = []
        frozen = None
        for k in range(1200):
            t = float(k)
            va = float(_truth(np.array([t]))[0] + rng.normal(0.0, NOISE_MPS))
            rows.append((t, round(va / KNOT_MPS, 2) * KNOT_MPS))
            out.add(p.feed(T0 + t, "a", _vhw(va)))
            vb = float(_truth(np.array([t + 0.5]))[0] + rng.normal(0.0, NOISE_MPS))
            if k >= 300:
                frozen = vb if frozen is None else frozen
                vb = frozen
            out.add(p.feed(T0 + t + 0.5, "b", _vhw(vb)))
        fused = _fused(out.emits)
        assert _window_check(fused, np.array(rows), 1200.0) == 0
        stuck = [
            e for e in out.emits if e.sentence.startswith("$PEMLF") and "b:stuck" in e.sentence
        ]
        assert stuck and stuck[0].t - T0 <= 311.0
        assert _pemlf(out.emits)[-1][3:7] == ["1", "a", "A", "b:stuck"]

    def test_a_stuck_log_with_noise_is_left_out(self) -> None:
        """Log b reads 3.00 ± 0.03 m/s from t = 300 s while a keeps moving (0.2 m/s swings
        every 97 s): its noise keeps it from being flat, but its block means stop
        following a's, so it is left out as stuck within STILL_S and one block, and from
        then on the fused speed is a's reading. Before, it stayed in the mean (the gate
        of two uncalibrated logs is about 1 m/s wide) and pulled the fused speed."""
        p = _pipeline()
        out, rows = _run_two_logs(p, 300.0, lambda t: 1.0)
        rng = np.random.default_rng(13)
        for k in range(300, 1200):
            t = float(k)
            va = float(_truth(np.array([t]))[0] + rng.normal(0.0, NOISE_MPS))
            rows = np.vstack([rows, [t, round(va / KNOT_MPS, 2) * KNOT_MPS]])
            out.add(p.feed(T0 + t, "a", _vhw(va)))
            out.add(p.feed(T0 + t + 0.5, "b", _vhw(3.0 + rng.normal(0.0, 0.03))))
        stuck = [e.t - T0 for e in out.emits if e.port == FUSED_PORT and "b:stuck" in e.sentence]
        assert stuck and stuck[0] <= 300.0 + STILL_S + STUCK_BLOCK_S
        a_at = dict(zip(rows[:, 0], rows[:, 1], strict=True))
        after = [(t, v) for t, v in _fused(out.emits) if t >= stuck[0] + 1.0]
        assert len(after) > 1000
        for t, v in after:
            assert v is not None and abs(v - a_at[math.floor(t)]) < 0.006
        assert _pemlf(out.emits)[-1][3:7] == ["1", "a", "A", "b:stuck"]

    @pytest.mark.parametrize("noise_mps", [0.0, 0.03], ids=["exact", "noisy"])
    def test_a_stuck_log_alone_beside_a_babbler_is_marked_invalid(self, noise_mps: float) -> None:
        """From t = 300 s log a reads 3.00 m/s (exactly, or ± 0.03 m/s of noise) while
        log b babbles at 50 Hz with 0–14 kn; no reference: nothing vouches for a. Within
        FLAT_S (exactly) or STILL_S and one block (noisy) the fused VHW has no speed and
        $PEMLF says V, naming a still; no fused speed after that presents a's reading as
        valid. Before, a's reading went out as the valid fused speed."""
        p = _pipeline()
        rng = np.random.default_rng(11)
        out = Output()
        for k in range(600):
            t = float(k)
            if k < 300:
                va = float(_truth(np.array([t]))[0] + rng.normal(0.0, NOISE_MPS))
                vb = float(_truth(np.array([t + 0.5]))[0] + rng.normal(0.0, NOISE_MPS))
                out.add(p.feed(T0 + t, "a", _vhw(va)))
                out.add(p.feed(T0 + t + 0.5, "b", _vhw(vb)))
                continue
            out.add(p.feed(T0 + t, "a", _vhw(3.0 + rng.normal(0.0, noise_mps))))
            for j in range(50):
                babble = float(rng.uniform(0.0, 14.0)) * KNOT_MPS
                out.add(p.feed(T0 + t + 0.01 + j / 50.0, "b", _vhw(babble)))
        fused = _fused(out.emits)
        assert all(v is not None for t, v in fused if t < 300.0)
        within = FLAT_S + 1.0 if noise_mps == 0.0 else STILL_S + STUCK_BLOCK_S
        late = [v for t, v in fused if t >= 300.0 + within]
        assert len(late) > 200 and all(v is None for v in late)
        last = _pemlf(out.emits)[-1]
        assert last[1] == "" and last[3:6] == ["0", "", "V"]
        assert "a:still" in last[6].split(";")
        st = p.status()["fused"]
        assert st["valid"] is False and st["excluded"]["a"] == "still"  # type: ignore[index]

    def test_a_log_reading_zero_leaves_at_its_first_sample(self) -> None:
        """Log b drops to 0.00 at t = 300.5 s: the zero is not sent, the fused speed sent
        next (a's reading at 301 s) and its $PEMLF already leave b out; it never comes
        near b's zero."""
        p = _pipeline()
        out, _ = _run_two_logs(p, 400.0, lambda t: 0.0 if t >= 300.0 else 1.0)
        fused = _fused(out.emits)
        after = [(t, v) for t, v in fused if t >= 300.5]
        assert after[0][0] == 301.0
        for t, v in after:
            assert v is not None and abs(v - float(_truth(np.array([t]))[0])) < 0.3
        status = [e for e in out.emits if e.sentence.startswith("$PEMLF") and e.t >= T0 + 300.5]
        first = split_nmea(status[0].sentence.encode()).decode().split(",")
        assert status[0].t == T0 + 301.0 and first[3:7] == ["1", "a", "A", "b:accel"]
        assert p.status()["uuts"]["b"]["counters"]["implausible_accel"] > 0  # type: ignore[index]


class _Learnt:
    """A recorder of the readings queued for learning."""

    def __init__(self) -> None:
        self.readings: list[tuple[float, float]] = []

    def reference(self, t: float, v: float | None, valid: bool, h: float | None) -> None:
        pass

    def reading(self, t: float, raw_mps: float) -> None:
        self.readings.append((t, raw_mps))


def _one_log() -> tuple[Pipeline, _Learnt]:
    p = Pipeline(
        [PortSettings("a", "nmea0183"), PortSettings("dvl", "pd6")],
        [UutSettings(port="a", reference_port="dvl", lag_s=0.0)],
    )
    rec = _Learnt()
    p.uuts["a"].cal.recorder = rec
    return p, rec


class TestPlausibility:
    """Readings a vessel cannot produce are neither emitted nor learnt, and counted."""

    @pytest.mark.parametrize("rate_hz", [1, 10])
    def test_a_spike_never_goes_out(self, rate_hz: int) -> None:
        """A 3-s spike to 7.9 m/s from 2.8 m/s (at 1 and 10 Hz): no sentence above 3 m/s,
        nothing learnt from it, each spike reading counted; the log carries on after."""
        p, rec = _one_log()
        out = Output()
        n = 60 * rate_hz
        spike = range(30 * rate_hz, 33 * rate_hz)
        for k in range(n):
            v = 7.9 if k in spike else 2.8
            out.add(p.feed(T0 + k / rate_hz, "a", _vhw(v)))
        speeds = _speeds(out.emits, "a")
        assert max(speeds) < 3.0 and len(speeds) == n - len(spike)
        assert max(v for _, v in rec.readings) < 3.0
        counters = p.status()["uuts"]["a"]["counters"]  # type: ignore[index]
        assert counters["implausible_accel"] == len(spike)

    def test_a_babbling_log_emits_at_most_its_nominal_rate(self) -> None:
        """1 Hz for a minute, then a minute of 100 Hz babble of 0–14 kn: beyond the
        rate's bucket nothing goes out nor is learnt (every reading counted as rate)
        until the log has kept its rate for 10 s again."""
        p, rec = _one_log()
        out = Output()
        rng = np.random.default_rng(3)
        for k in range(60):
            out.add(p.feed(T0 + k, "a", _vhw(2.8 + rng.normal(0.0, NOISE_MPS))))
        n_before = len(_speeds(out.emits, "a"))
        for k in range(6000):
            out.add(p.feed(T0 + 60.0 + k / 100.0, "a", _vhw(rng.uniform(0.0, 14.0) * KNOT_MPS)))
        babble = _speeds(out.emits, "a")[n_before:]
        # the bucket's two, judged for acceleration, then nothing while it babbles
        assert len(babble) <= 2 and all(abs(v - 2.8) < 1.3 for v in babble)
        counters = p.status()["uuts"]["a"]["counters"]  # type: ignore[index]
        assert counters["implausible_rate"] >= 6000 - 2
        assert len(rec.readings) <= 60 + 2
        # back at 1 Hz from 121 s: heard again once it has kept its rate for 10 s (130 s)
        for k in range(30):
            out.add(p.feed(T0 + 121.0 + k, "a", _vhw(2.8 + rng.normal(0.0, NOISE_MPS))))
        assert len(_speeds(out.emits, "a")) - n_before - len(babble) == 21

    def test_a_log_babbling_in_bursts_is_babbling(self) -> None:
        """A minute at 10 Hz, one sentence a read; then reads of 20 sentences of 0–14 kn
        every 0.1 s (a babble as a serial port delivers it: one receive time a read).
        A read holding more readings than its time since the last earned at the rate
        (READ_SLACK) is dropped for the rate: nothing of the babble goes out, nothing
        is learnt, each read's newest counted as rate. Only the newest was
        judged, at one a read, the log's own rate: the ones within the acceleration
        bound of the last accepted went out (and, fused, won over a stuck log)."""
        p, rec = _one_log()
        n_learnt = 0
        out = Output()
        rng = np.random.default_rng(4)
        for k in range(600):
            out.add(p.feed(T0 + k / 10.0, "a", _vhw(2.8 + rng.normal(0.0, NOISE_MPS))))
        n_before, n_learnt = len(_speeds(out.emits, "a")), len(rec.readings)
        for k in range(300):
            burst = b"".join(_vhw(rng.uniform(0.0, 14.0) * KNOT_MPS) for _ in range(20))
            out.add(p.feed(T0 + 60.0 + k / 10.0, "a", burst))
        assert len(_speeds(out.emits, "a")) == n_before and len(rec.readings) == n_learnt
        counters = p.status()["uuts"]["a"]["counters"]  # type: ignore[index]
        assert counters["implausible_rate"] == 300 and counters["implausible_accel"] == 0

    def test_a_stall_released_at_once_is_no_babble(self) -> None:
        """A 10 Hz log whose readings of 2 s come in one read (a USB-serial stall), five
        times a minute: each read's newest goes out; nothing is counted as rate."""
        p, _ = _one_log()
        out = Output()
        rng = np.random.default_rng(5)
        t = 0.0
        for k in range(600):
            t = k / 10.0
            out.add(p.feed(T0 + t, "a", _vhw(2.8 + rng.normal(0.0, NOISE_MPS))))
        for _ in range(5):
            t += 2.0
            burst = b"".join(_vhw(2.8 + rng.normal(0.0, NOISE_MPS)) for _ in range(20))
            out.add(p.feed(T0 + t, "a", burst))
            for _ in range(100):
                t += 0.1
                out.add(p.feed(T0 + t, "a", _vhw(2.8 + rng.normal(0.0, NOISE_MPS))))
        assert len(_speeds(out.emits, "a")) == 600 + 5 * 101
        counters = p.status()["uuts"]["a"]["counters"]  # type: ignore[index]
        assert counters["implausible_rate"] == 0 and counters["backlog"] == 5 * 19

    def test_a_lone_stuck_log_without_a_reference_goes_out_as_read(self) -> None:
        """One log, not fused, no reference: stuck at 3.0 ± 0.03 m/s after 300 s of
        moving. Nothing can tell it from a steady speed: its readings go out as read
        (never corrected), and the status says uncalibrated with the reference stale."""
        p, _ = _one_log()
        rng = np.random.default_rng(1)
        out = Output()
        raw = []
        for k in range(600):
            t = float(k)
            v = float(_truth(np.array([t]))[0] + rng.normal(0.0, NOISE_MPS))
            if k >= 300:
                v = 3.0 + rng.normal(0.0, 0.03)
            raw.append(round(v / KNOT_MPS, 2) * KNOT_MPS)
            out.add(p.feed(T0 + t, "a", _vhw(v)))
        speeds = _speeds(out.emits, "a")
        assert speeds[300:] == pytest.approx(raw[300:], abs=0.006)
        pemls = [e.sentence for e in out.emits if e.sentence.startswith("$PEMLS")][-1]
        assert split_nmea(pemls.encode()).decode().split(",")[2::9] == ["U", "S"]
        st = p.status()["uuts"]["a"]  # type: ignore[index]
        assert st["state"] == "uncalibrated" and st["reference"] == "stale"

    def test_a_log_back_from_zero_is_judged_against_its_last_moving_level(self) -> None:
        """Dropouts to 0.00 are refused; a log that re-acquired zero (dead for 15 s) and
        comes back at the speed it had is accepted at once, not after 10 s."""
        p, _ = _one_log()
        out = Output()
        seq = [2.8] * 30 + [0.0] * 15 + [2.9] * 5
        for k, v in enumerate(seq):
            out.add(p.feed(T0 + k, "a", _vhw(v)))
        speeds = _speeds(out.emits, "a")
        # 10 zeros refused, then zero re-acquired; 2.9 at once
        assert speeds[-5:] == pytest.approx([2.9] * 5, abs=0.006)
        counters = p.status()["uuts"]["a"]["counters"]  # type: ignore[index]
        assert counters["implausible_accel"] == 10


class TestDisputeRules:
    """The rules that decide a dispute, on the fusion alone (1 Hz, σ 0.05)."""

    @staticmethod
    def _feed(f: Fusion, t: float, va: float, vb: float, **kw: bool) -> Fused | None:
        f.update("a", t, va, 0.05, calibrated=kw.get("a_cal", False))
        return f.update("b", t + 0.5, vb, 0.05, calibrated=kw.get("b_cal", False))

    def test_a_flat_log_loses(self) -> None:
        """Log b stays at 3.00 while a moves, then a slows to 2.5: b (flat for 10 s
        while a moves) is left out as stuck."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        fused = None
        for k in range(60):
            va = 3.0 + 0.02 * (k % 3) if k < 40 else 2.5 + 0.02 * (k % 3)
            fused = self._feed(f, float(k), va, 3.0)
        assert fused is not None and fused.sources == ("a",)
        assert fused.excluded == (("b", "stuck"),)

    def test_a_still_log_loses_to_one_that_moves_without_a_step(self) -> None:
        """Both logs at 3.0 ± 0.01 m/s for a minute, then b speeds up 0.004 m/s per second
        (no step, less than MOVE_SPAN_MPS a minute) while a stays: when they come to
        disagree, a — still, its block means within their noise — is left out."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        rng = np.random.default_rng(2)
        fused = None
        for k in range(150):
            ramp = 0.004 * max(k - 60, 0)
            va, vb = 3.0 + rng.normal(0.0, 0.01), 3.0 + ramp + rng.normal(0.0, 0.01)
            fused = self._feed(f, float(k), va, vb)
        assert fused is not None and fused.sources == ("b",)
        assert fused.excluded == (("a", "still"),)

    def test_the_uncalibrated_log_loses(self) -> None:
        """Two moving logs 0.5 m/s apart, a calibrated: b is left out as uncalibrated."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        fused = None
        for k in range(30):
            v = 2.8 + 0.02 * (k % 3)
            fused = self._feed(f, float(k), v, v + 0.5, a_cal=True)
        assert fused is not None and fused.sources == ("a",)
        assert fused.excluded == (("b", "uncalibrated"),)

    def test_the_minority_loses(self) -> None:
        """Three logs, c 0.5 m/s off the two others: c is left out, a and b averaged."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        fused = None
        for k in range(30):
            v = 2.8 + 0.02 * (k % 3)
            f.update("a", k, v, 0.05)
            f.update("b", k + 0.3, v + 0.01, 0.05)
            fused = f.update("c", k + 0.6, v + 0.5, 0.05)
        assert fused is not None and sorted(fused.sources) == ["a", "b"]
        assert fused.excluded == (("c", "minority"),)

    def test_logs_that_agree_again_rejoin(self) -> None:
        """A dispute ends after the logs agree for rejoin_s: both are averaged again."""
        f = Fusion(FusionSettings(min_interval_s=0.0, rejoin_s=30.0))
        for k in range(30):
            w = 0.02 * (k % 3)
            fused = self._feed(f, float(k), 2.8 + w, 3.5 + w)
        assert fused is not None and not fused.valid
        for k in range(30, 80):
            w = 0.02 * (k % 3)
            fused = self._feed(f, float(k), 2.8 + w, 2.8 + w)
            if k < 55:  # smoothing, then 30 s of agreement
                assert fused is not None and not fused.valid
        assert fused is not None and fused.sources == ("a", "b")

    def test_a_step_against_a_flat_log_decides_nothing(self) -> None:
        """Log b has been flat for 6 s when a steps (the vessel's real change): a is not
        blamed — the output is invalid until b, flat for 10 s, is left out as stuck."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        for k in range(60):
            w = 0.02 * (k % 3)
            self._feed(f, float(k), 2.8 + w, 2.8 + (w if k < 54 else 0.0))
        fused = self._feed(f, 60.0, 3.6, 2.8)
        assert fused is not None and not fused.valid
        for k in range(61, 66):
            fused = self._feed(f, float(k), 3.6 + 0.02 * (k % 3), 2.8)
        assert fused is not None and fused.sources == ("a",)
        assert fused.excluded == (("b", "stuck"),)


ALTERNATING: dict[str, Callable[[float], float]] = {
    "two values": lambda t: (1.0, 0.96)[int(t) % 2],
    "three values": lambda t: (1.0, 1.04, 0.96)[int(t) % 3],
}
"""Log b's reading × these, sample by sample: within the gate of a dispute, never a step."""


@pytest.mark.parametrize("scale", ALTERNATING.values(), ids=ALTERNATING.keys())
def test_a_log_alternating_between_values_counts_for_its_spread(
    scale: Callable[[float], float],
) -> None:
    """Log b alternating sample by sample between readings 4 % apart, next to a healthy
    log a, both calibrated, no reference, 20 min: the fused speed is no worse than log
    a's raw reading (b weighted by its own spread about its prediction, not by its
    output σ alone). Weighted by the output σ, b counted as much as a: fused RMSE 0.056
    and 0.057 m/s against a's 0.048."""
    pair = _pipeline(calibrated=("a", "b"), param_std={"m": 0.001, "b": 0.002})
    out, rows = _run_two_logs(pair, 1200.0, scale)
    fused = [(t, v) for t, v in _fused(out.emits) if v is not None]
    assert len(fused) > 2000
    t = np.array([x for x, _ in fused])
    err = np.array([v for _, v in fused]) - _truth(t)
    raw = rows[:, 1] - _truth(rows[:, 0])
    assert np.sqrt(np.mean(err**2)) <= np.sqrt(np.mean(raw**2))
