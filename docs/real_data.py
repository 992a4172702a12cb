"""The real-recording regression suite: docs/REAL_DATA.md's table, from a folder of logs.

Usage: ``python docs/real_data.py DIR [--out OUTDIR] [--only NAME ...] [--json]``.

Every file of DIR that is a log is recognised by its content (:func:`kind`: an NMEA
0183 log, an Expedition CSV, a logger's TSV with a banner, JSON lines (Signal K,
canboat), canboat's NMEA 2000 text, or another CSV with an ISO time column — the
broken-heading kind among them) and run through emlogd's own
commands, exactly as a user would:

1. ``emlogd import`` (``--format nmea``; CSV and TSV by the importer's header
   detection, else the Expedition preset or the generic column map);
2. ``emlogd calibrate --uut nmea --ref nmea --ref-field gnss --current`` with
   ``--method ls`` and ``--method kf`` (lag auto);
3. ``emlogd replay --strict`` with ``examples/emlogd-gnss.yaml`` (lag auto; a log that
   sends VBW alone with ``uut_source: VBW`` added, as ``calibrate`` reads it), writing
   the corrected sentences to a capture.

One table row per recording: the import's counts by reason; LS and KF parameters ± σ
and the effective scale at the median speed (corrected / raw) next to the folder's
own independent fit (``DIR/reference_fit.py``, when the folder has one: its ``k``);
the LS current against the log's own set and drift (VDR, where the log has one); the
KF's NIS mean; and the replay's emitted speed against the GNSS water speed: its RMSE
next to raw's, the worst ratio emitted / raw over 5-minute windows, and the IMO
A.824(19) verdict of each (``calib.metrics.imo_verdict``: the fraction of samples within
2 % of the speed or 0.2 kn, whichever is greater; meets at 95 %). A third table gives
the headroom: the RMSE and the worst 5-min ratio of the independent fit's scale and of
least squares' calibration, each applied to every scored reading from the start
(:func:`headroom_params`).

**The GNSS water speed** is the GNSS speed along the hull (SOG·cos(COG − ψ), as the
pipeline projects it) less the current, fitted by least squares over each
:data:`CURRENT_WINDOW_S` window on 20-s means as ``along = α + k·raw + c·(cos ψ,
sin ψ)``: α and k free, so the same current serves any affine correction of the raw
reading, and neither series is favoured. A window whose headings cannot separate the
current (fewer than three 45° sectors) takes the recording's.

A step that fails is shown in the table with its reason (a recording the importer
cannot read yet, one whose heading cannot be used) and the rest go on. Progress lines
go to stderr. ``--json`` prints the rows as JSON instead of Markdown; with ``--out``
they are also written to ``OUTDIR/rows.json``.
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from calib.lsq import block_average  # noqa: E402
from calib.metrics import imo_verdict  # noqa: E402
from calib.models import FloatArray, Params, correct_array  # noqa: E402
from drivers import make_decoder  # noqa: E402
from drivers.io.capture import CaptureReader  # noqa: E402
from drivers.nmea0183 import Vbw, Vdr, Vhw  # noqa: E402
from emlogd.offline.dataset import record_capture  # noqa: E402
from emlogd.pipeline.settings import UutSettings  # noqa: E402

KN = 0.514444
"""One knot, m/s."""

CONFIG = ROOT / "examples" / "emlogd-gnss.yaml"
"""The replay's config: one port ``nmea`` (what ``emlogd import`` writes), GNSS reference."""

CURRENT_WINDOW_S = 1800.0
"""The GNSS water speed's current is fitted over windows this long, s (a tide turns in
hours; a sailing yacht's tacks give the headings within half an hour)."""

SCORE_WINDOW_S = 300.0
"""The worst emitted/raw ratio is taken over windows this long, s."""

MIN_WINDOW_SAMPLES = 60
"""A score window with fewer paired samples is not judged."""

MIN_SECTORS = 3
"""A current window needs headings in at least this many 45° sectors."""

KINDS = ("nmea", "expedition-csv", "logger-tsv", "csv", "json", "n2k")

KIND_SCAN_LINES = 200
"""A table's header is looked for among this many first lines (a logger may write its
settings first)."""

