"""What resting a reference port costs the calibration: stamps delayed by ``rest_s``.

When a reference port becomes readable, the daemon leaves it alone for ``rest_s``
(fewer wake-ups), then reads it: every line that arrived meanwhile is stamped with the
time of that read. This replays a simulated trial through the pipeline with exactly
that stamping (a DVL line arriving while no rest runs starts one; it and every line
arriving before the rest ends are stamped at its end) and prints the calibration and
the RMSE of the corrected speed against the DVL for a few rests. Prints figures only.

Run: ``python bench/bench_rest_stamps.py [--trial DIR] [--capture 2-figure8.cap]``
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

from drivers.io.capture import CaptureReader
from emlogd.config import load_config
from emlogd.offline.simulate import simulate
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

ROOT = Path(__file__).resolve().parents[1]
LAGS_S = {"emlog1": 3.3, "emlog2": 0.5}
"""The simulator's latencies plus the serial time (fixed lags, as in the tests)."""


def _rested(records: list[tuple[float, str, bytes]], rest: float) -> list[tuple[float, str, bytes]]:
    out = []
    read_at: float | None = None  # the end of the running rest: when the port is read
    for t, port, data in records:
        if port == "dvl":
            if read_at is None or t > read_at:
                read_at = t + rest  # readable while not resting: a rest starts
            t = read_at
        out.append((t, port, data))
    out.sort(key=lambda r: r[0])  # stable: arrival order among equal stamps
    return out


def main() -> None:
    """Replay with stamps as resting gives them, for several rests; print the results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trial", help="an existing trial directory (else one is simulated)")
    ap.add_argument("--capture", default="2-figure8.cap")
    args = ap.parse_args()
    trial = Path(args.trial or tempfile.mkdtemp(prefix="emlogd-bench-"))
    if not (trial / args.capture).exists():
        simulate(trial, seed=1, scale=1.0)
    records = [(r.t, r.port, r.data) for r in CaptureReader(trial / args.capture)]
    cfg = load_config(ROOT / "examples" / "emlogd.yaml")
    print(f"{args.capture}: {len(records)} records; fixed lags {LAGS_S}")
    for rest in (0.0, 0.02, 0.04, 0.1):
        ports, uuts = pipeline_from_config(cfg)
        uuts = [dataclasses.replace(u, lag_s=LAGS_S[u.port]) for u in uuts]
        pipe = Pipeline(ports, uuts)
        for t, port, data in _rested(records, rest):
            pipe.feed(t, port, data)
        status = pipe.status()["uuts"]
        assert isinstance(status, dict)
        cells = []
        for name, u in status.items():
            params = ", ".join(f"{k} {v:+.4f}" for k, v in (u["params"] or {}).items())
            cells.append(f"{name} RMSE {u['rmse_raw']:.4f} -> {u['rmse_corrected']:.4f} ({params})")
        print(f"rest {rest * 1000:5.0f} ms: " + "; ".join(cells))


if __name__ == "__main__":
    main()
