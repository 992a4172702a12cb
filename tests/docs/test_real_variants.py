"""The perturbation suite (docs/real_variants.py): each variant built in tmp from the
shared real recordings (skipped when absent).

The default run imports every variant of an excerpt of its recording and checks what
the import must keep (the same sentences for a change of format, the same span for a
midnight crossed, fewer fixes for a thinned GNSS) and that a magnetic heading without
any variation in the log still pairs with the reference; ``pytest -m real`` runs the
whole suite per variant (import, LS and KF calibration, replay) against the
unperturbed recording, where what does not hold yet is a strict xfail with its reason.
"""

from __future__ import annotations

import importlib
import math
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw
from drivers.records import KNOT_MPS
from emlogd.offline.dataset import record_capture
from emlogd.offline.importbase import ImportReport
from emlogd.offline.importer import import_csv, import_nmea
from emlogd.offline.importjson import import_json
from emlogd.pipeline.settings import UutSettings
from tests.once import Imported

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT.parent / "shared" / "real"

pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason=f"no real recordings at {REAL}")

SOURCES = {
    "nmea": "irene-2014-06-27-leman.nmea",
    "expedition-csv": "expedition-valencia.csv",
    "logger-tsv": "astra-race-2017-07-08-trieste.tsv",
}
"""The recording each kind's variants are built from."""

EXCERPT_LINES = {"nmea": 3000, "expedition-csv": 800, "logger-tsv": 800}
"""The default run's variants are built from this many first lines of each kind's log
(5 to 30 minutes of log)."""


def _suite() -> ModuleType:
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        return importlib.import_module("real_variants")
    finally:
        sys.path.remove(str(ROOT / "docs"))


rv = _suite()
VARIANTS = {(v.kind, v.name): v for v in rv.VARIANTS}


def _text(kind: str, excerpt: bool = True) -> str:
    src = REAL / SOURCES[kind]
    if not src.is_file():
        pytest.skip(f"{src.name} absent")
    text: str = src.read_bytes().decode("latin-1")
    if not excerpt:
        return text
    return "".join(text.splitlines(keepends=True)[: EXCERPT_LINES[kind]])


def _import(kind: str, text: str, tmp: Path, options: list[str]) -> tuple[ImportReport, Path]:
    """Import a variant's text as ``emlogd import`` would with the options it names."""
    suffix = Path(SOURCES[kind]).suffix
    src = tmp / f"variant{suffix}"
    src.write_bytes(text.encode("utf-8") if text[:1] == "\ufeff" else text.encode("latin-1"))
    cap = tmp / "variant.cap.gz"
    opts = dict(zip(options[::2], options[1::2], strict=True))
    if opts.get("--format") in ("json", "n2k"):
        return import_json([src], cap), cap
    if kind == "nmea":
        day = opts.get("--date")
        from datetime import date

        return import_nmea([src], cap, day=date.fromisoformat(day) if day else None), cap
    offset = opts.get("--utc-offset")
    return import_csv(src, cap, utc_offset_h=float(offset) if offset else None), cap


def _variant(kind: str, name: str, tmp: Path) -> tuple[ImportReport, ImportReport, Path]:
    """(the excerpt's report, the variant's report, the variant's capture)."""
    v = VARIANTS[(kind, name)]
    text = _text(kind)
    if kind not in _EXCERPTS:
        (tmp / "base").mkdir()
        _EXCERPTS[kind] = _import(kind, text, tmp / "base", [])[0]
    rep, cap = _import(kind, v.make(text), tmp, v.options(text))
    return _EXCERPTS[kind], rep, cap


_EXCERPTS: dict[str, ImportReport] = {}
"""Each kind's unperturbed excerpt imported once."""


@pytest.mark.parametrize(("kind", "name"), sorted(VARIANTS))
def test_every_variant_is_told_by_its_content(kind: str, name: str, tmp_path: Path) -> None:
    """docs/real_data.py tells each variant's kind as its recording's (a BOM, another
    delimiter, a prefix before each sentence, a long banner, Expedition's sparse log,
    units after the names), or a table's under another logger's names."""
    text = _text(kind)
    v = VARIANTS[(kind, name)]
    src = tmp_path / f"variant{Path(SOURCES[kind]).suffix}"
    out = v.make(text)
    src.write_bytes(out.encode("utf-8") if out[:1] == "\ufeff" else out.encode("latin-1"))
    assert rv._real_data().kind(src) == OTHER_KIND.get((kind, name), kind)