KIND_SCAN_BYTES = 65536
"""The bytes read to tell a file's kind."""


SENTENCE_IN_LINE = re.compile(r"[$!][A-Z0-9]{5},")
"""An NMEA sentence's start anywhere in a line (a logger may write a time before it)."""

TABLE_DELIMITERS = (",", ";", "\t", "|")
"""A table line's delimiter is the one of these it holds most."""

TIME_NAMES = frozenset(
    {"time", "utc", "timestamp", "datetime", "date_time", "date time", "utctime", "utc_time"}
)
"""A table whose header names one of these (in any case, a unit after it dropped) and
three more columns is a table of samples."""

UNIT_AFTER = re.compile(r"\s*[(\[].*$")
"""A unit after a column's name (``Bsp (kt)``, ``SOG [m/s]``), dropped before matching."""

JSON_MESSAGE = re.compile(r'[^{]*\{.*"(updates|pgn)"')
"""A JSON-lines log's line: a Signal K delta or a canboat analyzer message (a receive
time may come before it)."""

N2K_PLAIN = re.compile(r"(.*?[;\s])?\d{4}-\d{2}-\d{2}[-T ][\d:.]+Z?,\d,\d{5,6},\d{1,3},\d{1,3},\d")
"""A line of NMEA 2000 in canboat's plain text (time, priority, PGN, source, ...)."""

BOM = b"\xef\xbb\xbf"
"""UTF-8's byte-order mark, which a spreadsheet may write first."""


def kind(path: Path) -> str | None:
    """What a file is, from its first lines (a ``.gz`` read through gzip, as ``emlogd
    import`` reads it): one of :data:`KINDS`, or None (not a log)."""
    try:
        with gzip.open(path, "rb") if path.suffix == ".gz" else open(path, "rb") as f:
            raw = f.read(KIND_SCAN_BYTES)
    except (OSError, EOFError):
        return None
    head = raw.removeprefix(BOM).decode("latin-1", errors="replace")
    lines = [ln.strip() for ln in head.splitlines() if ln.strip()]
    if not lines:
        return None
    for kind, pattern in (("json", JSON_MESSAGE), ("n2k", N2K_PLAIN)):
        if sum(bool(pattern.match(ln)) for ln in lines[:50]) > len(lines[:50]) // 2:
            return kind
    if (
        sum(bool(SENTENCE_IN_LINE.search(ln)) for ln in lines[:50])
        >= min(len(lines[:50]), 5) // 2 + 1
    ):
        return "nmea"
    for ln in lines[:KIND_SCAN_LINES]:
        delim = max(TABLE_DELIMITERS, key=ln.count)
        cells = [UNIT_AFTER.sub("", c.strip().strip('"')).lower() for c in ln.split(delim)]
        if ("bsp" in cells and TIME_NAMES.intersection(cells)) or cells[:1] == ["!boat"]:
            return "expedition-csv"  # its export (Utc, or Date and Time), or its sparse log
        if delim == "\t" and ln.count("\t") >= 3:
            return "logger-tsv"
        if len(cells) >= 4 and TIME_NAMES.intersection(cells):
            return "csv"
    return None


PROGRESS_LINE = re.compile(r"emlogd [a-z-]+: \[ *\d+\.\d s\] ")
"""A progress line of an emlogd command (passed on to this script's stderr as it comes)."""


