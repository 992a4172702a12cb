"""The perturbation suite: each real recording rewritten as a held-out log of its kind
plausibly differs, and run through the same commands as docs/real_data.py.

Usage: ``python docs/real_variants.py DIR [--only NAME ...] [--variant V ...] [--out DIR] [--json]``.

A variant is a pure function of the source file's text (:data:`VARIANTS`): the GNSS
thinned to 0.5 and 0.2 Hz, fix times of 1-s and 10-s resolution; a magnetic heading
without any variation in the log (HDG with empty variation fields, HDM, VHW magnetic
only); other sentences and talkers (GGA + VTG instead of RMC, ZDA + GLL + VTG, GLL +
VTG without a date, RMC
without a course at low speed or at any speed, VLW, MWV with nonsense, proprietary ``$P`` lines),
lines without checksums, CRLF or LF endings, a truncated last line, a gap of minutes,
a midnight crossed by GGA times of day (and by RMC with a leap second, or with its date
advancing late), two sessions 3 h apart in one file, the fix times set back an hour
from the middle on (a receiver reset), fix times a second late now and then, an hour moored first,
variations signed without E/W, VHW in km/h alone, HDM with RMC's variation alone, a
0.5-Hz GNSS with the log at twice its rate; the log 2 s behind or ahead of the GNSS, at
half or twice its rate, silent (or the GNSS silent) 30 s every 5 minutes; THS or
$PASHR the only heading; VBW instead of VHW; Expedition exports with other column sets
(``Set``/``Drift``, no current, upper-case names, another order, extra columns, a
magnetic ``HdgMag`` with or without a variation column,
``;`` with decimal commas, quoted cells, a byte-order mark, ``Utc`` as US-English
text, ``Date`` and ``Time`` columns, a row of units under the header (also of SI
units, ``m/s`` and ``rad``, the cells in them), units in the
names, OLE days of local time with ``--utc-offset``, NMEA field names, ``UtcDate``
and ``UtcTime``) and
Expedition's own sparse log (``!Boat``
header, channel numbers, ``channel,value`` pairs); the logger's TSV without its
banner, with its local time given by ``--utc-offset``, with rows every 5 s, under its
other firmware's column names after a banner of settings, with its date in full or
year first, its time with tenths;
and a strong tidal current (:func:`tide`) added to the GNSS of an NMEA log (also at
3 kn, and with the GNSS at 0.5 Hz) and of an Expedition export: the water-frame
calibration should not move.

Each variant is imported, calibrated (LS and KF, ``--ref-field gnss --current``, no
``--variation``) and replayed (``examples/emlogd-gnss.yaml``, ``lag: auto``), and its
row set beside the unperturbed recording's: the effective scale at the unperturbed
median speed (LS and KF, and their change), the replay's emitted/raw RMSE against
the GNSS water speed and its worst 5-min ratio. A variant that moves the ground alone
(a tidal current added to the GNSS: ``ground_only``) is scored against the unperturbed
recording's GNSS water speed (its GNSS thinned alike where the variant thins it:
``Variant.water``), its water being that one: the water speed estimated from
its own GNSS takes the current as constant over half-hour windows, and a 3-kn tide
turning over 12.42 h moves by up to 0.4 m/s in one (its scores from its own GNSS are
kept beside, ``scores_own_gnss``). :func:`verdict` names what moved: a
step that failed, a scale more than :data:`MAX_SCALE_SHIFT` from the unperturbed run,
a replay worse than raw over the log, a 5-min window worse than both the unperturbed
run's and :data:`WINDOW_TOLERANCE` by more than :data:`WINDOW_SLACK`.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import variants_csv as vcsv
import variants_json as vjson
import variants_lines as vl
from variants_csv import add_current as add_current  # the tests' tide
from variants_nmea import GAP_S as GAP_S  # the tests' gap
from variants_nmea import (
    STRONG_TIDE,
    coarse_times,
    dropouts,
    expand,
    first_date,
    gap,
    hdm,
    lagged,
    line_endings,
    map_nmea,
    midnight_date,
    midnight_gga,
    no_checksums,
    no_variation,
    other_sentences,
    pashr_of,
    prefixed,
    rmc_course_empty,
    rmc_course_empty_slow,
    rmc_to,
    thin_gnss,
    ths_of,
    tidal_rmc,
    tide_hours,
    true_heading_as,
    truncated,
    vbw,
    vhw_every,
    vhw_magnetic_only,
    vhw_twice,
)
from variants_nmea import TIDE_PHASES as TIDE_PHASES  # the tests' hours
from variants_nmea import TIDE_TURNS_DEG as TIDE_TURNS_DEG

ROOT = Path(__file__).resolve().parents[1]


def _real_data() -> ModuleType:
    """docs/real_data.py as a module (its functions run each step)."""
    here = str(ROOT / "docs")
    if here not in sys.path:
        sys.path.insert(0, here)
    return importlib.import_module("real_data")


MAX_SCALE_SHIFT = 0.05
"""A variant whose effective scale at the median speed moves more than this from the
unperturbed run's has changed the result materially."""