OTHER_KIND = {
    ("expedition-csv", "nmea-field-names"): "csv",
    ("nmea", "signalk"): "json",
    ("nmea", "canboat"): "json",
    ("nmea", "n2k-plain"): "n2k",
}
"""Variants that are another kind of log than their source (another logger's names)."""


SAME_SENTENCES = [
    ("nmea", "no-checksum"),
    ("nmea", "prefixed"),
    ("nmea", "crlf"),
    ("nmea", "lf"),
    ("nmea", "other-sentences"),
    *(("nmea", f"stamp-{name}") for name in rv.vl.STAMPS),
    ("nmea", "opencpn-csv"),
    ("nmea", "cr"),
    ("nmea", "bom"),
    ("nmea", "nul-padded"),
    ("nmea", "split-lines"),
    ("nmea", "ais"),
    ("nmea", "signed-variation"),
    ("nmea", "vhw-kmh"),
    ("expedition-csv", "set-drift"),
    ("expedition-csv", "upper-case"),
    ("expedition-csv", "reordered"),
    ("expedition-csv", "extra-columns"),
    ("expedition-csv", "duplicate-rows"),
    ("expedition-csv", "semicolon"),
    ("expedition-csv", "quoted"),
    ("expedition-csv", "bom-crlf"),
    ("expedition-csv", "sparse-log"),
    ("expedition-csv", "units-row"),
    ("expedition-csv", "units-row-si"),
    ("expedition-csv", "ole-local"),
    ("expedition-csv", "nmea-field-names"),
    ("expedition-csv", "name-units"),
    ("logger-tsv", "no-banner"),
    ("logger-tsv", "utc-offset"),
    ("logger-tsv", "logger-firmware"),
    ("logger-tsv", "date-in-full"),
    ("logger-tsv", "date-year-first"),
    ("logger-tsv", "time-fraction"),
]
"""Variants that change only the format: the import writes the same sentences."""


@pytest.mark.parametrize(("kind", "name"), SAME_SENTENCES)
def test_a_change_of_format_imports_the_same_sentences(
    kind: str, name: str, tmp_path: Path
) -> None:
    """Line endings, checksums, talkers and extra sentences, column names, order,
    delimiters, quotes, a BOM, Expedition's sparse log, a banner: the same samples."""
    base, rep, _ = _variant(kind, name, tmp_path)
    # the other logger firmware writes '-' for its current at first: fewer VDR
    keep = ("RMC", "VHW", "HDG") if name == "logger-firmware" else ("RMC", "VHW", "VDR", "HDG")
    assert {k: rep.sentences[k] for k in keep} == {k: base.sentences[k] for k in keep}
    assert rep.t_end - rep.t_start == pytest.approx(base.t_end - base.t_start)
    if name == "utc-offset":
        assert rep.t_start == pytest.approx(base.t_start - 7200.0)


def test_a_units_row_of_si_units_reads_the_same_speeds_and_headings(tmp_path: Path) -> None:
    """The export's speeds in m/s and angles in radians under a row that says so: the
    water readings and the fixes are the unperturbed export's (to their rounding)."""
    _, rep, cap = _variant("expedition-csv", "units-row-si", tmp_path)
    assert rep.notes["units_row"] == 1
    (tmp_path / "unperturbed").mkdir()
    _, base_cap = _import("expedition-csv", _text("expedition-csv"), tmp_path / "unperturbed", [])
    got, want = _vhw_rmc(cap), _vhw_rmc(base_cap)
    assert len(got) == len(want) > 100
    assert np.allclose(got, want, atol=0.011)


def _vhw_rmc(cap: Path) -> np.ndarray:
    """(STW kn, heading °, SOG kn, COG °) of each VHW and RMC of a capture, in order."""
    dec = make_decoder("nmea0183", "nmea")
    out = []
    for r in CaptureReader(cap):
        for x in dec.feed(r.data):
            if isinstance(x, Vhw):
                out.append((x.stw_knots or 0.0, x.heading_true_deg or 0.0, 0.0, 0.0))
            elif isinstance(x, Rmc):
                out.append((0.0, 0.0, (x.sog_mps or 0.0) / KNOT_MPS, x.cog_true_deg or 0.0))
    return np.array(out, dtype=float)


