"""Benchmark: LS-EM3 (and the other LS models) on 130 000 samples.

Target (issue 3): LS-EM3 on 130 000 samples ≤ 10 ms. Prints figures only.

Run from the repository root (or after ``pip install -e .``):
``PYTHONPATH=. python bench/bench_ls.py [--samples N]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib.lsq import fit_ls
from calib.models import MODEL_NAMES, Params, forward_array


def main() -> None:
    """Time fit_ls per model (best of several runs) and print ms per fit."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=130_000)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    t = np.arange(args.samples) / 10.0
    v = 1.8 + 0.5 * np.sin(2 * np.pi * t / 90.0)
    raw = forward_array(Params("EM3", m=0.05, b_mps=0.1), v) + rng.normal(0.0, 0.05, v.size)
    w = rng.uniform(0.5, 2.0, v.size)
    print(f"batch least squares on {args.samples} samples (best of {args.repeat})")
    for model in MODEL_NAMES:
        for weights in (None, w):
            best = float("inf")
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                fit = fit_ls(model, v, raw, weights)
                best = min(best, time.perf_counter() - t0)
            tag = "weighted" if weights is not None else "        "
            target = "  (target ≤ 10 ms)" if model == "EM3" and weights is None else ""
            print(
                f"  LS-{model} {tag}: {best * 1e3:6.2f} ms  θ = "
                f"{', '.join(f'{x:.4f}' for x in fit.params.theta)}{target}"
            )


if __name__ == "__main__":
    main()
