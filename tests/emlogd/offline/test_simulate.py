"""The simulated sea trial: files, determinism, realism figures, faults, DVL formats."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from drivers.io.capture import CaptureReader
from emlogd.offline.simulate import FAULT_RATES, TRAJECTORIES, SimulationResult, simulate


def test_files_and_truth(trial: SimulationResult) -> None:
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
    reader = CaptureReader(trial.files[1])
    assert reader.ports == {"emlog1": "nmea0183", "emlog2": "nmea0183", "dvl": "pd6"}
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
    assert counts["emlog1"] == pytest.approx(dur * 1.0, rel=0.05)  # VHW 1 Hz
    assert counts["emlog2"] == pytest.approx(dur * 15.0, rel=0.05)  # VBW 10 Hz + VHW 5 Hz
    assert counts["dvl"] == pytest.approx(dur * 10 * 6, rel=0.05)  # 6 PD6 lines per ensemble
    assert {"$VWVHW", "$VMVBW", "$VMVHW", ":SA", ":TS", ":BI", ":BS", ":BE", ":BD"} <= kinds


def test_raw_error_in_the_papers_range(trial: SimulationResult) -> None:
    transit = trial.trajectories[0]
    assert 0.4 <= transit.rmse_raw_mps["emlog1"] <= 0.7
    assert 0.2 <= transit.rmse_raw_mps["emlog2"] <= 0.45
    for t in trial.trajectories:
        for port in ("emlog1", "emlog2"):
            assert t.rmse_best_mps[port] < t.rmse_raw_mps[port]


def test_faults_are_injected_and_counted(trial: SimulationResult) -> None:
    total_lines = sum(sum(t.lines.values()) for t in trial.trajectories)
    total_faults = {k: sum(t.faults[k] for t in trial.trajectories) for k in FAULT_RATES}
    for kind, rate in FAULT_RATES.items():
        assert total_faults[kind] > 0
        assert total_faults[kind] < 5 * rate * total_lines + 20


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path: Path) -> None:
    a = simulate(tmp_path / "a", seed=7, scale=0.02)
    b = simulate(tmp_path / "b", seed=7, scale=0.02)
    c = simulate(tmp_path / "c", seed=8, scale=0.02)
    for pa, pb, pc in zip(a.files, b.files, c.files, strict=True):
        assert pa.read_bytes() == pb.read_bytes()
        assert pa.read_bytes() != pc.read_bytes()
    assert a.truth_path.read_text() == b.truth_path.read_text()


def test_pd0_variant(tmp_path: Path) -> None:
    r = simulate(tmp_path, seed=2, scale=0.02, dvl_format="pd0")
    reader = CaptureReader(r.files[0])
    assert reader.ports["dvl"] == "pd0"
    dvl = [rec for rec in reader if rec.port == "dvl"]
    assert dvl and all(rec.binary for rec in dvl)
    assert all(rec.data[:2] == b"\x7f\x7f" for rec in dvl[:50] if len(rec.data) > 100)


@pytest.mark.parametrize("kwargs", [{"scale": 0.0}, {"scale": 11.0}, {"dvl_format": "pd4"}])
def test_bad_arguments(tmp_path: Path, kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        simulate(tmp_path, **kwargs)  # type: ignore[arg-type]