@pytest.mark.parametrize(
    ("recording", "share", "lines"),
    [("irene-2014-06-27-leman.nmea", 0.15, None), ("dasht-2016-05-07-trieste.nmea", 0.99, 30_000)],
)
def test_rmc_without_a_course_takes_it_from_the_positions(
    recording: str, share: float, lines: int | None, tmp_path: Path, imported: Imported
) -> None:
    """RMC without a course at any speed: the import gives those whose positions are far
    enough apart a course from them — Irene's 0.001' positions from about 6 kn (a sixth
    of the fixes of the whole log), DashT's 0.00001' at 3 Hz nearly all (its first
    ``lines`` lines: 3 223 fixes over 18 minutes, a quarter of the log) — within a few
    degrees of the course the receiver sent, unbiased; the rest stay without."""
    src = REAL / recording
    if not src.is_file():
        pytest.skip(f"{recording} absent")
    text = src.read_bytes().decode("latin-1")
    if lines is not None:
        text = "".join(text.splitlines(keepends=True)[:lines])
    v = VARIANTS[("nmea", "rmc-no-course")]
    courses = []
    for i, t in enumerate((text, v.make(text))):
        if i == 0 and lines is None:  # the whole log: imported once per run
            courses.append(_rmc_courses(imported(src)[1]))
            continue
        path = tmp_path / f"{i}.nmea"
        path.write_bytes(t.encode("latin-1"))
        rep = import_nmea([path], tmp_path / f"{i}.cap.gz")
        courses.append(_rmc_courses(tmp_path / f"{i}.cap.gz"))
    made, empty = rep.notes["course_from_positions"], rep.notes["course_empty"]
    assert made + empty == rep.sentences["RMC"] and made >= share * rep.sentences["RMC"]
    want, got = courses
    given = ~np.isnan(got)
    assert np.count_nonzero(given) == made and want.size == got.size
    diff = (got[given] - want[given] + 180.0) % 360.0 - 180.0
    assert np.median(np.abs(diff)) < 4.0 and abs(np.mean(diff)) < 1.0


def _rmc_courses(cap: Path) -> np.ndarray:
    """The course of each RMC of a capture, in order (nan without one)."""
    dec = make_decoder("nmea0183", "nmea", errors="skip")
    out = [
        math.nan if x.cog_true_deg is None else x.cog_true_deg
        for r in CaptureReader(cap)
        for x in dec.feed(r.data)
        if isinstance(x, Rmc)
    ]
    return np.array(out, dtype=float)


@pytest.mark.parametrize("name", ["signalk", "canboat", "n2k-plain"])
def test_a_json_lines_rewrite_keeps_the_water_and_the_fixes(name: str, tmp_path: Path) -> None:
    """The log as Signal K deltas, canboat analyzer JSON or plain text: every fix, the log's
    readings (but for those between fixes of one time, which the rewrite drops), the
    magnetic heading with its variation; an AIS target's deltas are not the boat's."""
    base, rep, _ = _variant("nmea", name, tmp_path)
    assert rep.sentences["RMC"] == base.sentences["RMC"]
    assert 0.95 * base.sentences["VHW"] <= rep.sentences["VHW"] <= base.sentences["VHW"]
    assert rep.t_end - rep.t_start == pytest.approx(base.t_end - base.t_start, abs=2.0)
    assert rep.heading_ref == "magnetic" and rep.variation == "column"
    assert bool(rep.skipped["other_vessel"]) == (name == "signalk")


def test_a_magnetic_heading_column_with_its_variation_is_made_true(tmp_path: Path) -> None:
    """``HdgMag`` beside ``MagVar`` (8° E) in place of ``Hdg``: read as magnetic with
    the column's variation, so the heading stands from the course as the true one did
    (taken as true it would stand 8° off), and the same sentences are written."""
    base, rep, _ = _variant("expedition-csv", "hdg-magnetic", tmp_path)
    assert rep.heading_ref == "magnetic" and rep.variation == "column"
    assert base.heading_check is not None and rep.heading_check is not None
    assert rep.heading_check["offset_deg"] == pytest.approx(
        base.heading_check["offset_deg"], abs=0.3
    )
    assert {k: rep.sentences[k] for k in ("RMC", "VHW")} == {
        k: base.sentences[k] for k in ("RMC", "VHW")
    }


