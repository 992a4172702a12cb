"""Benchmark: one KF-EMx step (predict + reference update + raw update).

Compares, in the same run and on the same data and model:

- ``calib.kalman.KfCalibrator.update`` (the per-sample path over plain floats), for
  KF-EM3 and, in the water frame, KF-EM3 and KF-EM4 with the current (5 and 6 states);
- the numpy reference ``calib.kalman.predict``/``update`` (Joseph form);
- filterpy's ``KalmanFilter`` (predict, update with the reference row, update with
  the pseudo-linear raw row; filterpy also uses the Joseph form).

Target: a 5- or 6-state step well under 20 µs (the daemon runs one per UUT sample,
16 per second on the example vehicle). Prints figures only; no assertion. filterpy
is optional (``pip install emlogd[bench]``).

Run from the repository root (or after ``pip install -e .``):
``PYTHONPATH=. python bench/bench_kf.py [--samples N]``.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from calib.kalman import KalmanModel, KfCalibrator, KfConfig, make_state, predict, update
from calib.models import Params, forward_array


def _data(n: int) -> tuple[list[float], list[float]]:
    rng = np.random.default_rng(0)
    t = np.arange(n, dtype=np.float64)
    v = 2.0 + 0.8 * np.sin(2 * np.pi * t / 240.0)
    raw = forward_array(Params("EM3", m=0.05, b_mps=0.1), v) + rng.normal(0.0, 0.05, n)
    ref = v + rng.normal(0.0, 0.01, n)
    return raw.tolist(), ref.tolist()


def bench_fast(
    raw: list[float], ref: list[float], cfg: KfConfig, model: str = "EM3", current: bool = False
) -> tuple[float, tuple[float, ...]]:
    """Seconds per step of the per-sample filter, and its final state."""
    kf = KfCalibrator(model, cfg, current=current)
    upd = kf.update
    heading = [(math.cos(k * 0.05), math.sin(k * 0.05)) for k in range(len(raw))]
    t0 = time.perf_counter()
    for r, z, cs in zip(raw, ref, heading, strict=True):
        upd(r, z, 1.0, heading_cs=cs)
    return (time.perf_counter() - t0) / len(raw), kf.x


def bench_numpy(
    raw: list[float], ref: list[float], cfg: KfConfig
) -> tuple[float, tuple[float, ...]]:
    """Seconds per step of the numpy reference implementation."""
    q_cov = np.diag([cfg.accel_psd_m2ps3, cfg.q_params, cfg.q_params])
    m_pred = KalmanModel.of(np.eye(3), [[1.0, 0.0, 0.0]], q_cov, [[cfg.r_ref_mps2]])
    m_raw = KalmanModel.of(np.eye(3), [[1.0, 0.0, 0.0]], q_cov, [[cfg.r_raw_mps2]])
    state = make_state(np.zeros(3), np.eye(3) * cfg.p0)
    t0 = time.perf_counter()
    for r, z in zip(raw, ref, strict=True):
        state = predict(state, m_pred)
        state, _ = update(state, z, m_pred)
        state, _ = update(state, r, m_raw, H=(1.0, z, 1.0))
    return (time.perf_counter() - t0) / len(raw), tuple(state.x.tolist())


def bench_filterpy(
    raw: list[float], ref: list[float], cfg: KfConfig
) -> tuple[float, tuple[float, ...]] | None:
    """Seconds per step of filterpy's KalmanFilter on the same model (None if absent)."""
    try:
        from filterpy.kalman import KalmanFilter  # type: ignore[import-untyped]
    except ImportError:
        return None
    f = KalmanFilter(dim_x=3, dim_z=1)
    f.x = np.zeros((3, 1))
    f.P = np.eye(3) * cfg.p0
    f.F = np.eye(3)
    f.Q = np.diag([cfg.accel_psd_m2ps3, cfg.q_params, cfg.q_params])
    h_ref = np.array([[1.0, 0.0, 0.0]])
    r_ref = np.array([[cfg.r_ref_mps2]])
    r_raw = np.array([[cfg.r_raw_mps2]])
    t0 = time.perf_counter()
    for r, z in zip(raw, ref, strict=True):
        f.predict()
        f.update(z, R=r_ref, H=h_ref)
        f.update(r, R=r_raw, H=np.array([[1.0, z, 1.0]]))
    return (time.perf_counter() - t0) / len(raw), tuple(f.x.ravel().tolist())


def main() -> None:
    """Run the three implementations and print µs per step."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=50_000)
    args = parser.parse_args()
    cfg = KfConfig()
    raw, ref = _data(args.samples)
    n_cmp = min(args.samples, 5_000)
    raw_c, ref_c = raw[:n_cmp], ref[:n_cmp]
    # the three in turn, the best of five each: every one sees the same moments of
    # this drifting VM, and the best is the least disturbed run (as timeit does)
    t_fast, t_np, t_fp = [], [], []
    x_np: tuple[float, ...] = ()
    x_fp: tuple[float, ...] | None = None
    for _ in range(5):
        t, x_fast_short = bench_fast(raw_c, ref_c, cfg)
        t_fast.append(t)
        t, x_np = bench_numpy(raw_c, ref_c, cfg)
        t_np.append(t)
        fp = bench_filterpy(raw_c, ref_c, cfg)
        if fp is not None:
            t_fp.append(fp[0])
            x_fp = fp[1]
    fast, slow = min(t_fast), min(t_np)
    _, x_fast = bench_fast(raw, ref, cfg)
    water = {
        (m, True): min(bench_fast(raw_c, ref_c, cfg, m, True)[0] for _ in range(5))
        for m in ("EM3", "EM4")
    }
    print(f"KF-EMx step (predict + ref update + raw update), {n_cmp} samples, best of 5")
    print(f"  KF-EM3 (plain floats)      : {fast * 1e6:7.2f} µs/step")
    for (m, _), t in water.items():
        n = 5 if m == "EM3" else 6
        print(f"  KF-{m} + current ({n} states): {t * 1e6:7.2f} µs/step  (target well under 20 µs)")
    print(f"  numpy reference (Joseph)   : {slow * 1e6:7.2f} µs/step  ({slow / fast:5.1f}× slower)")
    diff = max(abs(a - b) for a, b in zip(x_fast_short, x_np, strict=True))
    print(f"  per-sample vs numpy state  : max |Δx| = {diff:.2e}")
    if x_fp is None:
        print("  filterpy                   : not installed (pip install emlogd[bench])")
    else:
        t_filterpy = min(t_fp)
        ratios = [b / a for a, b in zip(t_fast, t_fp, strict=True)]
        diff_fp = max(abs(a - b) for a, b in zip(x_fast_short, x_fp, strict=True))
        print(
            f"  filterpy KalmanFilter      : {t_filterpy * 1e6:7.2f} µs/step  "
            f"(KF-EM3 per-sample path is {t_filterpy / fast:5.1f}× faster; "
            f"{min(ratios):.1f}–{max(ratios):.1f}× run by run)"
        )
        print(f"  per-sample vs filterpy state: max |Δx| = {diff_fp:.2e}")
    print(f"  over {args.samples} samples:")
    print(f"  final θ = m {x_fast[1]:.4f}, b {x_fast[2]:.4f} m/s (truth 0.05, 0.1)")
    if not math.isfinite(fast):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
