"""A reference whose records arrive minutes away from the log's (a clock offset between
the ports of a capture, a reference buffered on its way): what reaches the autopilot
against the truth. The trial (``soak``: a simulation and a replay, about a minute): the
lag check (:mod:`emlogd.pipeline.lagcheck`) finds the reference two minutes off the
configured lag, each lag scored on the readings the DVL (with its outages) overlaps at
it, and the UUT learns nothing from it and applies nothing (raw passes)."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers.io.capture import CaptureReader, CaptureWriter
from emlogd.config import parse_config
from emlogd.offline.replay import replay
from emlogd.offline.simulate import read_truth, simulate
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

RATIO = 1.05
"""The acceptance: emitted over raw RMSE against the truth, per 5-min window."""

CFG = (
    "ports: [{name: dvl, url: /dev/null, protocol: pd6, role: reference},"
    " {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut},"
    " {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}]\n"
    "calibration: [{uut: emlog1, reference: dvl, lag: 3.3, current: true},"
    " {uut: emlog2, reference: dvl, lag: 0.5, current: true}]\n"
)
"""The lags configured (checked every 5 min)."""

CFG_AUTO = CFG.replace("lag: 3.3", "lag: auto").replace("lag: 0.5", "lag: auto")
"""The lags found by the lag search (0..10 s: a reference minutes off is not found, and
0 s is used)."""


def shifted(src: Path, dst: Path, port: str, shift_s: float) -> Path:
    """``src`` with ``port``'s records stamped ``shift_s`` later, all in time order."""
    reader = CaptureReader(src)
    records = sorted(
        (t + (shift_s if p == port else 0.0), k, p, data)
        for k, (t, p, data, _) in enumerate(reader.received())
    )
    with CaptureWriter(dst, reader.ports) as w:
        for t, _, p, data in records:
            w.write_chunk(t, p, data)
    return dst


@pytest.mark.soak
@pytest.mark.parametrize("cfg", [CFG, CFG_AUTO], ids=["configured", "auto"])
@pytest.mark.parametrize("shift_s", [120.0, -120.0])
def test_a_reference_two_minutes_off_costs_no_window(
    tmp_path: Path, shift_s: float, cfg: str
) -> None:
    """The DVL's records stamped 120 s after the logs' (or before) over the whole trial
    (scale 0.3, seed 1), the lags configured or found: every 5-min window of both logs
    within 1.05x raw."""
    sim = simulate(tmp_path / "sim", seed=1, scale=0.3)
    (tmp_path / "late").mkdir()
    files = [shifted(f, tmp_path / "late" / f.name, "dvl", shift_s) for f in sim.files]
    ports, uuts = pipeline_from_config(parse_config(cfg))
    res = replay(Pipeline(ports, uuts), files, truth=read_truth(sim.outdir))
    worst = {u: max(w.ratio for w in ws) for u, ws in res.truth_windows.items()}
    assert all(r <= RATIO for r in worst.values()), worst