def test_a_magnetic_heading_column_without_a_variation_takes_the_models(tmp_path: Path) -> None:
    """``HdgMag`` (the heading less the model's -1.26° there) and no variation column:
    read as magnetic, the variation the model's at the positions, so the heading stands
    from the course as the true one did (within 0.3°; taken as true, 1.26° off)."""
    base, rep, _ = _variant("expedition-csv", "hdg-magnetic-no-var", tmp_path)
    assert rep.heading_ref == "magnetic" and rep.variation == "model"
    assert base.heading_check is not None and rep.heading_check is not None
    assert rep.heading_check["offset_deg"] == pytest.approx(
        base.heading_check["offset_deg"], abs=0.3
    )
    assert rep.sentences == base.sentences


def test_a_subset_of_columns_keeps_the_water_and_the_fixes(tmp_path: Path) -> None:
    """Five columns in another order (no position, no current): the same VHW and RMC,
    no VDR."""
    base, rep, _ = _variant("expedition-csv", "subset", tmp_path)
    assert rep.sentences["VHW"] == base.sentences["VHW"]
    assert rep.sentences["RMC"] == base.sentences["RMC"]
    assert rep.sentences["VDR"] == 0


CALIBRATE_GNSS = ("--uut", "nmea", "--ref", "nmea", "--ref-field", "gnss", "--current")
"""``emlogd calibrate``'s options for a log against its own GNSS."""


