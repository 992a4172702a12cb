"""Benchmark: full cross-validation of the 221-minute trial (8 estimators).

Synthetic segments with the paper's durations (125/27/15/24/30 min), generated
here (:func:`tests.synth.paper_trial`), for a 1 Hz UUT (EMlog1, 13 260 samples)
and a 10 Hz UUT (132 600 samples): 5 × 4 × 8 = 160 out-of-sample evaluations.
Target (issue 3): ≤ 10 s for the 1 Hz trial. Prints figures only.

Run from the repository root (or after ``pip install -e .``):
``PYTHONPATH=. python bench/bench_crossval.py [--workers N]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib.crossval import cross_validate
from calib.models import Params
from tests.synth import paper_trial


def main() -> None:
    """Run the cross-validation at 1 Hz and 10 Hz and print timings and Table III for LS-EM3."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    truth = Params("EM3", m=0.08, b_mps=0.1)
    for rate_hz in (1.0, 10.0):
        segs = paper_trial(truth, np.random.default_rng(0), rate_hz=rate_hz)
        n = sum(np.asarray(s.t_s).size for s in segs)
        t0 = time.perf_counter()
        res = cross_validate(segs, workers=args.workers)
        dt = time.perf_counter() - t0
        target = "  (target ≤ 10 s)" if rate_hz == 1.0 else ""
        print(
            f"{rate_hz:4.0f} Hz UUT, {n} samples: {res.n_out_of_sample} evaluations "
            f"in {dt:6.2f} s with workers={args.workers}{target}"
        )
    print("LS-EM3 overall (out-of-sample, last run):")
    for row in res.overall("LS-EM3"):
        print(
            f"  trained on {row.train:9s}: raw {row.rmse_raw_mps:.3f} → "
            f"{row.rmse_cal_mps:.3f} m/s ({row.improvement_pct:5.1f} %)"
        )


if __name__ == "__main__":
    main()
