"""Offline calibration on the simulated trial: lag, fits, identifiability, files, crossval."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from calib.excitation import Identifiability, identifiability
from calib.models import Params
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.offline import jobs
from emlogd.offline.dataset import Recording
from emlogd.offline.importer import import_nmea
from emlogd.offline.jobs import (
    WORSE_THAN_RAW,
    OfflineError,
    calibrate,
    crossval,
    evaluate,
    find_lag,
    load_captures,
    load_params,
    save_params,
)
from emlogd.offline.replay import replay
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings

E1 = UutSettings(port="emlog1", reference_port="dvl")
E1C = dataclasses.replace(E1, current=True)

Read = Callable[[Sequence[Path], UutSettings], list[Recording]]


@pytest.fixture(scope="module")
def read() -> Read:
    """:func:`load_captures` with each capture read once per UUT settings for the module
    (the multi-capture, parallel read itself: ``test_crossval_asks_for_no_more_processes_than_cores``).
    The recordings are shared read-only: a job that wrote into one would raise."""
    cache: dict[tuple[str, str], Recording] = {}

    def load(paths: Sequence[Path], settings: UutSettings) -> list[Recording]:
        for p in paths:
            key = (str(p), repr(settings))
            if key not in cache:
                (rec,) = load_captures([p], settings)
                for f in dataclasses.fields(rec):
                    value = getattr(rec, f.name)
                    if isinstance(value, np.ndarray):
                        value.flags.writeable = False
                cache[key] = rec
        return [cache[(str(p), repr(settings))] for p in paths]

    return load


class TestLag:
    """The lag over whole captures."""

    def test_lag_is_found_near_the_truth(self, trial_files: dict[str, Path], read: Read) -> None:
        """EMlog1's 3.2 s (+0.1 s of 4800-baud transmission) within 0.3 s, with the current modelled."""
        recs = read([trial_files["figure-8"], trial_files["circles"]], E1C)
        lag = find_lag(recs, E1C, None)
        assert lag.source == "auto", lag.note
        assert lag.lag_s == pytest.approx(3.3, abs=0.3)
        assert set(lag.per_capture) == {"2-figure8", "4-circles"}

    def test_given_lag_and_fallback(self, trial_files: dict[str, Path], read: Read) -> None:
        """A given lag is used as is; a non-finite one is an error."""
        recs = read([trial_files["straight"]], E1)
        assert find_lag(recs, E1, 3.2).source == "given"
        found = find_lag(recs, E1, None)
        assert found.source in ("fallback", "auto")
        assert found.lag_s >= 0.0
        with pytest.raises(OfflineError, match="finite"):
            find_lag(recs, E1, float("nan"))


