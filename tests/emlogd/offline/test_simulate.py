"""The simulated sea trial: files, determinism, realism figures, faults, DVL formats."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from calib.models import correct_array
from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.records import Rejected
from emlogd.cli import main
from emlogd.offline.jobs import calibrate, evaluate, load_captures
from emlogd.offline.simulate import (
    EMLOG1,
    EMLOG2,
    FAULT_RATES,
    MIN_SCALE,
    TRAJECTORIES,
    SimulationResult,
    TruthError,
    read_truth,
    score_truth,
    simulate,
)
from emlogd.pipeline.settings import UutSettings


def test_files_and_truth(trial: SimulationResult) -> None:
    """simulate writes the five trajectory captures and a truth.yaml with schema, scale, the EMlogs'
    latencies and each trajectory's scaled duration, mean speed and current bound."""
    assert [p.name for p in trial.files] == [
        "1-transit.cap",
        "2-figure8.cap",
        "3-straight.cap",
        "4-circles.cap",
        "5-return.cap",
    ]
    truth = yaml.safe_load(trial.truth_path.read_text())
    assert truth["schema"] == 1 and truth["scale"] == 0.2
    assert truth["sensors"]["emlog1"]["latency_s"] == 3.2
    assert truth["sensors"]["emlog2"]["latency_s"] == 0.45
    assert [t["name"] for t in truth["trajectories"]] == [t.kind for t in TRAJECTORIES]
    for spec, t in zip(TRAJECTORIES, trial.trajectories, strict=True):
        assert t.duration_s == pytest.approx(spec.duration_min * 60 * 0.2)
        assert t.mean_stw_mps == pytest.approx(spec.mean_mps, abs=1e-6)
        assert t.max_current_mps <= 0.3


def test_ports_rates_and_sentences(trial: SimulationResult) -> None:
    """The figure-8 capture declares the four ports, keeps time monotonic, and carries each sensor's
    sentence types at their documented rates (within 5 %)."""
    reader = CaptureReader(trial.files[1])
    assert reader.ports == {
        "emlog1": "nmea0183",
        "emlog2": "nmea0183",
        "dvl": "pd6",
        "gnss": "nmea0183",
    }
    counts: dict[str, int] = {}
    kinds: set[str] = set()
    last = 0.0
    for rec in reader:
        assert rec.t >= last
        last = rec.t
        counts[rec.port] = counts.get(rec.port, 0) + 1
        if not rec.binary:
            kinds.add(rec.payload[:6] if rec.port != "dvl" else rec.payload[:3])
    dur = trial.trajectories[1].duration_s
    assert counts["gnss"] == pytest.approx(dur * 1.0, rel=0.05)  # RMC 1 Hz
    assert counts["emlog1"] == pytest.approx(dur * 1.0, rel=0.05)  # VHW 1 Hz
    assert counts["emlog2"] == pytest.approx(dur * 15.0, rel=0.05)  # VBW 10 Hz + VHW 5 Hz
    assert counts["dvl"] == pytest.approx(dur * 10 * 6, rel=0.05)  # 6 PD6 lines per ensemble
    assert {
        "$VWVHW",
        "$VMVBW",
        "$VMVHW",
        "$GPRMC",
        ":SA",
        ":TS",
        ":BI",
        ":BS",
        ":BE",
        ":BD",
    } <= kinds


def test_raw_error_in_the_papers_range(trial: SimulationResult) -> None:
    """The EMlogs' raw RMSE on the transit lies in the paper's ranges, and the best fit beats raw on
    every trajectory."""
    transit = trial.trajectories[0]
    assert 0.4 <= transit.rmse_raw_mps["emlog1"] <= 0.7
    assert 0.2 <= transit.rmse_raw_mps["emlog2"] <= 0.45
    for t in trial.trajectories:
        for port in ("emlog1", "emlog2"):
            assert t.rmse_best_mps[port] < t.rmse_raw_mps[port]