WORSE_THAN_RAW = 1.01
"""A replay whose emitted RMSE over the log exceeds raw's by this factor is worse than
raw (below it, the sentences' rounding to 0.01 kn)."""

WINDOW_TOLERANCE = 1.10
"""A 5-min window of the replay up to this times raw's RMSE is within the suite's
tolerance (docs/REAL_DATA.md)."""

WINDOW_SLACK = 0.05
"""A variant's worst 5-min window is flagged when it exceeds both
:data:`WINDOW_TOLERANCE` and the unperturbed run's worst by more than this."""

# ------------------------------------------------------------------ the variants


@dataclass(frozen=True)
class Variant:
    """One perturbation: the kind of log it applies to, the rewrite, what it tests, and
    any import options it needs (a function of the source text)."""

    name: str
    kind: str
    make: Callable[[str], str]
    tests: str
    options: Callable[[str], list[str]] = lambda _text: []
    ground_only: bool = False
    """The rewrite moves the ground alone (a current added to the GNSS), every line
    kept in place: the water is the unperturbed recording's, and the replay is scored
    against the unperturbed recording's GNSS water speed (:func:`run_one`)."""
    water: Callable[[str], str] = lambda text: text
    """For a ``ground_only`` variant, the unperturbed recording as the rewrite leaves it
    but for the ground's change (the same lines kept or dropped, at the same times):
    the log its GNSS water speed is scored against."""


def _nm(fn: Callable[[list[str]], list[str] | None]) -> Callable[[str], str]:
    return lambda text: expand(map_nmea(text, fn))