class TestCalibrate:
    """Fits and their verdicts."""

    @pytest.mark.parametrize("method", ["ls", "kf"])
    def test_figure8_calibration_cuts_the_error(
        self, trial_files: dict[str, Path], method: str, read: Read
    ) -> None:
        """LS and KF on the figure-8 cut the error by ≥ 60 % and report every key."""
        recs = read([trial_files["figure-8"]], E1)
        res = calibrate(recs, E1, method, lag=3.3)  # type: ignore[arg-type]
        assert res.identifiable, res.ident.reason
        assert res.rmse_raw > 0.4
        assert res.improvement_pct >= 60.0
        d = res.to_dict()
        for key in (
            "model", "method", "params", "stderr", "lag_s", "rmse_raw", "rmse_cal",
            "improvement_pct", "identifiable", "unidentifiable", "condition_number", "current",
        ):  # fmt: skip
            assert key in d
        assert isinstance(d["params"], dict) and set(d["params"]) == {"m", "b"}
        assert d["unidentifiable"] == [] and d["current"] is None
        if method == "kf":
            assert d["nis_mean"] is not None

    def test_with_the_current(self, trial_files: dict[str, Path], read: Read) -> None:
        """With the current, circles give the current; the scale is reported undetermined or not."""
        recs = read([trial_files["circles"]], E1C)
        res = calibrate(recs, E1C, "ls", lag=3.3)
        d = res.to_dict()
        assert d["current"] is not None
        assert isinstance(d["current"], dict)
        assert set(d["current"]) == {"north_mps", "east_mps", "std_north_mps", "std_east_mps"}
        assert d["identifiable"] is (d["unidentifiable"] == [])

    def test_one_rmse_definition_for_both_methods(
        self, trial_files: dict[str, Path], tmp_path: Path, read: Read
    ) -> None:
        """With the current, LS and KF report the same raw RMSE (the water frame does not
        depend on the method), and the KF reports a current exactly when its trace's last
        row says it is determined."""
        recs = read([trial_files["circles"]], E1C)
        trace = tmp_path / "t.csv"
        ls = calibrate(recs, E1C, "ls", lag=3.3)
        kf = calibrate(recs, E1C, "kf", lag=3.3, trace=trace)
        assert kf.rmse_raw == pytest.approx(ls.rmse_raw, rel=1e-12)
        last = trace.read_text().splitlines()[-1].split(",")
        header = trace.read_text().splitlines()[0].split(",")
        determined = last[header.index("current_determined")] == "1"
        assert (kf.current_mps is not None) is determined
        assert kf.noise_scale is not None and ls.noise_scale is None

    def test_worse_than_raw_is_not_identifiable(
        self, trial_files: dict[str, Path], read: Read
    ) -> None:
        """A calibration whose RMSE exceeds the raw one is not called identifiable, and says why."""
        recs = read([trial_files["figure-8"]], E1)
        res = calibrate(recs, E1, "ls", lag=3.3)
        assert res.identifiable and res.reason == ""
        worse = dataclasses.replace(res, rmse_cal=2.0 * res.rmse_raw)
        assert worse.ident.identifiable and not worse.identifiable
        assert worse.reason == WORSE_THAN_RAW
        assert worse.to_dict()["identifiable"] is False

    def test_straight_run_holds_the_scale(self, trial_files: dict[str, Path], read: Read) -> None:
        """The straight run determines no scale: unidentifiable, held at the ideal sensor's."""
        recs = read([trial_files["straight"]], E1)
        res = calibrate(recs, E1, "ls", lag=3.3)
        assert res.ident.unidentifiable == ("m",)
        assert "constant" in res.ident.reason and res.params.m == 0.0
        assert res.to_dict()["stderr"]["m"] is None  # type: ignore[index]

    def test_kf_holds_an_undetermined_unknown_at_its_prior(
        self, trial_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch, read: Read
    ) -> None:
        """Where the whole run's verdict leaves the bias undetermined (here forced, as on a
        recording whose speed varied only in its last minutes), the filter's bias is
        reported at its prior and the scale conditioned on it: the scale then takes what
        the bias held of the offset, as least squares holding the bias fits it."""
        recs = read([trial_files["figure-8"]], E1)
        free = calibrate(recs, E1, "kf", lag=3.3)
        assert free.ident.identifiable and abs(free.params.b_mps) > 0.05

        def without_bias(*args: Any, **kw: Any) -> Identifiability:
            v = identifiability(*args, **kw)
            held = tuple(
                dataclasses.replace(x, determined=False, reason="forced", std=None)
                if x.unknown == "b"
                else x
                for x in v.verdicts
            )
            return dataclasses.replace(v, verdicts=held)

        monkeypatch.setattr(jobs, "identifiability", without_bias)
        held = calibrate(recs, E1, "kf", lag=3.3)
        assert held.params.b_mps == 0.0 and held.to_dict()["stderr"]["b"] is None  # type: ignore[index]
        # the scale moved along the valley: better than the free scale with the bias zeroed
        assert abs(held.params.m - free.params.m) > 0.01
        (zeroed,) = evaluate(recs, Params("EM3", m=free.params.m), E1, 3.3)
        assert held.rmse_cal < zeroed.rmse_cal

    def test_relative_calibration_against_the_other_emlog(
        self, trial_files: dict[str, Path], read: Read
    ) -> None:
        """A UUT calibrates against another EMlog's speed."""
        rel = UutSettings(port="emlog1", reference_port="emlog2", reference_field="speed")
        recs = read([trial_files["figure-8"]], rel)
        res = calibrate(recs, rel, "ls", lag=2.8)
        assert res.n_samples > 100 and res.rmse_cal < res.rmse_raw

    def test_kf_agrees_with_replay(self, trial_files: dict[str, Path]) -> None:
        """calibrate --method kf is the daemon's filter fed the same capture with the same
        settings: the replay's filter, with what the whole run leaves undetermined held at
        its prior (the figure-8 in the current does not separate the scale from it), gives
        the same parameters exactly, and its raw estimate the status's."""
        path = trial_files["figure-8"]
        settings = dataclasses.replace(E1C, lag_s=3.3)
        res = calibrate(load_captures([path], settings), settings, "kf", lag=3.3)
        held = [k for k in res.ident.unidentifiable if k in res.params.as_dict()]
        assert held == ["m"]
        ports = [PortSettings(n, p) for n, p in CaptureReader(path).ports.items()]
        pipeline = Pipeline(ports, [settings])
        replay(pipeline, [path])
        kf = pipeline.uuts["emlog1"].cal.kf
        est = pipeline.status()["uuts"]["emlog1"]["estimate"]  # type: ignore[index]
        for k, v in kf.params.as_dict().items():
            assert est[k] == pytest.approx(v, abs=1e-9)
        conditioned = kf.copy()
        conditioned.condition({k: 0.0 for k in held})
        for k, v in res.params.as_dict().items():
            assert conditioned.params.as_dict()[k] == pytest.approx(v, abs=1e-9)