def test_without_a_heading_column_the_import_says_so_and_calibrate_refuses(
    tmp_path: Path,
) -> None:
    """No heading column (course over ground alone): the import keeps the speed and the
    fixes and says the heading is missing (``no_heading_column``); calibrating against
    the GNSS exits non-zero with the reason in words, no traceback."""
    text = rv.vcsv.drop({"Hdg"})(_text("expedition-csv"))
    rep, cap = _import("expedition-csv", text, tmp_path, [])
    assert rep.notes["no_heading_column"] == 1 and rep.heading_ref is None
    assert rep.sentences["VHW"] > 0 and rep.sentences["RMC"] > 0
    run = subprocess.run(
        [sys.executable, "-m", "emlogd", "calibrate", *CALIBRATE_GNSS, str(cap)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=120,
    )
    assert run.returncode != 0
    assert "no heading arrived" in run.stderr and "course over ground alone" in run.stderr
    assert "Traceback" not in run.stderr


def test_without_the_current_columns_no_vdr(tmp_path: Path) -> None:
    """An Expedition export without set and drift: the same water and fixes, no VDR."""
    base, rep, _ = _variant("expedition-csv", "no-current", tmp_path)
    assert rep.sentences["VDR"] == 0 < base.sentences["VDR"]
    assert rep.sentences["VHW"] == base.sentences["VHW"]


@pytest.mark.parametrize("name", ["utc-text-us", "date-time-columns", "utc-date-time"])
def test_expedition_times_as_text_keep_the_log(name: str, tmp_path: Path) -> None:
    """Utc written as US-English text (month first, AM/PM), or Date and Time columns
    (UtcDate and UtcTime) in its place: the same water readings and current over the
    same span (to the second the text keeps)."""
    base, rep, _ = _variant("expedition-csv", name, tmp_path)
    assert rep.sentences["VHW"] == base.sentences["VHW"]
    if name != "utc-text-us":  # whole seconds: the current's repeats tell fewer samples
        assert rep.sentences["VDR"] == base.sentences["VDR"]
    assert rep.t_end - rep.t_start == pytest.approx(base.t_end - base.t_start, abs=1.0)


@pytest.mark.parametrize(
    ("name", "share"),
    [
        ("log-half-rate", 0.5),
        ("log-0.2hz", 0.25),
        ("log-twice", 2.0),
        ("doubled", 2.0),
        ("log-dropouts", 0.9),
        ("log-lags-2s", 1.0),
    ],
)
def test_the_log_at_another_rate_or_lag_keeps_its_time(
    name: str, share: float, tmp_path: Path
) -> None:
    """The log at half or twice its rate, silent 30 s every 5 min, or 2 s behind the
    GNSS: as many VHW as that makes, over the same span; the pipeline keeps nearly every
    reading of a log at twice its rate (the rate check learns its rate from the
    imported times)."""
    base, rep, cap = _variant("nmea", name, tmp_path)
    assert rep.sentences["VHW"] == pytest.approx(share * base.sentences["VHW"], rel=0.05)
    assert rep.t_end - rep.t_start == pytest.approx(base.t_end - base.t_start, abs=2.0)
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    assert record_capture(cap, s).raw.size >= 0.85 * rep.sentences["VHW"]


def test_a_log_at_twice_its_rate_in_back_to_back_pairs_keeps_its_readings(
    tmp_path: Path,
) -> None:
    """Each VHW sent twice, one line apart (a multiplexer batching a log at twice the
    GNSS's rate): the rate check learns bursts of two a fix interval and keeps nearly
    every reading. Learnt from the longer of the two intervals, 37 of 1198 were kept
    (the log babbling)."""
    text = _text("nmea")
    back_to_back = sys.modules["variants_nmea"].vhw_back_to_back
    rep, cap = _import("nmea", back_to_back(text), tmp_path, [])
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    assert record_capture(cap, s).raw.size >= 0.95 * rep.sentences["VHW"]


@pytest.mark.parametrize(("name", "sentence"), [("ths", "THS"), ("pashr", "PASHR")])
def test_a_gnss_compass_or_an_ins_alone_pairs(name: str, sentence: str, tmp_path: Path) -> None:
    """THS or $PASHR the only heading: the readings pair with the GNSS reference as with
    HDG."""
    _, rep, cap = _variant("nmea", name, tmp_path)
    assert rep.sentences[sentence] > 0 and rep.sentences.get("HDG", 0) == 0
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    al = record_capture(cap, s).aligned(0.0)
    assert np.count_nonzero(al.usable(heading=True)) > 0.8 * al.t.size


def test_a_log_sending_vbw_alone_is_read_from_vbw(tmp_path: Path) -> None:
    """VBW instead of VHW: docs/real_data.py tells the log's sentence and its readings
    pair from VBW."""
    _, rep, cap = _variant("nmea", "vbw", tmp_path)
    assert rep.sentences.get("VHW", 0) == 0 < rep.sentences["VBW"]
    assert rv._real_data().log_sentence(cap) == "VBW"
    s = UutSettings(
        port="nmea", reference_port="nmea", reference_field="gnss", current=True, uut_source="VBW"
    )
    al = record_capture(cap, s).aligned(0.0)
    assert np.count_nonzero(al.usable(heading=True)) > 0.8 * al.t.size


@pytest.mark.parametrize(
    ("kind", "name", "period_s"),
    [
        ("nmea", "gnss-0.5hz", 2.0),
        ("nmea", "gnss-0.2hz", 5.0),
        ("nmea", "fix-10s", 10.0),
        ("nmea", "tide-gnss-0.5hz", 2.0),
        ("nmea", "gnss-0.5hz-log-2hz", 2.0),
        ("expedition-csv", "sog-0.5hz", 2.0),
        ("expedition-csv", "sog-0.2hz", 5.0),
    ],
)
def test_a_slower_gnss_gives_fewer_fixes(
    kind: str, name: str, period_s: float, tmp_path: Path
) -> None:
    """GNSS thinned (or of 10-s time resolution): the fixes that time the log come at
    most once a period (and at least half as often), the water readings stay."""
    base, rep, _ = _variant(kind, name, tmp_path)
    fixes = rep.sentences["RMC"] - rep.notes["fix_time_not_increasing"]
    periods = (rep.t_end - rep.t_start) / period_s
    assert 0.5 * periods <= fixes <= periods + 1
    assert rep.sentences["VHW"] >= 0.9 * base.sentences["VHW"]


@pytest.mark.parametrize(
    "name",
    [
        "gga-vtg",
        "zda-gll-vtg",
        "gll-vtg",
        "midnight-gga",
        "midnight-rmc",
        "rmc-no-date",
        "midnight-rmc-no-date",
        "gap",
        "truncated",
        "leap-second",
        "late-fixes",
        "time-reset",
        "midnight-date-late",
    ],
)
def test_other_fixes_midnight_gaps_and_cuts_keep_the_log(name: str, tmp_path: Path) -> None:
    """GGA + VTG (with --date), ZDA + GLL + VTG, GLL + VTG alone (the date the file's),
    midnight crossed by GGA times of day or
    by RMC with or without its date (then --date) or with a leap second, RMC without a
    date, a gap of minutes, cut lines, fix times a second late now and then, the fix
    times set back an hour from the middle on (a receiver reset: the new time base
    follows the old), RMC's date advancing 5 s after midnight: the water readings keep
    their time."""
    base, rep, _ = _variant("nmea", name, tmp_path)
    span = base.t_end - base.t_start
    kept = 1.0 - rv.GAP_S / span if name == "gap" else 1.0
    assert rep.sentences["VHW"] >= 0.9 * kept * base.sentences["VHW"], rep.skipped
    assert rep.t_end - rep.t_start == pytest.approx(span, abs=2.0)


@pytest.mark.parametrize("name", ["hdg-no-var", "hdm", "vhw-mag", "hdm-rmc-var"])
def test_a_magnetic_heading_without_variation_pairs(name: str, tmp_path: Path) -> None:
    """No variation anywhere in the log (or in RMC's field alone): the heading is made
    true with the model's at the fixes' positions (or RMC's), and the readings pair
    with the GNSS reference as before."""
    _, _, cap = _variant("nmea", name, tmp_path)
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    al = record_capture(cap, s).aligned(0.0)
    assert np.count_nonzero(al.usable(heading=True)) > 0.8 * al.t.size


def test_a_gll_only_log_with_a_magnetic_heading_pairs(tmp_path: Path) -> None:
    """GLL + VTG alone and HDM without any variation: GLL's fixes, written as GGA too,
    give the model its positions, and the readings pair with the GNSS reference."""
    text = rv._nm(rv.hdm)(VARIANTS[("nmea", "gll-vtg")].make(_text("nmea")))
    rep, cap = _import("nmea", text, tmp_path, [])
    assert rep.notes["gga_from_gll"] > 0.9 * rep.sentences["GLL"]
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    al = record_capture(cap, s).aligned(0.0)
    assert np.count_nonzero(al.usable(heading=True)) > 0.8 * al.t.size


@pytest.mark.parametrize(
    ("name", "added_s"), [("two-sessions", rv.vl.SESSION_GAP_S), ("moored-hour", rv.vl.MOORED_S)]
)
def test_two_sessions_and_a_mooring_keep_every_reading(
    name: str, added_s: float, tmp_path: Path
) -> None:
    """Two sessions 3 h apart in one file, an hour moored before the start: the span
    grows by that time, every water reading of the log keeps its time (the few lines
    between the sessions' fixes are counted ``fix_gap``), and at rest nothing pairs."""
    base, rep, cap = _variant("nmea", name, tmp_path)
    assert rep.t_end - rep.t_start == pytest.approx(base.t_end - base.t_start + added_s, abs=2.0)
    assert rep.sentences["VHW"] >= base.sentences["VHW"] - 2
    assert (rep.skipped["fix_gap"] > 0) == (name == "two-sessions")
    s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
    al = record_capture(cap, s).aligned(0.0)
    assert np.count_nonzero(al.usable(heading=True)) <= base.sentences["VHW"]


@pytest.mark.parametrize(("name", "scale"), [("tide", 1.0), ("tide-strong", rv.STRONG_TIDE)])
def test_the_tide_moves_the_ground_not_the_water(name: str, scale: float, tmp_path: Path) -> None:
    """The tide variants change speed and course over ground by the current they add."""
    t = 1.4e9
    cn, ce = rv.vcsv.tide(t, scale)
    sog, _cog = rv.add_current(0.0, 0.0, t, scale)
    assert sog == pytest.approx(np.hypot(cn, ce))
    assert np.hypot(cn, ce) <= scale * rv.vcsv.TIDE_KN
    base, rep, _ = _variant("nmea", name, tmp_path)
    assert rep.sentences == base.sentences
    # every line in place at its time: the replay is scored against the unperturbed water
    assert VARIANTS[("nmea", name)].ground_only
    assert (rep.t_start, rep.t_end) == (base.t_start, base.t_end)


def test_the_tide_met_at_another_hour_or_across() -> None:
    """``tide-pNN``/``-r90``: the same tide a fraction of its cycle later, its axis turned
    clockwise (a stream running east where ``tide``'s runs north), and one variant for
    every other (phase, axis) pair."""
    t, period = 1.4e9, rv.vcsv.TIDE_PERIOD_S
    assert rv.vcsv.tide(t, 1.0, 0.25) == pytest.approx(rv.vcsv.tide(t + period / 4))
    n, e = rv.vcsv.tide(t)
    n90, e90 = rv.vcsv.tide(t, 1.0, 0.0, 90.0)
    assert (n90, e90) == pytest.approx((-e, n))
    sog, cog = rv.add_current(0.0, 0.0, t, 1.0, 0.5, 90.0)
    cn, ce = rv.vcsv.tide(t, 1.0, 0.5, 90.0)
    assert sog == pytest.approx(np.hypot(cn, ce), abs=1e-9)
    assert math.radians(cog) == pytest.approx(math.atan2(ce, cn) % (2 * math.pi))
    names = {n for k, n in VARIANTS if k == "nmea" and n.startswith("tide-")}
    hours = {
        "tide" + (f"-p{round(p * 100)}" if p else "") + (f"-r{r:.0f}" if r else "")
        for p in rv.TIDE_PHASES
        for r in rv.TIDE_TURNS_DEG
    } - {"tide"}
    assert hours <= names and len(hours) == 7
    assert all(VARIANTS[("nmea", h)].ground_only for h in hours)


@pytest.mark.parametrize("name", ["tide", "tide-strong", "tide-gnss-0.5hz", "tide-p50-r90"])
def test_a_ground_only_variant_is_scored_on_the_same_lines_without_the_tide(name: str) -> None:
    """A tidal variant's water (the log its replay is scored against) holds the same
    lines as the variant, in place, differing only in RMC's speed and course over ground:
    a thinned GNSS thinned alike."""
    v = VARIANTS[("nmea", name)]
    assert v.ground_only
    text = _text("nmea")
    moved = v.make(text).splitlines()
    water = v.water(text).splitlines()
    assert len(moved) == len(water)
    differ = [(a, b) for a, b in zip(moved, water, strict=True) if a != b]
    assert differ
    for a, b in differ:
        fa, fb = a.split("*")[0].split(","), b.split("*")[0].split(",")
        assert fa[0][3:] == "RMC"
        assert fa[:7] == fb[:7]  # the time and the position
        assert fa[9:] == fb[9:]  # the date onwards
        assert fa[7:9] != fb[7:9]  # the speed and course over ground


# The whole suite, variant by variant, against the unperturbed recording: every step
# runs and nothing moves materially (real_variants.verdict).
KNOWN: dict[tuple[str, str], str] = {}
"""What does not hold yet, by (kind, variant): strict xfails."""

_BASES: dict[str, Any] = {}


def _params() -> list[Any]:
    return [
        pytest.param(k, n, marks=pytest.mark.xfail(reason=KNOWN[(k, n)]))
        if (k, n) in KNOWN
        else pytest.param(k, n)
        for k, n in VARIANTS
    ]


@pytest.mark.real
@pytest.mark.parametrize(("kind", "name"), _params())
def test_the_whole_suite_per_variant(
    kind: str, name: str, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """import → calibrate (LS, KF) → replay, as docs/real_variants.py runs them; the
    verdict against the unperturbed recording is ``ok``."""
    src = REAL / SOURCES[kind]
    text = _text(kind, excerpt=False)
    if kind not in _BASES:
        _BASES[kind] = rv.run_one(src, text, None, tmp_path_factory.mktemp(f"{kind}-base"))
    row = rv.run_one(src, text, VARIANTS[(kind, name)], tmp_path_factory.mktemp(name))
    assert rv.verdict(row, _BASES[kind]) == "ok"


_TIDE_LEAK = (
    "the tide met at another hour: a bias or scale takes what the learner's current has "
    "not reached, validated on one heading (docs/REAL_DATA.md, the same tide at other hours)"
)

TIDE_HOURS_FAILING: dict[tuple[str, str], str] = {
    (f"{rec}.nmea", name): f"{why}: {_TIDE_LEAK}"
    for rec, name, why in (
        ("irene-2014-06-29-leman", "tide-p50-r90", "a 5-min window 1.18 times raw's"),
        ("psaros33-2014-08-22-leman", "tide-p50", "a 5-min window 1.41 times raw's"),
        ("psaros33-2014-08-22-leman", "tide-p50-r90", "a 5-min window 1.17 times raw's"),
        ("psaros33-2014-08-22-leman", "tide-p75", "a 5-min window 1.25 times raw's"),
        (
            "dasht-2016-05-07-trieste",
            "tide-p25",
            "worse than raw over the log (0.316 against 0.279 m/s), the filter's scale 1.151",
        ),
    )
}
"""The runs of the tide at other hours (``tide-pNN``, ``-r90``) that fail on this code,
with their measured figures; the other 50 of the 56 hold (docs/REAL_DATA.md)."""

OTHER_RECORDINGS: tuple[tuple[str, str], ...] = (
    ("irene-2007-11-03-leman.nmea", "tide-strong"),
    ("irene-2007-11-03-leman.nmea", "tide-gnss-0.5hz"),
    ("irene-2013-09-22-leman.nmea", "tide"),
    ("irene-2013-09-22-leman.nmea", "tide-gnss-0.5hz"),
    ("dasht-2016-05-07-trieste.nmea", "tide-gnss-0.5hz"),
    ("irene-2007-11-03-leman.nmea", "rmc-no-course"),
    ("irene-2013-09-22-leman.nmea", "rmc-no-course"),
    ("psaros33-2014-08-22-leman.nmea", "rmc-no-course"),
    # the tide at other hours: these two hold since a log's zero readings are not learnt
    ("irene-2014-06-29-leman.nmea", "tide-p25"),
    ("irene-2014-06-29-leman.nmea", "tide-p50"),
    # and this one since a calibration the sea memory refutes is not applied
    ("irene-2013-09-22-leman.nmea", "tide-p50"),
    *TIDE_HOURS_FAILING,
)
"""Variants run on another recording than their kind's, whose calibration the replay
applies (so a wrong one shows): the 3-kn tide on Irene 2007, scored against the
unperturbed recording's water (``ground_only``). Scored against its own GNSS, a 5-min
window at the log's end is 1.6 to 1.9 times raw's: with headings in fewer than three
sectors in its last three minutes, that window's current is the recording's mean, far
from a 3-kn tide's at that hour; against the unperturbed water the same emitted speeds
are 0.83 of raw's there. The 1.5-kn tide with the GNSS at 0.5 Hz on Irene 2007 and DashT
(whose least squares holds a scale its current per 30 minutes takes); on Irene 2013, at
1 Hz and at 0.5 Hz, it does not hold yet (:data:`KNOWN_OTHER`). RMC without a course
at any speed, the course from the positions around each fix: Irene 2007 (fixes 2 s apart,
positions to 0.001') and Irene 2013 hold; Psaros does not yet."""

KNOWN_OTHER: dict[tuple[str, str], str] = {
    ("irene-2013-09-22-leman.nmea", "tide"): (
        "the bias takes the current the learner's current has not reached yet (a 0.77-m/s "
        "tide against the current's prior of 0.5 m/s): m -0.032, b +0.124 applied at 42 "
        "min, a 5-min window 1.89 times raw's (docs/REAL_DATA.md, the tide's leak)"
    ),
    ("irene-2013-09-22-leman.nmea", "tide-gnss-0.5hz"): (
        "the unperturbed log's own calibration (m +0.054, b -0.057) applied 5 min earlier, "
        "in a window where raw reads 0.1 m/s low: 1.19 times raw's against the water"
    ),
    ("psaros33-2014-08-22-leman.nmea", "rmc-no-course"): (
        "courses over 15 m of 1.85-m positions are degrees off the receiver's: a 5-min "
        "window 1.31 times raw's"
    ),
    **TIDE_HOURS_FAILING,
}
"""What does not hold yet among :data:`OTHER_RECORDINGS`: strict xfails."""


@pytest.mark.real
@pytest.mark.parametrize(
    ("recording", "name"),
    [
        pytest.param(r, n, marks=pytest.mark.xfail(reason=KNOWN_OTHER[(r, n)]))
        if (r, n) in KNOWN_OTHER
        else pytest.param(r, n)
        for r, n in OTHER_RECORDINGS
    ],
)
def test_the_whole_suite_on_another_recording(
    recording: str, name: str, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """As :func:`test_the_whole_suite_per_variant`, on a recording whose replay applies
    its calibration."""
    src = REAL / recording
    if not src.is_file():
        pytest.skip(f"{recording} absent")
    text = src.read_bytes().decode("latin-1")
    base = rv.run_one(src, text, None, tmp_path_factory.mktemp(f"{src.stem}-base"))
    variant = next(v for v in rv.VARIANTS if v.kind == "nmea" and v.name == name)
    row = rv.run_one(src, text, variant, tmp_path_factory.mktemp(name))
    assert rv.verdict(row, base) == "ok"