VARIANTS: tuple[Variant, ...] = (
    Variant(
        "gnss-0.5hz",
        "nmea",
        thin_gnss(2.0),
        "a GNSS at 0.5 Hz: alignment at the reference's cadence",
    ),
    Variant("gnss-0.2hz", "nmea", thin_gnss(5.0), "a GNSS at 0.2 Hz"),
    Variant(
        "fix-1s", "nmea", coarse_times(1.0), "fix times of 1-s resolution (repeated at > 1 Hz)"
    ),
    Variant("fix-10s", "nmea", coarse_times(10.0), "fix times of 10-s resolution"),
    Variant(
        "hdg-no-var",
        "nmea",
        _nm(no_variation),
        "HDG and RMC with empty variation: the IGRF model's",
    ),
    Variant("hdm", "nmea", _nm(hdm), "HDM, a magnetic heading alone"),
    Variant("vhw-mag", "nmea", _nm(vhw_magnetic_only), "VHW's magnetic heading the only heading"),
    Variant(
        "gga-vtg",
        "nmea",
        _nm(rmc_to(("GGA", "VTG"))),
        "GGA + VTG instead of RMC, the date given by --date",
        lambda text: ["--date", first_date(text)],
    ),
    Variant(
        "zda-gll-vtg", "nmea", _nm(rmc_to(("ZDA", "GLL", "VTG"))), "ZDA + GLL + VTG instead of RMC"
    ),
    Variant(
        "gll-vtg",
        "nmea",
        _nm(rmc_to(("GLL", "VTG"))),
        "GLL + VTG alone (no RMC, ZDA, GGA), no --date: the date the file's name holds",
    ),
    Variant(
        "rmc-slow-no-course", "nmea", _nm(rmc_course_empty_slow), "RMC without a course below 1 kn"
    ),
    Variant(
        "rmc-no-course",
        "nmea",
        _nm(rmc_course_empty),
        "RMC without a course at any speed (the course from the positions)",
    ),
    Variant(
        "other-sentences",
        "nmea",
        other_sentences,
        "other talkers, VLW, nonsense MWV, proprietary lines",
    ),
    Variant("no-checksum", "nmea", no_checksums, "sentences without checksums"),
    Variant("prefixed", "nmea", prefixed, "a receive time and a tag before each sentence"),
    Variant("crlf", "nmea", line_endings("\r\n"), "CRLF line endings"),
    Variant("lf", "nmea", line_endings("\n"), "LF line endings"),
    Variant("truncated", "nmea", truncated, "a truncated last line and a line cut by a reset"),
    Variant("gap", "nmea", gap, "a gap of minutes"),
    Variant(
        "midnight-gga",
        "nmea",
        midnight_gga,
        "midnight crossed with GGA times of day and no ZDA",
        lambda text: ["--date", midnight_date(text)],
    ),
    Variant(
        "tide",
        "nmea",
        _nm(tidal_rmc),
        "a 1.5-kn tidal current turning over 12.42 h",
        ground_only=True,
    ),
    Variant(
        "tide-strong",
        "nmea",
        _nm(lambda f: tidal_rmc(f, STRONG_TIDE)),
        "a 3-kn tidal current (a tidal race, a fjord's narrows)",
        ground_only=True,
    ),
    Variant(
        "tide-gnss-0.5hz",
        "nmea",
        lambda text: thin_gnss(2.0)(_nm(tidal_rmc)(text)),
        "the 1.5-kn tide with a GNSS at 0.5 Hz",
        ground_only=True,
        water=thin_gnss(2.0),
    ),
    *(Variant(n, "nmea", fn, doc, ground_only=True) for n, fn, doc in tide_hours()),
    Variant("log-lags-2s", "nmea", lagged(2.0), "the log 2 s behind the GNSS"),
    Variant("log-leads-2s", "nmea", lagged(-2.0), "the log 2 s ahead of the GNSS"),
    Variant("log-half-rate", "nmea", vhw_every(2), "every other VHW: the log at half its rate"),
    Variant("log-twice", "nmea", vhw_twice, "a VHW twice per fix: the log at twice its rate"),
    Variant(
        "log-dropouts", "nmea", dropouts(frozenset({"VHW"})), "the log silent 30 s every 5 min"
    ),
    Variant(
        "gnss-dropouts",
        "nmea",
        dropouts(frozenset({"RMC", "GGA", "GLL", "VTG", "ZDA"})),
        "the GNSS silent 30 s every 5 min",
    ),
    Variant(
        "ths",
        "nmea",
        _nm(true_heading_as(ths_of)),
        "THS, a GNSS compass's true heading, the only heading",
    ),
    Variant(
        "pashr",
        "nmea",
        _nm(true_heading_as(pashr_of)),
        "$PASHR, an INS's attitude, the only heading",
    ),
    Variant("vbw", "nmea", _nm(vbw), "VBW instead of VHW (a log sending VBW alone)"),
    *(
        Variant(f"stamp-{name}", "nmea", vl.stamped(name), f"a receive time ({name}) first")
        for name in vl.STAMPS
    ),
    Variant(
        "opencpn-csv",
        "nmea",
        vl.opencpn_csv,
        "OpenCPN's data log in CSV: epoch ms, protocol, address, source, the sentence quoted",
    ),
    Variant("cr", "nmea", line_endings("\r"), "CR line endings alone"),
    Variant("bom", "nmea", lambda text: "\ufeff" + text, "a UTF-8 byte-order mark"),
    Variant("nul-padded", "nmea", vl.nul_padded, "NULs after each line and ending the file"),
    Variant("split-lines", "nmea", vl.split_lines, "sentences split over two lines"),
    Variant("ais", "nmea", vl.with_ais, "AIS sentences (!AIVDM) mixed in"),
    Variant("doubled", "nmea", vl.doubled, "every line logged twice"),
    Variant("log-0.2hz", "nmea", vhw_every(4), "every 4th VHW: the log at about 0.2 Hz"),
    Variant(
        "rmc-no-date",
        "nmea",
        vl.rmc_no_date,
        "RMC without its date (given by --date)",
        lambda text: ["--date", first_date(text)],
    ),
    Variant("midnight-rmc", "nmea", vl.midnight_rmc, "midnight crossed, RMC with its dates"),
    Variant(
        "midnight-rmc-no-date",
        "nmea",
        vl.midnight_rmc_no_date,
        "midnight crossed by RMC without a date (--date the first fix's)",
        lambda text: ["--date", midnight_date(text)],
    ),
    Variant(
        "two-sessions",
        "nmea",
        vl.two_sessions,
        "two sessions of one day in one file, the second 3 h after the first",
    ),
    Variant(
        "time-reset",
        "nmea",
        vl.time_reset,
        "the fix times an hour earlier from the middle on (a receiver reset)",
    ),
    Variant(
        "midnight-date-late",
        "nmea",
        vl.midnight_date_late,
        "midnight crossed by RMC whose date advances 5 s late",
    ),
    Variant("leap-second", "nmea", vl.leap_second, "midnight crossed with a leap second 23:59:60"),
    Variant("late-fixes", "nmea", vl.late_fixes, "every 5th fix's time a second late (jitter)"),
    Variant(
        "moored-hour",
        "nmea",
        vl.moored,
        "an hour moored before the start (at rest: nothing to learn from it)",
    ),
    Variant(
        "signed-variation",
        "nmea",
        _nm(vl.signed_variation),
        "RMC's and HDG's variation signed (west negative), no E/W",
    ),
    Variant("vhw-kmh", "nmea", _nm(vl.vhw_kmh_only), "VHW's speed in km/h alone"),
    Variant(
        "hdm-rmc-var",
        "nmea",
        _nm(vl.hdm_rmc_variation),
        "HDM the only heading, the variation in RMC's field alone",
    ),
    Variant(
        "gnss-0.5hz-log-2hz",
        "nmea",
        lambda text: thin_gnss(2.0)(vhw_twice(text)),
        "a GNSS at 0.5 Hz and the log at twice its rate",
    ),
    Variant(
        "signalk",
        "nmea",
        vjson.signalk,
        "a Signal K delta log (SI units, an AIS target's deltas among the boat's)",
        lambda _text: ["--format", "json"],
    ),
    Variant(
        "canboat",
        "nmea",
        vjson.canboat,
        "NMEA 2000 as canboat analyzer JSON (PGNs 128259, 127250, 129026, 129025)",
        lambda _text: ["--format", "json"],
    ),
    Variant(
        "n2k-plain",
        "nmea",
        vjson.n2k_plain,
        "NMEA 2000 as canboat's plain text (the same PGNs' bytes)",
        lambda _text: ["--format", "n2k"],
    ),
    Variant(
        "set-drift",
        "expedition-csv",
        vcsv.rename({"iSet": "Set", "iDrift": "Drift"}),
        "Set/Drift for iSet/iDrift",
    ),
    Variant("no-current", "expedition-csv", vcsv.drop({"iSet", "iDrift"}), "no current columns"),
    Variant(
        "upper-case",
        "expedition-csv",
        vcsv.rename({"Bsp": "BSP", "Hdg": "HDG", "Sog": "SOG", "Cog": "COG", "Utc": "UTC"}),
        "Expedition 10+'s upper-case names",
    ),
    Variant("reordered", "expedition-csv", vcsv.columns(vcsv.reverse), "another column order"),
    Variant("extra-columns", "expedition-csv", vcsv.columns(vcsv.extra), "extra columns"),
    Variant(
        "hdg-magnetic",
        "expedition-csv",
        vcsv.columns(vcsv.magnetic_heading),
        "the compass's magnetic heading (HdgMag) and a MagVar column instead of Hdg",
    ),
    Variant(
        "hdg-magnetic-no-var",
        "expedition-csv",
        vcsv.columns(vcsv.magnetic_heading_alone),
        "the compass's magnetic heading (HdgMag) and no variation column: the model's",
    ),
    Variant("subset", "expedition-csv", vcsv.columns(vcsv.subset), "five columns, reordered"),
    Variant(
        "duplicate-rows", "expedition-csv", vcsv.columns(vcsv.duplicate_rows), "each row twice"
    ),
    Variant("semicolon", "expedition-csv", vcsv.semicolon, "';' delimiter and decimal commas"),
    Variant("quoted", "expedition-csv", vcsv.quoted, "every cell quoted"),
    Variant("bom-crlf", "expedition-csv", vcsv.bom_crlf, "a byte-order mark and CRLF"),
    Variant(
        "sog-0.5hz",
        "expedition-csv",
        vcsv.sparse_gnss(2.0),
        "Sog/Cog written every 2 s (a 0.5 Hz GNSS)",
    ),
    Variant("sog-0.2hz", "expedition-csv", vcsv.sparse_gnss(5.0), "Sog/Cog written every 5 s"),
    Variant(
        "tide",
        "expedition-csv",
        vcsv.columns(vcsv.tidal_cells),
        "a 1.5-kn tidal current",
        ground_only=True,
    ),
    Variant(
        "utc-text-us",
        "expedition-csv",
        vcsv.columns(vcsv.utc_text("%m/%d/%Y %I:%M:%S %p")),
        "Utc as US-English Windows writes a date and time (month first, AM/PM)",
    ),
    Variant(
        "date-time-columns",
        "expedition-csv",
        vcsv.columns(vcsv.date_time_columns),
        "Date and Time columns instead of Utc (a spreadsheet's re-export)",
    ),
    Variant(
        "sparse-log",
        "expedition-csv",
        vcsv.expedition_log,
        "Expedition's own sparse log (channel, value pairs)",
    ),
    Variant(
        "utc-date-time",
        "expedition-csv",
        vcsv.columns(vcsv.utc_date_time),
        "UtcDate and UtcTime columns instead of Utc (another program's export)",
    ),
    Variant(
        "units-row",
        "expedition-csv",
        vcsv.columns(vcsv.units_row),
        "a row of units under the header",
    ),
    Variant(
        "units-row-si",
        "expedition-csv",
        vcsv.columns(vcsv.units_row_si),
        "a row of SI units under the header (m/s, rad), the cells in them",
    ),
    Variant(
        "ole-local",
        "expedition-csv",
        vcsv.columns(vcsv.ole_local),
        "Utc as OLE days of local time, given by --utc-offset 2",
        lambda _text: ["--utc-offset", str(vcsv.LOCAL_OFFSET_H)],
    ),
    Variant(
        "nmea-field-names",
        "expedition-csv",
        vcsv.rename(vcsv.NMEA_NAMES),
        "another logger's NMEA field names (UTC, SOW, HDT, SOG, COG, SET, DRIFT)",
    ),
    Variant(
        "name-units",
        "expedition-csv",
        vcsv.rename(vcsv.NAME_UNITS),
        "units in the names: Bsp (kt), Hdg (°T), Cog (°T)",
    ),
    Variant("no-banner", "logger-tsv", vcsv.no_banner, "the logger's TSV without its banner"),
    Variant(
        "utc-offset",
        "logger-tsv",
        lambda text: text,
        "the logger's local time given as --utc-offset 2",
        lambda _text: ["--utc-offset", "2"],
    ),
    Variant(
        "logger-firmware",
        "logger-tsv",
        vcsv.logger_firmware,
        "the logger's other firmware: BS/HDG/SOG/COG names, a settings banner, '-' cells",
    ),
    Variant("rows-0.2hz", "logger-tsv", vcsv.thin_rows(5.0), "the logger's rows every 5 s"),
    Variant(
        "date-in-full", "logger-tsv", vcsv.tsv_dates("%d/%m/%Y"), "the logger's date dd/mm/yyyy"
    ),
    Variant(
        "date-year-first", "logger-tsv", vcsv.tsv_dates("%Y/%m/%d"), "the logger's date yyyy/mm/dd"
    ),
    Variant("time-fraction", "logger-tsv", vcsv.tsv_fraction, "the logger's time with tenths"),
)
"""Every variant (module docstring), by the kind of log it rewrites."""