def test_faults_are_injected_and_counted(trial: SimulationResult) -> None:
    """Every fault kind occurs at least once and at most five times its per-line rate (+ 20)."""
    total_lines = sum(sum(t.lines.values()) for t in trial.trajectories)
    total_faults = {k: sum(t.faults[k] for t in trial.trajectories) for k in FAULT_RATES}
    for kind, rate in FAULT_RATES.items():
        assert total_faults[kind] > 0
        assert total_faults[kind] < 5 * rate * total_lines + 20


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path: Path) -> None:
    """The same seed gives byte-identical captures and truth; another seed other captures."""
    a = simulate(tmp_path / "a", seed=7, scale=0.02)
    b = simulate(tmp_path / "b", seed=7, scale=0.02)
    c = simulate(tmp_path / "c", seed=8, scale=0.02)
    for pa, pb, pc in zip(a.files, b.files, c.files, strict=True):
        assert pa.read_bytes() == pb.read_bytes()
        assert pa.read_bytes() != pc.read_bytes()
    assert a.truth_path.read_text() == b.truth_path.read_text()


def test_pd0_variant(tmp_path: Path) -> None:
    """dvl_format='pd0' declares the DVL port pd0 and writes binary records starting with the 0x7F7F
    header."""
    r = simulate(tmp_path, seed=2, scale=0.02, dvl_format="pd0")
    reader = CaptureReader(r.files[0])
    assert reader.ports["dvl"] == "pd0"
    dvl = [rec for rec in reader if rec.port == "dvl"]
    assert dvl and all(rec.binary for rec in dvl)
    assert all(rec.data[:2] == b"\x7f\x7f" for rec in dvl[:50] if len(rec.data) > 100)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"scale": 0.0},
        {"scale": 11.0},
        {"dvl_format": "pd4"},
        {"circles": "spiral"},
        {"current": (0.2, math.nan)},
        {"current": (3.5, 0.0)},
    ],
)
def test_bad_arguments(tmp_path: Path, kwargs: dict[str, object]) -> None:
    """Arguments outside their ranges are refused before anything is written."""
    with pytest.raises(ValueError):
        simulate(tmp_path, **kwargs)  # type: ignore[arg-type]


# ------------------------------------------------------------------ current, circles, truth


def test_given_current_moves_only_the_ground_referenced_ports(tmp_path: Path) -> None:
    """--current sets a constant current in the truth; the EMlogs' bytes do not move, the DVL's and GNSS's do."""
    base = simulate(tmp_path / "a", seed=4, scale=0.02)
    tide = simulate(tmp_path / "b", seed=4, scale=0.02, current=(0.25, -0.1))
    truth = read_truth(tide.outdir)
    assert np.all(truth.current_n_mps == 0.25) and np.all(truth.current_e_mps == -0.1)
    assert read_truth(base.outdir).current_n_mps.std() > 0.0
    assert np.array_equal(read_truth(base.outdir).stw_mps, truth.stw_mps)
    doc = yaml.safe_load(tide.truth_path.read_text())
    assert doc["current"] == {"north_mps": 0.25, "east_mps": -0.1}
    for pa, pb in zip(base.files, tide.files, strict=True):
        by_port: dict[str, list[list[bytes]]] = {}
        for path in (pa, pb):
            for rec in CaptureReader(path):
                by_port.setdefault(rec.port, [[], []])[path == pb].append(rec.data)
        assert by_port["emlog1"][0] == by_port["emlog1"][1]
        assert by_port["emlog2"][0] == by_port["emlog2"][1]
        assert by_port["dvl"][0] != by_port["dvl"][1]
        assert by_port["gnss"][0] != by_port["gnss"][1]