def _recording(dt_ref: float, heading: float, valid: bool = True) -> Recording:
    """A UUT read at 1 Hz for 10 min against a reference every ``dt_ref`` s."""
    t_read = np.arange(0.5, 600.0, 1.0)
    t_ref = np.arange(0.0, 600.0, dt_ref)
    return Recording(
        path="x.cap",
        uut="log",
        ports={"log": "nmea0183"},
        t_read=t_read,
        raw=np.full(t_read.size, 3.0),
        t_ref=t_ref,
        v_ref=np.full(t_ref.size, 3.0),
        ok_ref=np.full(t_ref.size, valid),
        heading=np.full(t_ref.size, heading),
        counters={},
        uut_counters={},
        t_start=0.0,
        t_end=600.0,
        heading_info={"port": "log"} if math.isfinite(heading) else {},
    )


class TestStalledReadings:
    """Least squares fits what the daemon's learner learns from: a stalled reading (a
    wheel below its threshold reads far under the reference) is left out."""

    @staticmethod
    def _stalling(stalled: slice) -> Recording:
        """20 min at 1 Hz of a log with m = 0.1, b = 0.05 m/s, reading 0 over ``stalled``."""
        t = np.arange(0.0, 1200.0, 1.0)
        v = 2.0 + 0.8 * np.sin(2.0 * np.pi * t / 300.0)
        raw = 1.1 * v + 0.05
        raw[stalled] = 0.0
        return Recording(
            path="x.cap",
            uut="log",
            ports={"log": "nmea0183"},
            t_read=t + 0.5,
            raw=raw,
            t_ref=t + 0.5,
            v_ref=v,
            ok_ref=np.full(t.size, True),
            heading=np.full(t.size, 10.0),
            counters={},
            uut_counters={},
            t_start=0.0,
            t_end=1200.0,
        )

    def test_a_stalled_stretch_does_not_pull_the_fit(self) -> None:
        """Two minutes of zeros at 2 m/s: the fit is the sensor's, its RMSE scored on
        every reading; every reading stalled: refused, saying why."""
        s = UutSettings(port="log", reference_port="log")
        res = calibrate([self._stalling(slice(600, 720))], s, "ls", lag=0.0, average_s=0.0)
        assert res.params.m == pytest.approx(0.1, abs=1e-6)
        assert res.params.b_mps == pytest.approx(0.05, abs=1e-6)
        assert res.n_samples == 1200
        with pytest.raises(OfflineError, match="all 1200 are stalled"):
            calibrate([self._stalling(slice(None))], s, "ls", lag=0.0, average_s=0.0)

    def test_a_dead_band_below_the_stall_speed_does_not_pull_the_fit(self) -> None:
        """Two minutes at 0.4 m/s (above the learning speed, below the stall rule's
        0.5 m/s) with the log reading 0.00 (its dead band): left out as the daemon's
        learner leaves it, the fit is the sensor's."""
        rec = self._stalling(slice(600, 720))
        v = rec.v_ref.copy()
        v[600:720] = 0.4
        s = UutSettings(port="log", reference_port="log")
        res = calibrate([dataclasses.replace(rec, v_ref=v)], s, "ls", lag=0.0, average_s=0.0)
        assert res.params.m == pytest.approx(0.1, abs=1e-6)
        assert res.params.b_mps == pytest.approx(0.05, abs=1e-6)