# ------------------------------------------------------------------ running


def import_options(kind: str, extra: list[str]) -> list[list[str]]:
    """The import attempts of real_data.run_import, with the variant's options."""
    base = {"nmea": [["--format", "nmea"]], "expedition-csv": [["--format", "csv"]]}
    return [a + extra for a in base.get(kind, [["--format", "csv"]])]


def run_one(src: Path, text: str, variant: Variant | None, out: Path) -> dict[str, Any]:
    """Import, calibrate (LS, KF) and replay one variant (None: the unperturbed file)."""
    rd = _real_data()
    tag = f"{src.stem}.{variant.name if variant else 'base'}"
    path = out / f"{tag}{src.suffix}"
    data = variant.make(text) if variant else text
    path.write_bytes(
        data.encode("utf-8") if "\ufeff" in data[:1] else data.encode("latin-1", errors="replace")
    )
    row: dict[str, Any] = {"name": src.stem, "variant": variant.name if variant else "base"}
    what = rd.kind(path)  # the variant's own kind, as docs/real_data.py would tell it
    if what is None:
        row["errors"] = {"kind": "docs/real_data.py does not recognise the file as a log"}
        return row
    cap = out / f"{tag}.cap.gz"
    extra = variant.options(text) if variant else []
    doc: dict[str, Any] | None = None
    why = ""
    for opts in import_options(what or "", extra):
        rc, stdout, err = rd.emlogd(["import", str(path), *opts, "--out", str(cap), "--json"])
        if rc == 0:
            doc = json.loads(stdout)
            break
        why = rd._last_line(err) or f"exit {rc}"
    row["import"] = doc
    if doc is None:
        row["errors"] = {"import": why}
        return row
    row["errors"] = {}
    for method in ("ls", "kf"):
        res, why = rd.run_calibrate(cap, method)
        row[method] = res
        if res is None:
            row["errors"][method] = why
    emitted = out / f"{tag}.emitted.cap.gz"
    rep, why = rd.run_replay(cap, emitted)
    row["replay"] = rep["uuts"]["nmea"] if rep else None
    if rep is None:
        row["errors"]["replay"] = why
    else:
        try:
            row["scores"] = rd.water_scores(cap, emitted)
            if variant is not None and variant.ground_only:
                row["scores_own_gnss"] = row["scores"]
                truth = _truth(src, variant.water(text), what, out / tag)
                row["scores"] = rd.water_scores(truth, emitted)
        except (ValueError, RuntimeError) as exc:
            row["errors"]["scores"] = str(exc)
    return row


