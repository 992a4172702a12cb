"""The figures of docs/REAL_DATA.md, from the three public recordings.

Usage: ``python docs/real_data.py DIR [OUTDIR]`` where DIR holds
``expedition-valencia.csv``, ``irene-2014-06-27-leman.nmea`` and
``irene-2014-06-29-leman.nmea`` (sources in docs/REAL_DATA.md). Each is imported
(``emlogd import``), calibrated against GNSS with both methods, with and without the
current, and the Kalman filter's trace summarised; where the log holds the logging
software's own current (Expedition's set and drift, imported as VDR) emlogd's current
is compared with it. Prints Markdown tables.
"""

from __future__ import annotations

import csv
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from calib.lsq import block_average, fit_ls
from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Vdr
from emlogd.offline.importer import EXPEDITION, import_csv, import_nmea
from emlogd.offline.jobs import calibrate, concat_usable, load_captures
from emlogd.pipeline.settings import UutSettings

KN = 0.514444
FILES = {
    "valencia": "expedition-valencia.csv",
    "irene 06-27": "irene-2014-06-27-leman.nmea",
    "irene 06-29": "irene-2014-06-29-leman.nmea",
}
WINDOW_S = 1800.0


def settings(current: bool) -> UutSettings:
    """The UUT on the one multiplexed port, GNSS as the reference."""
    return UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=current)


def vdr_series(cap: Path) -> np.ndarray:
    """(t, north, east) m/s of the VDR sentences in a capture."""
    dec = make_decoder("nmea0183", "nmea", errors="skip")
    out = []
    for r in CaptureReader(cap):
        for x in dec.feed(r.data):
            if isinstance(x, Vdr) and x.set_true_deg is not None and x.drift_mps is not None:
                a = math.radians(x.set_true_deg)
                out.append((r.t, x.drift_mps * math.cos(a), x.drift_mps * math.sin(a)))
    return np.array(out).reshape(-1, 3)


def window_mean(v: np.ndarray, t: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray]:
    """The mean of v's north and east over ``t ± half``."""
    cs = np.vstack([np.zeros((1, 2)), np.cumsum(v[:, 1:], axis=0)])
    i0 = np.searchsorted(v[:, 0], t - half)
    i1 = np.maximum(np.searchsorted(v[:, 0], t + half), i0 + 1)
    i1 = np.minimum(i1, len(v))
    n = np.maximum(i1 - i0, 1)
    m = (cs[i1] - cs[i0]) / n[:, None]
    return m[:, 0], m[:, 1]


def main(src: Path, out: Path) -> None:
    """Import, calibrate and summarise every recording."""
    rows_import, rows_fit, rows_kf, rows_cur = [], [], [], []
    for name, fname in FILES.items():
        cap = out / (fname.rsplit(".", 1)[0] + ".cap.gz")
        if fname.endswith(".csv"):
            rep = import_csv(src / fname, cap, dict(EXPEDITION))
        else:
            rep = import_nmea([src / fname], cap)
        skipped = ", ".join(f"{k} {v}" for k, v in sorted(rep.skipped.items())) or "none"
        rows_import.append(
            f"| {name} | {rep.lines} | {rep.written} | {skipped} | "
            f"{(rep.t_end - rep.t_start) / 60:.0f} min |"
        )
        for current in (False, True):
            s = settings(current)
            recs = load_captures([str(cap)], s)
            for method in ("ls", "kf"):
                trace = out / f"{cap.stem}.{method}.{int(current)}.csv" if method == "kf" else None
                res = calibrate(recs, s, method, lag=0.0, trace=trace)
                cur = (
                    f"{math.hypot(*res.current_mps) / KN:.2f} kn"
                    if res.current_mps is not None
                    else ("not determined" if current else "—")
                )
                rows_fit.append(
                    f"| {name} | {method} | {'yes' if current else 'no'} | "
                    f"{res.params.m:+.3f} | {res.params.b_mps:+.3f} | {cur} | "
                    f"{res.rmse_raw:.3f} | {res.rmse_cal:.3f} |"
                )
                if trace is not None and current:
                    rows_kf.append(kf_row(name, trace, vdr_series(cap)))
        rows_cur.append(current_row(name, cap))
    print("| recording | lines/rows | sentences written | skipped | span |\n|---|---|---|---|---|")
    print("\n".join(rows_import))
    print(
        "\n| recording | method | current | m | b m/s | current | RMSE raw m/s | RMSE cal m/s |"
        "\n|---|---|---|---|---|---|---|---|"
    )
    print("\n".join(rows_fit))
    print(
        "\n| recording | KF m after 10 min | KF b after 10 min | current reported | "
        "KF current speed median / p95 / max (kn) | KF σ(c) median m/s | KF vs the log's own current "
        "(10-min mean), median (kn) |\n|---|---|---|---|---|---|---|"
    )
    print("\n".join(rows_kf))
    print(
        f"\n| recording | {WINDOW_S / 60:.0f}-min windows (LS, 20-s means) with the current "
        "determined | current speed median / max (kn) | vs the log's own current, median / max (kn) |"
        "\n|---|---|---|---|"
    )
    print("\n".join(rows_cur))


