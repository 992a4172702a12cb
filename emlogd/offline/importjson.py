"""``emlogd import --format json``: JSON-lines logs, one message a line, turned into a
capture.

Two kinds of line are read, told by their keys (they may be mixed):

- **Signal K deltas** (a Signal K server's or plugin's delta log: ``{"context": ...,
  "updates": [{"timestamp": ISO, "values": [{"path": ..., "value": ...}]}]}``), in
  Signal K's SI units: ``navigation.speedThroughWater``, ``navigation.speedOverGround``
  (m/s), ``navigation.headingTrue``, ``navigation.headingMagnetic``,
  ``navigation.courseOverGroundTrue``, ``navigation.magneticVariation`` (radians) and
  ``navigation.position`` (``{"latitude", "longitude"}`` in degrees). Only the own
  boat's deltas are read: those without a context, and those of the context that
  carries ``navigation.speedThroughWater`` most often (a first pass over the files finds
  it); another vessel's (an AIS target's) are counted ``other_vessel``.
- **NMEA 2000 in canboat's analyzer JSON** (``{"timestamp": ..., "pgn": N, "fields":
  {...}}``, values as numbers or strings; the time ISO 8601 or ``yyyy-mm-dd-hh:mm:ss.sss``)
  in the analyzer's units (speeds in m/s, angles in degrees): PGN 128259 ``Speed Water
  Referenced``, 127250 ``Heading`` with its ``Reference`` (``True`` or ``Magnetic``) and
  ``Variation``, 129026 ``SOG`` and ``COG`` (a ``COG Reference`` other than true is
  not used, counted ``cog_not_true``), 129025 and 129029 ``Latitude`` and
  ``Longitude``, 127258 ``Variation``.

- **NMEA 2000 in canboat's plain text** (``actisense-serial``'s output, a Signal K
  server's data log of an NMEA 2000 connection), its bytes decoded into the same
  messages (:mod:`emlogd.offline.importn2k`).

A line may have text before its ``{`` (a logger's receive time): the message's own
time is used. Each message's values are checked against the range a boat can produce
(:data:`emlogd.offline.csvmaps.LIMITS`; counted in ``cells`` otherwise) and become
sentences at the message's time as a CSV row's do (:mod:`emlogd.offline.importer`):
a new speed over ground or course makes an RMC (with the position and variation last
given), a new speed through the water a VHW with the heading last given (true, else
magnetic) — values taken as last given for at most :data:`CARRY_S`. Messages a few
seconds out of order (several sources on one bus) are put in order within
:data:`REORDER_S`; one later than that is counted ``time_going_back``.
"""

from __future__ import annotations

import heapq
import json
import math
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.offline import ProgressFn
from emlogd.offline.csvmaps import ANGLES, LIMITS, reasons
from emlogd.offline.importbase import (
    CaptureSink,
    ImportFormatError,
    ImportReport,
    bounded_lines,
    open_text,
    what_it_looks_like,
    within_years,
)
from emlogd.offline.importn2k import plain_message
from emlogd.pipeline.variation import model_variation

CARRY_S = 10.0
"""A value is taken as last given for at most this long, s (as a CSV cell)."""

REORDER_S = 2.0
"""Messages up to this much out of time order are put in order, s."""

DEG_PER_RAD = 180.0 / math.pi

SIGNALK_PATHS: dict[str, tuple[str, float]] = {
    "navigation.speedThroughWater": ("stw", 1.0),
    "navigation.speedOverGround": ("sog", 1.0),
    "navigation.courseOverGroundTrue": ("cog", DEG_PER_RAD),
    "navigation.headingTrue": ("heading", DEG_PER_RAD),
    "navigation.headingMagnetic": ("heading_mag", DEG_PER_RAD),
    "navigation.magneticVariation": ("variation", DEG_PER_RAD),
}
"""Signal K paths read: the key each gives and the factor from its SI unit to m/s or
degrees (``navigation.position`` is read apart)."""