def _truth(src: Path, text: str, kind: str, stem: Path) -> Path:
    """The unperturbed recording ``text`` (as the variant's :attr:`Variant.water` leaves
    it) imported as ``stem.truth.cap.gz``, whose GNSS water speed scores a ground-only
    variant's replay (the same lines at the same times, the same water).

    Raises:
        RuntimeError: the unperturbed recording does not import.
    """
    path = stem.with_name(f"{stem.name}.truth{src.suffix}")
    path.write_bytes(text.encode("latin-1", errors="replace"))
    cap = stem.with_name(f"{stem.name}.truth.cap.gz")
    err = ""
    for opts in import_options(kind, []):
        rc, _, err = _real_data().emlogd(["import", str(path), *opts, "--out", str(cap)])
        if rc == 0:
            return cap
    raise RuntimeError(f"the unperturbed recording does not import: {err.strip()[-200:]}")


def scales(row: dict[str, Any], speed: float) -> tuple[float | None, float | None]:
    """(LS, KF) effective scale at ``speed``."""
    rd = _real_data()
    return rd.effective_scale(row.get("ls"), speed), rd.effective_scale(row.get("kf"), speed)


def verdict(row: dict[str, Any], base: dict[str, Any]) -> str:
    """What moved against the unperturbed run: ``ok`` or the reasons."""
    why: list[str] = []
    for step, msg in row.get("errors", {}).items():
        if step not in base.get("errors", {}):
            why.append(f"{step} fails: {msg}")
    speed = (base.get("scores") or {}).get("median_speed", math.nan)
    for label, a, b in zip(("LS", "KF"), scales(row, speed), scales(base, speed), strict=True):
        if a is not None and b is not None and abs(a - b) > MAX_SCALE_SHIFT:
            why.append(f"{label} scale {a:.3f} against {b:.3f}")
    s = row.get("scores")
    if s and s["rmse_emitted"] > WORSE_THAN_RAW * s["rmse_raw"]:
        why.append(f"replay worse than raw ({s['rmse_emitted']:.3f} > {s['rmse_raw']:.3f})")
    worst = (s or {}).get("worst_5min_ratio")
    was = (base.get("scores") or {}).get("worst_5min_ratio")
    if isinstance(worst, float) and worst > max(WINDOW_TOLERANCE, was or 0.0) + WINDOW_SLACK:
        why.append(f"a 5-min window {worst:.2f} times raw's RMSE (unperturbed {_f(was, '.2f')})")
    return "; ".join(why) or "ok"