def kf_row(name: str, trace: Path, vdr: np.ndarray) -> str:
    """The scale band and the current over a KF trace (after its first 10 minutes)."""
    with open(trace, newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["t"]) for r in rows])
    late = t - t[0] >= 600.0

    def col(k: str) -> np.ndarray:
        return np.array([float(r[k]) if r[k] else math.nan for r in rows])

    m, b = col("m")[late], col("b")[late]
    c = np.hypot(col("current_north_mps"), col("current_east_mps"))[late] / KN
    sd = np.maximum(col("std_current_north_mps"), col("std_current_east_mps"))[late]
    det = np.array([r["current_determined"] == "1" for r in rows])[late]
    versus = "—"
    if len(vdr):
        en, ee = window_mean(vdr, t[late], 300.0)
        cn, ce = col("current_north_mps")[late], col("current_east_mps")[late]
        versus = f"{np.nanmedian(np.hypot(cn - en, ce - ee)) / KN:.2f}"
    return (
        f"| {name} | {np.nanmin(m):+.3f} … {np.nanmax(m):+.3f} | "
        f"{np.nanmin(b):+.3f} … {np.nanmax(b):+.3f} | {100 * det.mean():.0f} % of samples | "
        f"{np.nanmedian(c):.2f} / {np.nanpercentile(c, 95):.2f} / {np.nanmax(c):.2f} | "
        f"{np.nanmedian(sd):.3f} | {versus} |"
    )


def current_row(name: str, cap: Path) -> str:
    """Least squares over windows: the current where the heading determines it."""
    s = settings(True)
    recs = load_captures([str(cap)], s)
    t, raw, ref, hd = concat_usable([r.aligned(0.0) for r in recs], True)
    a = block_average(t, raw, ref, hd, 20.0)
    vdr = vdr_series(cap)
    found: list[tuple[float, float, float]] = []
    n_windows = 0
    for t0 in np.arange(a.t[0], a.t[-1] - WINDOW_S + 1.0, WINDOW_S / 2):
        sel = (a.t >= t0) & (a.t < t0 + WINDOW_S)
        if sel.sum() < 10:
            continue
        n_windows += 1
        fit = fit_ls("EM3", a.ref[sel], a.raw[sel], heading_deg=a.heading_deg[sel], current=True)
        if fit.current_mps is not None:
            found.append((t0 + WINDOW_S / 2, *fit.current_mps))
    if not found:
        return f"| {name} | 0 of {n_windows} | — | — |"
    f_ = np.array(found)
    speed = np.hypot(f_[:, 1], f_[:, 2]) / KN
    versus = "— (no current in the log)"
    if len(vdr):
        en, ee = window_mean(vdr, f_[:, 0], WINDOW_S / 2)
        d = np.hypot(f_[:, 1] - en, f_[:, 2] - ee) / KN
        versus = f"{np.median(d):.2f} / {np.max(d):.2f}"
    return (
        f"| {name} | {len(found)} of {n_windows} | {np.median(speed):.2f} / {speed.max():.2f} | "
        f"{versus} |"
    )


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    if len(sys.argv) == 3:
        Path(sys.argv[2]).mkdir(parents=True, exist_ok=True)
        main(Path(sys.argv[1]), Path(sys.argv[2]))
    else:
        with tempfile.TemporaryDirectory() as d:
            main(Path(sys.argv[1]), Path(d))