class TestNothingAligns:
    """When no reading pairs with a reference, the error names the cause with its figures."""

    @pytest.mark.parametrize(
        ("dt_ref", "heading", "valid", "cause"),
        [
            (60.0, 10.0, True, "too sparse — 10 valid samples, 60.0 s apart .* at most 15 s"),
            (2.0, np.nan, True, "no heading arrived"),
            (2.0, 10.0, False, "'gnss' has no valid sample"),
        ],
    )
    def test_the_cause_is_named(
        self, dt_ref: float, heading: float, valid: bool, cause: str
    ) -> None:
        """A reference slower than the alignment's cap; no heading; no valid GNSS sample."""
        s = UutSettings(port="log", reference_port="log", reference_field="gnss", current=True)
        with pytest.raises(OfflineError, match=cause):
            calibrate([_recording(dt_ref, heading, valid)], s, "ls", lag=0.0)

    def test_a_reference_every_5_s_aligns(self) -> None:
        """0.2 Hz is within reach: every reading inside the recording pairs."""
        s = UutSettings(port="log", reference_port="log", reference_field="gnss", current=False)
        res = calibrate([_recording(5.0, 10.0)], s, "ls", lag=0.0, average_s=0.0)
        assert res.n_samples >= 590


class TestFiles:
    """Calibration files and evaluate."""

    def test_saved_calibration_replays_frozen_with_its_lag(
        self, trial_files: dict[str, Path], tmp_path: Path, read: Read
    ) -> None:
        """A saved fit warm-starts a no-learn replay: its lag is used (no re-estimate)
        and the corrected speed is scored against the reference."""
        from emlogd.calfile import loads

        recs = read([trial_files["figure-8"], trial_files["circles"]], E1)
        res = calibrate(recs, E1, "ls", lag=3.3)
        path = tmp_path / "p.yaml"
        save_params(path, res)
        cals, _ = loads(path.read_text())
        settings = dataclasses.replace(E1, learn=False)
        transit = trial_files["transit"]
        ports = [PortSettings(n, p) for n, p in CaptureReader(transit).ports.items()]
        pipeline = Pipeline(ports, [settings], calibrations=cals)
        out = replay(pipeline, [transit])
        uuts = out.to_dict()["uuts"]
        assert isinstance(uuts, dict)
        (u,) = [v for k, v in uuts.items() if k == "emlog1"]
        assert u["state"] == "frozen" and u["lag_s"] == pytest.approx(3.3)
        assert u["rmse_corrected"] < 0.5 * u["rmse_raw"]

    def test_round_trip_and_evaluate(
        self, trial_files: dict[str, Path], tmp_path: Path, read: Read
    ) -> None:
        """--save writes a calibration file that evaluate applies to other captures."""
        recs = read([trial_files["figure-8"]], E1)
        res = calibrate(recs, E1, "ls", lag=3.3)
        path = tmp_path / "p.yaml"
        save_params(path, res)
        cal, extra = load_params(path)
        assert cal.params == res.params and cal.lag_s == 3.3 and cal.method == "ls"
        assert cal.reference == {"port": "dvl", "field": "bottom"}
        assert extra["captures"] == [str(trial_files["figure-8"])]
        others = read([trial_files["transit"], trial_files["return"]], E1)
        rows = evaluate(others, cal.params, E1, 3.3)
        assert [Path(r.capture).name for r in rows] == ["1-transit.cap", "5-return.cap"]
        assert all(r.improvement_pct > 30 for r in rows)
        assert rows[0].to_dict()["n_samples"] == rows[0].n_samples

    def test_bad_files(self, tmp_path: Path) -> None:
        """Unreadable, foreign or malformed files are one clear error each."""
        p = tmp_path / "x.yaml"
        p.write_text("just: text\n")
        with pytest.raises(OfflineError, match="not an emlogd calibration file"):
            load_params(p)
        p.write_text("kind: emlogd-calibration\nschema: 99\n")
        with pytest.raises(OfflineError, match="schema"):
            load_params(p)
        with pytest.raises(OfflineError, match="cannot read"):
            load_params(tmp_path / "missing.yaml")

    def test_missing_port_is_a_clear_error(self, trial_files: dict[str, Path]) -> None:
        """A capture without the UUT's port is an OfflineError naming it."""
        with pytest.raises(OfflineError, match="no port"):
            load_captures(
                [trial_files["straight"]], UutSettings(port="emlog9", reference_port="dvl")
            )