SELF_PATH = "navigation.speedThroughWater"
"""The path whose context is the own boat's."""

CANBOAT_FIELDS: dict[int, tuple[tuple[str, str], ...]] = {
    128259: (("Speed Water Referenced", "stw"),),
    129026: (("SOG", "sog"), ("COG", "cog")),
    129025: (("Latitude", "lat"), ("Longitude", "lon")),
    129029: (("Latitude", "lat"), ("Longitude", "lon")),
    127258: (("Variation", "variation"),),
    127250: (("Heading", "heading"), ("Variation", "variation")),
}
"""canboat analyzer PGNs read: each field's name and the key it gives (speeds in m/s,
angles in degrees, as the analyzer writes them)."""

CANBOAT_TIME = re.compile(r"(\d{4}-\d{2}-\d{2})-(\d{2}:\d{2}:\d{2}(?:\.\d+)?)$")
"""canboat's older time stamp, ``yyyy-mm-dd-hh:mm:ss.sss`` (UTC)."""


@dataclass
class _Run:
    """One JSON import while its messages are written."""

    sink: CaptureSink
    self_context: str | None
    last: dict[str, tuple[float, float]] = field(default_factory=dict)
    queue: list[tuple[float, int, str]] = field(default_factory=list)
    seq: int = 0
    t_written: float = -math.inf
    t_newest: float = -math.inf
    refs: Counter[str] = field(default_factory=Counter)
    first_line: str = ""

    @property
    def report(self) -> ImportReport:
        return self.sink.report

    def held(self, key: str, t: float) -> float | None:
        v = self.last.get(key)
        return v[1] if v is not None and abs(t - v[0]) <= CARRY_S else None


def import_json(
    paths: Sequence[str | Path],
    out: str | Path,
    *,
    port: str = "nmea",
    progress: ProgressFn | None = None,
) -> ImportReport:
    """Import JSON-lines logs (see the module docstring), in the order given.

    Raises:
        ImportFormatError: an unreadable file, or no message giving a speed through
            the water.
    """
    report = ImportReport([str(p) for p in paths], str(out), port)
    context = _self_context(paths, report)
    sink = CaptureSink(out, port, f"emlogd import --format json: {paths[0]}", report)
    run = _Run(sink, context)
    try:
        for path in paths:
            with open_text(path) as f:
                for line in bounded_lines(f, report.skipped):
                    _line(line, run)
        _flush(run, math.inf)
        _finish(paths, run)
    except BaseException:
        sink.abort()
        raise
    sink.commit()
    if progress is not None:
        progress("import json", 1.0)
    return report


def _self_context(paths: Sequence[str | Path], report: ImportReport) -> str | None:
    """The context that carries :data:`SELF_PATH` most often (None: none does)."""
    seen: Counter[str] = Counter()
    for path in paths:
        with open_text(path) as f:
            for line in bounded_lines(f, Counter()):
                doc = _json(line) if SELF_PATH in line else None
                if doc is not None and isinstance(ctx := doc.get("context"), str):
                    seen[ctx] += 1
    if len(seen) > 1:
        report.notes["signalk_contexts"] += len(seen)
    return seen.most_common(1)[0][0] if seen else None


