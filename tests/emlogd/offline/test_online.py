"""The daemon's calibration run over recordings (``calibrate --method kf``) and its trace."""

from __future__ import annotations

import csv
import dataclasses
import itertools
from pathlib import Path

import pytest

from emlogd.offline.jobs import OfflineError, calibrate, load_captures
from emlogd.offline.online import TRACE_COLUMNS
from emlogd.pipeline.settings import UutSettings

E1C = dataclasses.replace(UutSettings(port="emlog1", reference_port="dvl"), current=True)


def test_kf_trace(trial_files: dict[str, Path], tmp_path: Path) -> None:
    """--trace writes one row per learnt-from reading: full-precision times, the
    parameters ending at the result's (the filter's, where the run determines them; one
    it does not is reported at its prior), the current with its σ, and the state."""
    recs = load_captures([trial_files["figure-8"]], E1C)
    path = tmp_path / "trace.csv"
    res = calibrate(recs, E1C, "kf", lag=3.3, trace=path)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == TRACE_COLUMNS
    t = [float(r["t"]) for r in rows]
    assert len(rows) > 100 and all(b > a for a, b in itertools.pairwise(t))
    assert res.ident.unidentifiable == ("m",) and res.params.m == 0.0
    assert float(rows[-1]["m"]) != 0.0
    e1 = dataclasses.replace(E1C, current=False)
    whole = calibrate(load_captures([trial_files["figure-8"]], e1), e1, "kf", lag=3.3, trace=path)
    with open(path, newline="") as f:
        last = list(csv.DictReader(f))[-1]
    assert whole.ident.identifiable
    assert float(last["m"]) == pytest.approx(whole.params.m, abs=1e-5)
    assert float(last["b"]) == pytest.approx(whole.params.b_mps, abs=1e-5)
    assert {r["state"] for r in rows} >= {"learning"}
    assert all(r["std_current_north_mps"] for r in rows[1:])
    with pytest.raises(OfflineError, match="--method kf"):
        calibrate(recs, E1C, "ls", lag=3.3, trace=path)