def _f(x: object, spec: str) -> str:
    return format(x, spec) if isinstance(x, int | float) and math.isfinite(x) else "—"


def markdown(rows: list[dict[str, Any]]) -> str:
    """One line per variant: scales (LS / KF), replay RMSE and worst window, verdict."""
    out = [
        "| recording | variant | import: lines → sentences | scale LS / KF | replay at the end | "
        "emitted / raw RMSE (m/s) | worst 5-min | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    bases = {r["name"]: r for r in rows if r["variant"] == "base"}
    for r in rows:
        base = bases.get(r["name"], r)
        speed = (base.get("scores") or {}).get("median_speed", math.nan)
        ls, kf = scales(r, speed)
        imp = r.get("import")
        imported = f"{imp['lines']} → {imp['written']}" if imp else "fails"
        s = r.get("scores") or {}
        rmse = f"{_f(s.get('rmse_emitted'), '.3f')} / {_f(s.get('rmse_raw'), '.3f')}"
        v = "(reference)" if r is base else verdict(r, base)
        rep = r.get("replay")
        end = "—" if rep is None else "applied" if rep.get("params") else "raw"
        if rep is not None and rep.get("state") == "fault":
            end += " (fault)"
        out.append(
            f"| {r['name']} | {r['variant']} | {imported} | {_f(ls, '.3f')} / {_f(kf, '.3f')} | "
            f"{end} | {rmse} | {_f(s.get('worst_5min_ratio'), '.3f')} | {v} |"
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Parse the command line, run every (recording, variant), print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="the folder of recordings")
    ap.add_argument(
        "--only", nargs="*", default=[], help="recordings whose name contains one of these"
    )
    ap.add_argument("--variant", nargs="*", default=[], help="only these variants")
    ap.add_argument("--out", type=Path, help="keep the files here (default: a temporary folder)")
    ap.add_argument("--json", action="store_true", help="the rows as JSON")
    args = ap.parse_args(argv)
    rd = _real_data()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        for src in sorted(p for p in args.dir.iterdir() if p.is_file()):
            what = rd.kind(src)
            if (
                what is None
                or src.suffix == ".py"
                or (args.only and not any(o in src.stem for o in args.only))
            ):
                continue
            chosen = [
                v
                for v in VARIANTS
                if v.kind == what and (not args.variant or v.name in args.variant)
            ]
            if not chosen:
                continue
            text = src.read_bytes().decode("latin-1")
            for v in [None, *chosen]:
                rd.say(f"{src.stem}: {v.name if v else 'base'}")
                row = run_one(src, text, v, out)
                rows.append(row)
                if args.out is not None:
                    (out / "variants.json").write_text(json.dumps(rows, default=str) + "\n")
    sys.stdout.write(
        (json.dumps(rows, indent=1, default=str) if args.json else markdown(rows)) + "\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