def test_crossval_is_160_evaluations(trial_files: dict[str, Path], read: Read) -> None:
    """160 out-of-sample evaluations; the straight run determines no scale, the figure-8 does."""
    recs = read(list(trial_files.values()), E1)
    result, lag = crossval(recs, E1, lag=3.3, workers=1)
    assert result.n_out_of_sample == 160
    assert lag.lag_s == 3.3
    assert isinstance(result.params("LS-EM3", "2-figure8"), Params)
    for test in ("1-transit", "3-straight", "4-circles", "5-return"):
        assert result.evaluation("LS-EM3", "2-figure8", test).improvement_pct >= 25
    straight = next(t for t in result.trained if (t.estimator, t.train) == ("LS-EM3", "3-straight"))
    figure8 = next(t for t in result.trained if (t.estimator, t.train) == ("LS-EM3", "2-figure8"))
    assert straight.unidentifiable == ("m",) and straight.params.m == 0.0
    assert figure8.unidentifiable == ()
    with pytest.raises(OfflineError, match="two captures"):
        crossval(recs[:1], E1)


class TestSparseReference:
    """A log whose GNSS comes every 2 s with times of 10-s resolution (the log kept aside
    that paired 0 of 2209 samples with the fixed 1-s gap) imports and calibrates."""

    def test_rmc_every_2_s_with_10_s_times_calibrates(self, tmp_path: Path) -> None:
        """Import spreads the sentences between fixes; the cadence gap pairs them."""
        t0 = datetime(2024, 7, 1, 12, 0, 0, tzinfo=UTC)
        lines: list[str] = []
        n = 1800
        for k in range(n):
            psi = (k * 0.4) % 360.0  # a slow turn: every heading sector
            water = 3.0 + 1.0 * math.sin(2 * math.pi * k / 600.0)
            cur_n, cur_e = 0.2, -0.1
            vn = water * math.cos(math.radians(psi)) + cur_n
            ve = water * math.sin(math.radians(psi)) + cur_e
            raw = 1.05 * water + 0.05
            lines.append(encode_vhw(raw, heading_true_deg=psi, talker="II"))
            if k % 2 == 0:
                stamp = t0 + timedelta(seconds=10 * (k // 10))
                cog = math.degrees(math.atan2(ve, vn)) % 360.0
                lines.append(encode_rmc(stamp, math.hypot(vn, ve), cog))
        log = tmp_path / "sparse.nmea"
        log.write_text("\r\n".join(lines) + "\r\n", encoding="ascii")
        cap = tmp_path / "sparse.cap.gz"
        import_nmea([log], cap)
        s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
        recs = load_captures([str(cap)], s)
        assert np.median(np.diff(recs[0].t_ref)) == pytest.approx(2.0, abs=0.3)
        res = calibrate(recs, s, "ls")
        assert res.n_samples > 0.95 * recs[0].t_read.size
        assert res.lag.source in ("fallback", "auto") and res.lag.lag_s >= 0.0
        assert res.params.m == pytest.approx(0.05, abs=0.03)


def test_crossval_asks_for_no_more_processes_than_cores(
    trial_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``crossval --workers 100000``: the cross-validation is handed at most one process
    per core (CPU-bound work), the pool itself at most one per job."""
    import os

    recs = load_captures([trial_files["figure-8"], trial_files["straight"]], E1)
    handed: list[int] = []

    def cross_validate(*args: Any, workers: int, **kw: Any) -> object:
        handed.append(workers)
        raise RuntimeError("stop here")

    monkeypatch.setattr(jobs, "cross_validate", cross_validate)
    with pytest.raises(RuntimeError, match="stop here"):
        crossval(recs, E1, lag=3.3, workers=100_000)
    assert handed == [os.cpu_count() or 1]