def _emlog_readings(
    path: Path, port: str, source: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A capture's readings of one EMlog (of one sentence, or all): receive times and
    longitudinal speeds."""
    dec = make_decoder("nmea0183", port, errors="skip")
    t, raw = [], []
    for rt, rport, data, _ in CaptureReader(path).received():
        if rport == port:
            for r in dec.feed(data):
                assert not isinstance(r, Rejected)  # errors="skip" yields none
                for sp in dec.speed_records(r):
                    if source in (None, sp.source) and sp.longitudinal_mps is not None:
                        t.append(rt)
                        raw.append(sp.longitudinal_mps)
    return np.array(t), np.array(raw)


def test_truth_scores_and_floor(trial: SimulationResult) -> None:
    """The raw readings score their known raw error against the truth; the true inverse reaches the floor."""
    truth = read_truth(trial.outdir)
    t, raw = _emlog_readings(trial.files[2], "emlog1")
    params, latency = truth.emlog("emlog1")
    assert latency == 3.2
    floor = correct_array(params, raw)
    s = score_truth(truth, "emlog1", t, raw, floor)
    assert s.n_samples == len(t)
    assert s.rmse_corrected == pytest.approx(s.rmse_floor)
    assert s.rmse_floor == pytest.approx(trial.trajectories[2].rmse_floor_mps["emlog1"], rel=0.05)
    assert 0.02 < s.rmse_floor < 0.035  # 0.03 m/s of noise through 1 + m = 1.17, quantised
    assert s.rmse_raw > 0.3
    assert s.to_dict().keys() == {"n_samples", "rmse_raw", "rmse_corrected", "rmse_floor", "imo"}
    with pytest.raises(TruthError, match="no EMlog 'dvl'"):
        score_truth(truth, "dvl", t, raw, raw)


def test_simulate_command_current_and_circles(tmp_path: Path) -> None:
    """simulate --current N,E --circles constant reaches the simulator; a bad --current is a usage error."""
    out = tmp_path / "sim"
    argv = [
        "simulate",
        str(out),
        "--scale",
        "0.01",
        "--current",
        "0.2,0.1",
        "--circles",
        "constant",
    ]
    assert main(argv) == 0
    doc = yaml.safe_load((out / "truth.yaml").read_text())
    assert doc["current"] == {"north_mps": 0.2, "east_mps": 0.1} and doc["circles"] == "constant"
    for bad in ("0.2", "0.2,x", "5,0"):
        assert main(["simulate", str(tmp_path / "x"), "--current", bad]) == 2
    assert not (tmp_path / "x").exists()


def test_simulate_command_sensor_sets_the_emlogs_error_model(tmp_path: Path) -> None:
    """simulate --sensor gives an EMlog other parameters: truth.yaml records them and the
    readings follow them (scale and bias fitted on the truth at the given latency)."""
    out = tmp_path / "sim"
    argv = ["simulate", str(out), "--seed", "5", "--scale", "0.05", "--current", "0,0"]
    argv += ["--sensor", "emlog2:a=0,m=0.25,b=-0.3,latency=2.0,noise=0.01"]
    assert main(argv) == 0
    doc = yaml.safe_load((out / "truth.yaml").read_text())
    e2 = doc["sensors"]["emlog2"]
    assert (e2["a_spm"], e2["m"], e2["b_mps"], e2["latency_s"], e2["noise_mps"]) == (
        0.0,
        0.25,
        -0.3,
        2.0,
        0.01,
    )
    e1 = doc["sensors"]["emlog1"]  # the other EMlog keeps its defaults
    assert (e1["m"], e1["latency_s"]) == (EMLOG1.params.m, EMLOG1.latency_s)
    truth = read_truth(out)
    t, raw = _emlog_readings(out / TRAJECTORIES[1].filename, "emlog2", "VHW")
    stw = truth.stw_at(t - 2.0)
    ok = np.isfinite(stw)
    m1, b = np.polyfit(stw[ok], raw[ok], 1)
    assert m1 - 1.0 == pytest.approx(0.25, abs=0.01)
    assert b == pytest.approx(-0.3, abs=0.02)


@pytest.mark.parametrize(
    ("value", "why"),
    [
        ("emlog3:m=0.1", "expected emlog1:KEY=V"),
        ("emlog2", "expected emlog1:KEY=V"),
        ("emlog2:q=0.1", "KEY one of a, m, b, latency, noise"),
        ("emlog2:m=x", "is not a number"),
        ("emlog2:m=0.1,m=0.2", "given twice"),
        ("emlog2:m=0.7", "emlog2 m must be within"),
        ("emlog1:latency=-1", "emlog1 latency must be within"),
    ],
)
def test_simulate_command_bad_sensor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], value: str, why: str
) -> None:
    """A bad --sensor is a usage error naming what is wrong, and nothing is written."""
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0.01", "--sensor", value]) == 2
    assert why in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("args", "why"),
    [
        (["--seed", "-5"], "--seed must be 0 or more"),
        (["--scale", "1e-5"], "--scale must be in [0.005, 10]"),
        (["--scale", "0.004"], "--scale must be in [0.005, 10]"),
    ],
)
def test_simulate_command_refuses_a_negative_seed_and_a_scale_too_small(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], why: str
) -> None:
    """A negative seed (which numpy's seed sequence refuses) and a scale under
    ``MIN_SCALE`` (trajectories holding no reading with a reference) are usage errors,
    nothing written; each was ``internal error`` (``ValueError``, ``IndexError``) or
    ``nan`` figures."""
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0.01", *args]) == 2
    assert why in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_simulate_at_the_smallest_scale_scores_every_capture(tmp_path: Path) -> None:
    """At ``MIN_SCALE`` every capture holds readings of both logs with a reference: each
    trajectory's raw RMSE is a number."""
    r = simulate(tmp_path, seed=3, scale=MIN_SCALE)
    figures = [x for tr in r.trajectories for x in tr.rmse_raw_mps.values()]
    assert len(figures) == 10 and all(math.isfinite(x) for x in figures), figures
    with pytest.raises(ValueError, match="seed must be 0 or more"):
        simulate(tmp_path, seed=-1, scale=MIN_SCALE)


def test_simulate_refuses_emlogs_on_other_ports_or_out_of_range(tmp_path: Path) -> None:
    """simulate() takes the two EMlogs on their ports, each within SENSOR_LIMITS."""
    import dataclasses

    with pytest.raises(ValueError, match="ports emlog1 and emlog2"):
        simulate(tmp_path, scale=0.01, emlogs=(EMLOG2, EMLOG1))
    loud = dataclasses.replace(EMLOG2, noise_mps=0.9)
    with pytest.raises(ValueError, match="emlog2 noise must be within"):
        simulate(tmp_path, scale=0.01, emlogs=(EMLOG1, loud))
    assert not any(tmp_path.iterdir())


def test_trial_calibrates_against_its_gnss(trial_files: dict[str, Path]) -> None:
    """The gnss port stands in for the DVL: --ref gnss --ref-field gnss with the current learns
    a calibration that cuts EMlog1's error against the DVL on another trajectory by > 60 %.
    The lag search finds EMlog1's lag behind the GNSS (3.2 s less the GNSS's ~0.78 s), too
    uncertain against 1 Hz fixes to be used on its own; given, it serves."""
    gnss = UutSettings(port="emlog1", reference_port="gnss", reference_field="gnss", current=True)
    recs = load_captures([trial_files["transit"]], gnss)
    found = calibrate(recs, gnss, "ls").lag
    assert 1.5 < found.per_capture["1-transit"].lag_s < 3.0
    assert found.source == "fallback" and found.lag_s == 0.0
    res = calibrate(recs, gnss, "ls", lag=2.4)
    assert res.identifiable or res.ident.unidentifiable == ("b",)
    dvl = UutSettings(port="emlog1", reference_port="dvl")
    (row,) = evaluate(load_captures([trial_files["figure-8"]], dvl), res.params, dvl, 3.3)
    assert row.improvement_pct > 60.0