def _json(line: str) -> dict[str, Any] | None:
    """The JSON object from a line's first ``{`` (None: no object)."""
    at = line.find("{")
    if at < 0:
        return None
    try:
        doc = json.loads(line[at:])
    except (ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None


def _line(line: str, run: _Run) -> None:
    """One line: its messages' values set and their sentences queued."""
    if not line.strip():
        return
    run.report.lines += 1
    if run.report.lines == 1:
        run.first_line = line
    doc = _json(line)
    if doc is None and (doc := plain_message(line)) is None:
        run.report.skipped["not_a_message"] += 1
    elif "updates" in doc:
        ctx = doc.get("context")
        if ctx is not None and run.self_context is not None and ctx != run.self_context:
            run.report.skipped["other_vessel"] += 1
            return
        updates = doc["updates"] if isinstance(doc["updates"], list) else []
        got = [_signalk_update(u, run) for u in updates if isinstance(u, dict)]
        if "ok" not in got:
            run.report.skipped[_why(got)] += 1
    elif "pgn" in doc:
        why = _canboat(doc, run)
        if why:
            run.report.skipped[why] += 1
    else:
        run.report.skipped["not_a_message"] += 1


def _why(got: list[str]) -> str:
    """The reason a line gave nothing: its updates' first, else ``no_value``."""
    return next((g for g in got if g != "no_value"), "no_value")


def _time(stamp: object) -> float | None:
    """A message's time stamp → epoch seconds (naive: UTC), None when unreadable."""
    if not isinstance(stamp, str):
        return None
    m = CANBOAT_TIME.match(stamp.strip())
    text = f"{m.group(1)}T{m.group(2)}" if m else stamp.strip()
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        return None
    return (t if t.tzinfo else t.replace(tzinfo=UTC)).timestamp()


def _timed(stamp: object, run: _Run) -> float | str:
    """The message's time, or the reason it has none."""
    if stamp is None:
        return "no_time"
    t = _time(stamp)
    if t is None:
        return "bad_time"
    if not within_years(t):
        return "time_out_of_range"
    if t < run.t_written:
        return "time_going_back"
    return t


def _signalk_update(u: dict[str, Any], run: _Run) -> str:
    """One Signal K update: ``ok``, or why it gave nothing."""
    t = _timed(u.get("timestamp"), run)
    if isinstance(t, str):
        return t
    values: dict[str, Any] = {}
    for v in u.get("values") or []:
        if not isinstance(v, dict):
            continue
        path, value = v.get("path"), v.get("value")
        if path == "navigation.position" and isinstance(value, dict):
            values["lat"], values["lon"] = value.get("latitude"), value.get("longitude")
        elif isinstance(path, str) and path in SIGNALK_PATHS:
            key, factor = SIGNALK_PATHS[path]
            x = _number(value, run, key)
            if x is not None:
                values[key] = x * factor
    return _message(t, values, run)


def _canboat(doc: dict[str, Any], run: _Run) -> str:
    """One canboat analyzer message: empty, or why it gave nothing."""
    try:
        pgn = int(doc["pgn"])
    except (TypeError, ValueError):
        return "bad_pgn"
    wanted = CANBOAT_FIELDS.get(pgn)
    if wanted is None:
        return "pgn_not_read"
    t = _timed(doc.get("timestamp"), run)
    if isinstance(t, str):
        return t
    fields = doc.get("fields")
    fields = fields if isinstance(fields, dict) else {}
    values: dict[str, float] = {}
    for name, key in wanted:
        if name in fields:
            x = _number(fields[name], run, key)
            if x is not None:
                values[key] = x
    if pgn == 127250 and "heading" in values and _enum(fields.get("Reference")) != "true":
        values["heading_mag"] = values.pop("heading")
    if pgn == 129026 and "cog" in values and _enum(fields.get("COG Reference")) != "true":
        del values["cog"]
        run.report.cells["cog: cog_not_true"] += 1
    return "" if _message(t, values, run) == "ok" else "no_value"


def _enum(value: object) -> str:
    """A canboat lookup field's name, folded (``True``; ``{"name": "True"}``)."""
    if isinstance(value, dict):
        value = value.get("name")
    return str(value).strip().casefold()


def _number(value: object, run: _Run, key: str) -> float | None:
    """A value as a float (a number or a numeric string), None (counted) otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        run.report.cells[f"{key}: not_a_number"] += 1
        return None
    try:
        x = float(value)
    except ValueError:
        run.report.cells[f"{key}: not_a_number"] += 1
        return None
    return x


def _message(t: float, values: dict[str, Any], run: _Run) -> str:
    """A message's values at ``t`` checked, set and their sentences queued: ``ok``, or
    ``no_value``."""
    new: set[str] = set()
    for key, x in values.items():
        if not isinstance(x, int | float) or isinstance(x, bool):
            run.report.cells[f"{key}: not_a_number"] += 1
            continue
        lo, hi = LIMITS[key]
        if not (math.isfinite(x) and lo <= x <= hi):
            run.report.cells[f"{key}: out_of_range"] += 1
            continue
        run.last[key] = (t, x % 360.0 if key in ANGLES else float(x))
        new.add(key)
    if not new:
        return "no_value"
    if new & {"sog", "cog"}:
        _queue(t, _fix(t, run), run)
    if "stw" in new:
        _queue(t, _water(t, run), run)
    return "ok"


def _fix(t: float, run: _Run) -> str | None:
    """RMC from the values last given (None without both speed and course)."""
    sog, cog = run.held("sog", t), run.held("cog", t)
    if sog is None or cog is None:
        return None
    lat, lon, var = run.held("lat", t), run.held("lon", t), run.held("variation", t)
    hdg, ref = _heading(t, run)
    if hdg is not None and ref == "magnetic":
        var_m = var if var is not None else _model(lat, lon, t)
        hdg = None if var_m is None else (hdg + var_m) % 360.0
    if hdg is not None:
        run.sink.check.add(t, hdg, sog, cog)
    when = datetime.fromtimestamp(t, UTC)
    return encode_rmc(when, sog, cog, lat_deg=lat, lon_deg=lon, variation_deg=var, talker="GP")


def _model(lat: float | None, lon: float | None, t: float) -> float | None:
    return None if lat is None or lon is None else model_variation(lat, lon, t)


def _heading(t: float, run: _Run) -> tuple[float | None, str]:
    """The heading last given, true before magnetic, and its reference."""
    hdg = run.held("heading", t)
    if hdg is not None:
        return hdg, "true"
    return run.held("heading_mag", t), "magnetic"


def _water(t: float, run: _Run) -> str:
    """VHW: the speed through the water and the heading last given."""
    stw = run.held("stw", t)
    assert stw is not None
    hdg, ref = _heading(t, run)
    if hdg is not None:
        run.refs[ref] += 1
    else:
        run.report.notes["water_without_heading"] += 1
    return encode_vhw(
        stw,
        heading_true_deg=hdg if ref == "true" else None,
        heading_mag_deg=hdg if ref == "magnetic" else None,
        talker="II",
    )


def _queue(t: float, line: str | None, run: _Run) -> None:
    """A sentence queued at ``t``; those :data:`REORDER_S` older than the newest written."""
    if line is None:
        return
    heapq.heappush(run.queue, (t, run.seq, line))
    run.seq += 1
    run.t_newest = max(run.t_newest, t)
    _flush(run, run.t_newest - REORDER_S)


def _flush(run: _Run, until: float) -> None:
    while run.queue and run.queue[0][0] <= until:
        t, _, line = heapq.heappop(run.queue)
        run.sink.write(t, line)
        run.t_written = t


def _finish(paths: Sequence[str | Path], run: _Run) -> None:
    """The heading's reference and check into the report.

    Raises:
        ImportFormatError: no speed through the water written.
    """
    report = run.report
    if run.refs:
        report.heading_ref = run.refs.most_common(1)[0][0]
    if report.heading_ref == "magnetic":
        report.variation = (
            "column" if "variation" in run.last else "model" if "lat" in run.last else "none"
        )
    if run.sink.check.n:
        report.heading_check = run.sink.check.as_dict()
    if report.sentences["VHW"] == 0:
        looks = what_it_looks_like(run.first_line) if report.skipped["not_a_message"] else ""
        raise ImportFormatError(
            f"{paths[0]}: no Signal K delta with navigation.speedThroughWater nor canboat "
            f"PGN 128259 'Speed Water Referenced' with a time (lines {report.lines}; "
            f"skipped: {reasons(report.skipped) or 'none'}; "
            f"values: {reasons(report.cells) or 'none'})"
            + (f"; the file looks like {looks}" if looks else "")
        )