def emlogd(args: list[str], timeout_s: float = 1800.0) -> tuple[int, str, str]:
    """Run ``python -m emlogd ARGS`` with this tree on the path: (exit code, stdout, stderr).

    The command's progress lines are passed on to stderr as they arrive (they are not
    part of the returned stderr); the command is killed after ``timeout_s``.
    """
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    with tempfile.TemporaryFile("w+", encoding="utf-8") as out:
        p = subprocess.Popen(
            [sys.executable, "-m", "emlogd", *args],
            stdout=out,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        fired = threading.Event()

        def kill() -> None:
            fired.set()
            p.kill()

        timer = threading.Timer(timeout_s, kill)
        timer.start()
        err: list[str] = []
        try:
            assert p.stderr is not None
            for line in p.stderr:
                if PROGRESS_LINE.match(line):
                    say(f"  {line.rstrip()}")
                else:
                    err.append(line)
            code = p.wait()
        finally:
            timer.cancel()
        if fired.is_set():
            raise subprocess.TimeoutExpired(p.args, timeout_s)
        out.seek(0)
        return code, out.read(), "".join(err)


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else ""


@dataclass
class Row:
    """One recording's results (None: the step did not run or failed)."""

    name: str
    kind: str
    imported: dict[str, Any] | None = None
    ls: dict[str, Any] | None = None
    kf: dict[str, Any] | None = None
    replay: dict[str, Any] | None = None
    scores: dict[str, float] | None = None
    ref_k: float | None = None
    log_current: tuple[float, float] | None = None
    errors: dict[str, str] = field(default_factory=dict)


def run_import(path: Path, what: str, cap: Path) -> tuple[dict[str, Any] | None, str]:
    """``emlogd import`` by the file's kind: the report, or None and why."""
    attempts: list[list[str]]
    if what == "nmea":
        attempts = [["--format", "nmea"]]
    elif what == "expedition-csv":
        attempts = [["--format", "csv"], ["--format", "csv", "--preset", "expedition"]]
    elif what in ("json", "n2k"):
        attempts = [["--format", what]]
    elif what == "logger-tsv":
        attempts = [["--format", "csv"]]
    else:
        generic = "time=time,stw=speed,heading=hdg,sog=sog,cog=cog"
        attempts = [
            ["--format", "csv"],
            ["--format", "csv", "--map", generic, "--time-format", "iso"],
        ]
    why = ""
    for extra in attempts:
        rc, out, err = emlogd(["import", str(path), *extra, "--out", str(cap), "--json"])
        if rc == 0:
            doc: dict[str, Any] = json.loads(out)
            doc["options"] = " ".join(extra)
            return doc, ""
        why = _last_line(err) or f"exit {rc}"
    return None, why


def run_calibrate(cap: Path, method: str) -> tuple[dict[str, Any] | None, str]:
    """``emlogd calibrate`` against GNSS with the current: the JSON, or None and why."""
    rc, out, err = emlogd(
        [
            "calibrate",
            str(cap),
            "--uut",
            "nmea",
            "--ref",
            "nmea",
            "--ref-field",
            "gnss",
            "--current",
            "--method",
            method,
            "--json",
        ]
    )
    if rc != 0:
        return None, _last_line(err) or f"exit {rc}"
    doc: dict[str, Any] = json.loads(out)
    doc["warning"] = "\n".join(ln for ln in err.splitlines() if "warning" in ln)
    return doc, ""


def run_replay(cap: Path, out: Path) -> tuple[dict[str, Any] | None, str]:
    """``emlogd replay`` with the GNSS config: the JSON summary, or None and why.

    ``--strict``: the capture ``emlogd import`` wrote holds no malformed record, so one
    (a capture cut short) fails the step instead of scoring a replay of part of it."""
    config = CONFIG
    if log_sentence(cap) == "VBW":  # the log sends VBW alone: the config's UUT learns it
        config = out.with_name(f"{out.name.split('.')[0]}.vbw.yaml")
        text = CONFIG.read_text(encoding="utf-8")
        config.write_text(text.replace("  - uut: nmea\n", "  - uut: nmea\n    uut_source: VBW\n"))
    rc, stdout, err = emlogd(
        ["replay", str(cap), "--config", str(config), "--out", str(out), "--json", "--strict"]
    )
    if rc != 0:
        return None, _last_line(err) or f"exit {rc}"
    doc: dict[str, Any] = json.loads(stdout)
    return doc, ""


def log_sentence(cap: Path) -> str:
    """The log's speed sentence in a capture: ``VHW``, else ``VBW`` when it sends VBW
    alone (as ``emlogd calibrate`` reads it)."""
    t, _ = speeds(cap, "VHW")
    return "VHW" if t.size or not speeds(cap, "VBW")[0].size else "VBW"


def speeds(
    cap: Path, sentence: str = "VHW", port: str | None = None
) -> tuple[FloatArray, FloatArray]:
    """(t, speed m/s) of every VHW (or VBW: its longitudinal water speed) with a speed in
    a capture (one port, or any)."""
    dec = make_decoder("nmea0183", "x", errors="skip")
    t: list[float] = []
    v: list[float] = []
    for r in CaptureReader(cap):
        if port is not None and r.port != port:
            continue
        for x in dec.feed(r.data):
            if sentence == "VHW" and isinstance(x, Vhw) and x.stw_mps is not None:
                t.append(r.t)
                v.append(x.stw_mps)
            elif sentence == "VBW" and isinstance(x, Vbw) and x.water_long_mps is not None:
                t.append(r.t)
                v.append(x.water_long_mps)
    return np.asarray(t, dtype=np.float64), np.asarray(v, dtype=np.float64)


def log_current(cap: Path) -> tuple[float, float] | None:
    """The mean of the log's own current (VDR: set towards, drift), north and east m/s."""
    dec = make_decoder("nmea0183", "x", errors="skip")
    n: list[float] = []
    e: list[float] = []
    for r in CaptureReader(cap):
        for x in dec.feed(r.data):
            if isinstance(x, Vdr) and x.set_true_deg is not None and x.drift_mps is not None:
                a = math.radians(x.set_true_deg)
                n.append(x.drift_mps * math.cos(a))
                e.append(x.drift_mps * math.sin(a))
    if not n:
        return None
    return float(np.mean(n)), float(np.mean(e))


def _sectors(heading_deg: FloatArray) -> int:
    return int(np.unique(np.floor(np.mod(heading_deg, 360.0) / 45.0)).size)


def _current_fit(raw: FloatArray, along: FloatArray, hd: FloatArray) -> tuple[float, float] | None:
    """``along = α + k·raw + c_N cos ψ + c_E sin ψ``: (c_N, c_E), or None (too few sectors)."""
    if raw.size < 10 or _sectors(hd) < MIN_SECTORS:
        return None
    psi = np.radians(hd)
    design = np.stack((np.ones_like(raw), raw, np.cos(psi), np.sin(psi)), axis=1)
    sol, *_ = np.linalg.lstsq(design, along, rcond=None)
    return float(sol[2]), float(sol[3])


def _worst_ratio(tb: FloatArray, err_raw: FloatArray, err: FloatArray) -> float:
    """The largest RMSE ratio ``err`` / ``err_raw`` over :data:`SCORE_WINDOW_S` windows
    of at least :data:`MIN_WINDOW_SAMPLES` samples (NaN without one)."""
    worst = math.nan
    for t0 in np.arange(tb[0], tb[-1], SCORE_WINDOW_S) if tb.size else []:
        sel = (tb >= t0) & (tb < t0 + SCORE_WINDOW_S)
        if np.count_nonzero(sel) < MIN_WINDOW_SAMPLES:
            continue
        r = math.sqrt(float(np.mean(err_raw[sel] ** 2)))
        e = math.sqrt(float(np.mean(err[sel] ** 2)))
        if r > 0.0:
            worst = e / r if not math.isfinite(worst) else max(worst, e / r)
    return worst


def water_scores(
    cap: Path, emitted_cap: Path, fixed: dict[str, Params] | None = None
) -> dict[str, float]:
    """Raw and emitted speed against the GNSS water speed (module docstring); with
    ``fixed``, also each calibration's RMSE and worst 5-min ratio had it been applied to
    every scored reading from the start (``rmse_NAME``, ``worst_NAME``: the headroom)."""
    sentence = log_sentence(cap)
    s = UutSettings(
        port="nmea",
        reference_port="nmea",
        reference_field="gnss",
        current=True,
        uut_source="VBW" if sentence == "VBW" else "VHW",
    )
    rec = record_capture(cap, s)
    al = rec.aligned(0.0)
    ok = al.usable(heading=True)
    t, raw, along, hd = al.t[ok], al.raw[ok], al.ref[ok], al.heading[ok]
    if t.size < MIN_WINDOW_SAMPLES:
        raise ValueError(f"{t.size} readings pair with a GNSS reference and a heading")
    # emitted speeds: each sentence of the replay's capture at the time of its sample
    te, ve = speeds(emitted_cap, sentence)
    idx = np.clip(np.searchsorted(te, t), 0, max(te.size - 1, 0))
    have = te.size > 0
    emitted = np.where(have & (np.abs(te[idx] - t) < 1e-6), ve[idx], np.nan) if have else t * np.nan
    # the current, window by window on 20-s means, else the recording's
    a = block_average(t, raw, along, hd, 20.0)
    whole = _current_fit(a.raw, a.ref, a.heading_deg) or (0.0, 0.0)
    cn = np.full(t.size, whole[0])
    ce = np.full(t.size, whole[1])
    for t0 in np.arange(t[0], t[-1], CURRENT_WINDOW_S):
        sel = (a.t >= t0) & (a.t < t0 + CURRENT_WINDOW_S)
        c = _current_fit(a.raw[sel], a.ref[sel], a.heading_deg[sel])
        if c is not None:
            into = (t >= t0) & (t < t0 + CURRENT_WINDOW_S)
            cn[into], ce[into] = c
    psi = np.radians(hd)
    water = along - cn * np.cos(psi) - ce * np.sin(psi)
    both = np.isfinite(emitted)
    err_raw = (raw - water)[both]
    err_em = (emitted - water)[both]
    tb = t[both]
    headroom: dict[str, float] = {}
    for name, p in (fixed or {}).items():
        err = correct_array(p, raw[both]) - water[both]
        headroom[f"rmse_{name}"] = math.sqrt(float(np.mean(err**2))) if err.size else math.nan
        headroom[f"worst_{name}"] = _worst_ratio(tb, err_raw, err)
    imo_raw = imo_verdict(water[both], raw[both])
    imo_em = imo_verdict(water[both], emitted[both])
    return {
        "n": float(np.count_nonzero(both)),
        "imo_raw_fraction": imo_raw.fraction,
        "imo_raw_meets": float(imo_raw.meets),
        "imo_emitted_fraction": imo_em.fraction,
        "imo_emitted_meets": float(imo_em.meets),
        "rmse_raw": math.sqrt(float(np.mean(err_raw**2))) if err_raw.size else math.nan,
        "rmse_emitted": math.sqrt(float(np.mean(err_em**2))) if err_em.size else math.nan,
        "worst_5min_ratio": _worst_ratio(tb, err_raw, err_em),
        "median_speed": float(np.median(raw)),
        **headroom,
    }


def reference_k(src: Path, path: Path) -> float | None:
    """The folder's own independent fit of the scale (``DIR/reference_fit.py FILE``), if any."""
    script = src / "reference_fit.py"
    if not script.is_file():
        return None
    p = subprocess.run(
        [sys.executable, str(script), str(path)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    try:
        doc = json.loads(p.stdout.strip().splitlines()[-1])
        k = doc["fit"]["k"]
    except (IndexError, KeyError, TypeError, ValueError):
        return None
    return float(k) if isinstance(k, int | float) else None


def effective_scale(doc: dict[str, Any] | None, speed_mps: float) -> float | None:
    """Corrected / raw at ``speed_mps`` for a calibrate result."""
    if doc is None or not math.isfinite(speed_mps) or speed_mps <= 0.0:
        return None
    return _params_of(doc).correct(speed_mps) / speed_mps


def _params_of(doc: dict[str, Any]) -> Params:
    """A calibrate result's parameters."""
    p = doc["params"]
    return Params(doc["model"], m=p.get("m", 0.0), b_mps=p.get("b", 0.0), a_spm=p.get("a", 0.0))


def headroom_params(row: Row) -> dict[str, Params]:
    """The calibrations a replay could have applied from the start: the independent
    fit's scale (``k``: corrected = k·raw) and least squares' over the whole log
    (``ls``), where the row has them."""
    k = {"k": Params("EM3", m=1.0 / row.ref_k - 1.0)} if row.ref_k and row.ref_k > 0.0 else {}
    return k | ({"ls": _params_of(row.ls)} if row.ls is not None else {})


_STARTED = time.monotonic()


def say(msg: str) -> None:
    """A progress line on stderr, with the time since the script started (flushed)."""
    sys.stderr.write(f"real_data: [{time.monotonic() - _STARTED:6.1f} s] {msg}\n")
    sys.stderr.flush()


def run(src: Path, out: Path, only: list[str]) -> list[Row]:
    """Every recording of ``src``, each step in turn (module docstring)."""
    rows: list[Row] = []
    files = sorted(p for p in src.iterdir() if p.is_file())
    for path in files:
        what = kind(path)
        if path.suffix == ".py" or path.name.endswith(".md"):
            continue
        if what is None:
            say(
                f"{path.name}: skipped, not a log (no NMEA sentence, no table header among "
                f"its first {KIND_SCAN_LINES} lines)"
            )
            continue
        name = path.name.rsplit(".", 1)[0]
        if only and not any(o in name for o in only):
            continue
        row = Row(name, what)
        rows.append(row)
        t0 = time.monotonic()
        cap = out / f"{name}.cap.gz"
        say(f"{name}: import ({what})")
        row.imported, why = run_import(path, what, cap)
        if row.imported is None:
            row.errors["import"] = why
            say(f"{name}: import failed: {why}")
            continue
        row.log_current = log_current(cap)
        row.ref_k = reference_k(src, path)
        for method in ("ls", "kf"):
            say(f"{name}: calibrate --method {method}")
            doc, why = run_calibrate(cap, method)
            setattr(row, method, doc)
            if doc is None:
                row.errors[method] = why
        say(f"{name}: replay")
        emitted = out / f"{name}.emitted.cap.gz"
        row.replay, why = run_replay(cap, emitted)
        if row.replay is None:
            row.errors["replay"] = why
        else:
            try:
                row.scores = water_scores(cap, emitted, headroom_params(row))
            except ValueError as exc:
                row.errors["scores"] = str(exc)
        say(f"{name}: done in {time.monotonic() - t0:.0f} s")
    return rows


def _f(x: object, spec: str) -> str:
    return format(x, spec) if isinstance(x, int | float) and math.isfinite(x) else "—"


def _params(doc: dict[str, Any] | None, why: str | None) -> str:
    if doc is None:
        return "fails (below)" if why else "—"
    se = doc.get("stderr", {})
    return " ".join(f"{k} {v:+.3f}±{_f(se.get(k), '.3f')}" for k, v in doc["params"].items())


def _current(doc: dict[str, Any] | None) -> tuple[float, float] | None:
    c = doc.get("current") if doc is not None else None
    if not isinstance(c, dict) or c.get("north_mps") is None:
        return None
    return float(c["north_mps"]), float(c["east_mps"])


def _imo(scores: dict[str, float], which: str) -> str:
    """The IMO A.824(19) verdict of ``which`` (``raw``, ``emitted``): ``97 % meets``."""
    frac = scores.get(f"imo_{which}_fraction", math.nan)
    if not math.isfinite(frac):
        return "—"
    return f"{100.0 * frac:.0f} % {'meets' if scores.get(f'imo_{which}_meets') else 'fails'}"


def markdown(rows: list[Row]) -> str:
    """The two tables: what each step found, and the replay's scores."""
    out = [
        "| recording | kind | import: lines → sentences, skipped | LS (20-s means) | KF | "
        "scale at the median speed LS / KF / independent | lag LS / replay |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        imp = r.imported
        if imp is None:
            out.append(f"| {r.name} | {r.kind} | fails (below) | — | — | — | — |")
            continue
        skipped = ", ".join(f"{k} {v}" for k, v in sorted(imp.get("skipped", {}).items()) if v)
        med = r.scores["median_speed"] if r.scores else math.nan
        k_ls, k_kf = effective_scale(r.ls, med), effective_scale(r.kf, med)
        lag_ls = r.ls["lag"]["source"] if r.ls else "—"
        lag_rp = "—"
        if r.replay is not None:
            lag_rp = _f(r.replay["uuts"]["nmea"]["lag_s"], ".2f") + " s"
        out.append(
            f"| {r.name} | {r.kind} | {imp.get('lines')} → {imp.get('written')}, "
            f"{skipped or 'none'} | {_params(r.ls, r.errors.get('ls'))} | "
            f"{_params(r.kf, r.errors.get('kf'))} | {_f(k_ls, '.3f')} / {_f(k_kf, '.3f')} / "
            f"{_f(r.ref_k, '.3f')} | {lag_ls} / {lag_rp} |"
        )
    out += [
        "",
        "| recording | LS current (kn) | vs the log's own (kn) | KF NIS mean | replay state | "
        "emitted / raw RMSE vs GNSS water speed (m/s) | worst 5-min ratio | "
        "IMO A.824 emitted / raw |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r.imported is None:
            continue
        c = _current(r.ls)
        cur = f"{math.hypot(*c) / KN:.2f}" if c else "not determined"
        versus = "— (none in the log)"
        if r.log_current is not None:
            versus = (
                f"{math.hypot(c[0] - r.log_current[0], c[1] - r.log_current[1]) / KN:.2f}"
                if c
                else "—"
            )
        nis = _f(r.kf.get("nis_mean") if r.kf else None, ".2f")
        state = "—"
        score = "fails (below)"
        worst = "—"
        imo = "—"
        if r.replay is not None:
            u = r.replay["uuts"]["nmea"]
            state = f"{u['state']}, {'applied' if u['params'] else 'raw'}"
        if r.scores is not None:
            s = r.scores
            score = f"{s['rmse_emitted']:.3f} / {s['rmse_raw']:.3f} ({s['n']:.0f} samples)"
            worst = _f(s["worst_5min_ratio"], ".3f")
            imo = f"{_imo(s, 'emitted')} / {_imo(s, 'raw')}"
        out.append(f"| {r.name} | {cur} | {versus} | {nis} | {state} | {score} | {worst} | {imo} |")
    out += [
        "",
        "| recording | raw RMSE (m/s) | emitted (worst 5-min) | the independent k from the start "
        "(worst 5-min) | least squares from the start (worst 5-min) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        if r.scores is not None:
            s = r.scores
            cells = [f"{s['rmse_emitted']:.3f} ({_f(s['worst_5min_ratio'], '.3f')})"] + [
                f"{_f(s.get('rmse_' + x), '.3f')} ({_f(s.get('worst_' + x), '.3f')})"
                for x in ("k", "ls")
            ]
            out.append(f"| {r.name} | {s['rmse_raw']:.3f} | {' | '.join(cells)} |")
    failed = [(r.name, step, why) for r in rows for step, why in r.errors.items()]
    if failed:
        out += ["", "What failed:", ""]
        out += [f"- {name}, {step}: {why}" for name, step, why in failed]
    return "\n".join(out)


def as_json(rows: list[Row]) -> str:
    """The rows as one JSON document (what the tests read)."""

    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    docs = []
    for r in rows:
        med = r.scores["median_speed"] if r.scores else math.nan
        docs.append(
            clean(
                {
                    "name": r.name,
                    "kind": r.kind,
                    "import": r.imported,
                    "ls": r.ls,
                    "kf": r.kf,
                    "replay": r.replay["uuts"]["nmea"] if r.replay else None,
                    "scores": r.scores,
                    "scale_ls": effective_scale(r.ls, med),
                    "scale_kf": effective_scale(r.kf, med),
                    "reference_k": r.ref_k,
                    "log_current": r.log_current,
                    "errors": r.errors,
                }
            )
        )
    return json.dumps(docs, indent=1)


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, run, print."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="the folder of recordings")
    ap.add_argument("--out", type=Path, help="keep the captures here (default: a temporary folder)")
    ap.add_argument(
        "--only", nargs="*", default=[], help="recordings whose name contains one of these"
    )
    ap.add_argument("--json", action="store_true", help="the rows as JSON")
    args = ap.parse_args(argv)
    if not args.dir.is_dir():
        ap.error(f"{args.dir}: not a folder")
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        rows = run(args.dir, out, args.only)
        if args.out is not None:
            (out / "rows.json").write_text(as_json(rows) + "\n", encoding="utf-8")
    sys.stdout.write((as_json(rows) if args.json else markdown(rows)) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
