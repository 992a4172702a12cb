"""The figures of docs/KF_VS_LS.md: the Kalman filter against least squares.

Usage, from the repository root: ``PYTHONPATH=. python docs/kf_vs_ls.py DIR`` where DIR holds the public recordings of
docs/REAL_DATA.md (the NMEA logs, ``expedition-valencia.csv`` and
``regatta-analyser-2024-07-18-estonia.csv``; the ones missing are skipped). Each is
imported, calibrated against GNSS in the water frame (EM3 with the current) by least
squares and by the daemon's filter (``calibrate --method kf``), and the two compared:
``z`` is the difference over the root-sum-square of their standard errors, and the
last column each one's scale at the median speed (corrected / raw at the median
reading); a recording calibrate refuses (a wrong heading) shows why. Then the
same on synthetic 20-s block means of a GNSS-like reference (σ 0.3 m/s) through a
tidal current swinging ±0, 0.5 and 1 m/s over 6 hours, where the truth is known: the
filter as the paper has it (its operating point the reference, the configured noises)
and as emlogd runs it, least squares with one current and with one per 30 minutes.
Prints Markdown tables.
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from calib.kalman import KfCalibrator, KfConfig
from calib.lsq import block_average, fit_ls
from calib.models import Params
from emlogd.offline.importer import EXPEDITION, import_csv, import_nmea
from emlogd.offline.jobs import OfflineError, calibrate, load_captures
from emlogd.pipeline.settings import UutSettings
from tests.synth import water_frame_segment

KN = 0.514444
VARIATION_DEG = {"leman": 1.5, "trieste": 3.0}
"""Magnetic variation where a log gives only magnetic headings and no variation, °E."""
ESTONIA = {"time": "time", "stw": "speed", "heading": "hdg", "sog": "sog", "cog": "cog"}
SYNTH_TRUTH = Params("EM3", m=0.02, b_mps=0.1)
GNSS_SIGMA_MPS = 0.3
BLOCK_S = 20.0
CURRENT_BLOCK_S = 1800.0


def capture(src: Path, out: Path) -> Path:
    """Import one recording into a capture."""
    cap = out / (src.stem + ".cap.gz")
    if src.name.startswith("expedition"):
        import_csv(src, cap, dict(EXPEDITION))
    elif src.name.startswith("regatta"):
        import_csv(src, cap, dict(ESTONIA), time_format="iso")
    else:
        import_nmea([src], cap)
    return cap


def _pm(d: dict[str, object], p: str) -> str:
    v = d["params"][p]  # type: ignore[index]
    s = d["stderr"].get(p)  # type: ignore[attr-defined]
    return f"{v:+.3f} ± {s:.3f}" if s is not None else f"{v:+.3f} (held)"


def _z(a: dict[str, object], b: dict[str, object], p: str) -> str:
    sa, sb = a["stderr"].get(p), b["stderr"].get(p)  # type: ignore[attr-defined]
    if sa is None or sb is None:
        return "–"
    va, vb = a["params"][p], b["params"][p]  # type: ignore[index]
    return f"{abs(va - vb) / math.hypot(sa, sb):.1f}"


def _cur(d: dict[str, object]) -> str:
    c = d["current"]
    if c is None:
        return "—"
    speed = math.hypot(c["north_mps"], c["east_mps"]) / KN  # type: ignore[index]
    sd = max(c["std_north_mps"] or 0.0, c["std_east_mps"] or 0.0)  # type: ignore[index]
    return f"{speed:.2f} kn ± {sd:.3f}"


def _scale(d: dict[str, Any], speed_mps: float) -> float:
    """Corrected / raw at ``speed_mps`` for a calibrate result."""
    p = d["params"]
    params = Params("EM3", m=p.get("m", 0.0), b_mps=p.get("b", 0.0))
    return params.correct(speed_mps) / speed_mps


def real(src: Path, out: Path) -> None:
    """LS and KF on every recording found."""
    print(
        "| recording | LS m | KF m | z(m) | LS b m/s | KF b m/s | z(b) | LS current | "
        "KF current | KF NIS | RMSE raw / LS / KF m/s | identifiable LS / KF | "
        "scale at the median speed LS / KF |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    files = [
        *sorted(src.glob("*.nmea")),
        src / "expedition-valencia.csv",
        src / "regatta-analyser-2024-07-18-estonia.csv",
    ]
    for f in files:
        if not f.exists():
            continue
        var = next((v for k, v in VARIATION_DEG.items() if k in f.name), None)
        s = UutSettings(
            port="nmea",
            reference_port="nmea",
            reference_field="gnss",
            current=True,
            magnetic_variation_deg=var,
        )
        recs = load_captures([str(capture(f, out))], s)
        try:
            ls = calibrate(recs, s, "ls", lag=0.0).to_dict()
            kf = calibrate(recs, s, "kf", lag=0.0).to_dict()
        except OfflineError as exc:
            print(f"| {f.stem} | refused: {exc} |" + " — |" * 11, flush=True)
            continue
        nis = kf["nis_mean"]
        al = [r.aligned(0.0) for r in recs]
        med = float(np.median(np.concatenate([a.raw[a.usable(heading=True)] for a in al])))
        print(
            f"| {f.stem} | {_pm(ls, 'm')} | {_pm(kf, 'm')} | {_z(ls, kf, 'm')} | "
            f"{_pm(ls, 'b')} | {_pm(kf, 'b')} | {_z(ls, kf, 'b')} | {_cur(ls)} | {_cur(kf)} | "
            f"{'–' if nis is None else f'{nis:.2f}'} | "
            f"{ls['rmse_raw']:.3f} / {ls['rmse_cal']:.3f} / {kf['rmse_cal']:.3f} | "
            f"{'yes' if ls['identifiable'] else 'no'} / {'yes' if kf['identifiable'] else 'no'} | "
            f"{_scale(ls, med):.3f} / {_scale(kf, med):.3f} |",
            flush=True,
        )


def synthetic() -> None:
    """Block means through a tide, the truth known: m +0.02, b +0.10 m/s."""
    print(
        "\n| trajectory | tide ± m/s | KF, the paper's: m | b m/s | KF: m | b m/s | "
        "LS, one current: m | b m/s | LS, a current per 30 min: m | b m/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    ratio = GNSS_SIGMA_MPS**2 / KfConfig().r_raw_mps2
    for kind in ("transit", "circles"):
        for swing in (0.0, 0.5, 1.0):
            s = water_frame_segment(
                kind,
                6 * 3600,
                1.0,
                SYNTH_TRUTH,
                np.random.default_rng(4),
                current_mps=(0.2, 0.1),
                current_swing_mps=swing,
                sigma_ref_mps=GNSS_SIGMA_MPS,
            )
            a = block_average(s.t_s, s.raw_mps, s.ref_mps, s.heading_deg, BLOCK_S)
            paper, kf = (
                KfCalibrator(
                    "EM3",
                    KfConfig(r_ref_mps2=GNSS_SIGMA_MPS**2, adaptive=new, fused_operating_point=new),
                    current=True,
                )
                for new in (False, True)
            )
            for k in range(a.t.size):
                psi = math.radians(float(a.heading_deg[k]))
                for f in (paper, kf):
                    f.predict(BLOCK_S)
                    f.reacquire_speed()
                    f.update(
                        float(a.raw[k]),
                        float(a.ref[k]),
                        0.0,
                        heading_cs=(math.cos(psi), math.sin(psi)),
                    )
            one = fit_ls("EM3", a.ref, a.raw, heading_deg=a.heading_deg, current=True)
            blocks = fit_ls(
                "EM3",
                a.ref,
                a.raw,
                heading_deg=a.heading_deg,
                current=True,
                t_s=a.t,
                current_block_s=CURRENT_BLOCK_S,
                noise_ratio=ratio,
            )

            def pm(v: float, sd: float | None) -> str:
                return f"{v:+.3f} ± {sd:.3f}" if sd is not None else f"{v:+.3f} (held)"

            print(
                f"| {kind} | {swing:g} | {pm(paper.params.m, paper.param_std['m'])} | "
                f"{pm(paper.params.b_mps, paper.param_std['b'])} | "
                f"{pm(kf.params.m, kf.param_std['m'])} | "
                f"{pm(kf.params.b_mps, kf.param_std['b'])} | "
                f"{pm(one.params.m, one.param_std['m'])} | {pm(one.params.b_mps, one.param_std['b'])} | "
                f"{pm(blocks.params.m, blocks.param_std['m'])} | "
                f"{pm(blocks.params.b_mps, blocks.param_std['b'])} |",
                flush=True,
            )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    with tempfile.TemporaryDirectory() as d:
        real(Path(sys.argv[1]), Path(d))
    synthetic()
