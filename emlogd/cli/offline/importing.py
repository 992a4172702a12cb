"""``emlogd import``: NMEA logs or CSV exports turned into a capture."""

from __future__ import annotations

import argparse
import json
import math
import sys
from datetime import date
from typing import TYPE_CHECKING, get_args

from emlogd.cli.common import Subparsers, UsageError, key_arg, progress, progress_done
from emlogd.cli.offline.args import json_arg
from emlogd.offline.importbase import ImportFormat
from emlogd.offline.importer import HeadingRef
from emlogd.pipeline.settings import UutSettings

if TYPE_CHECKING:
    from collections.abc import Callable

    from emlogd.offline.importer import ImportReport


def _date_arg(value: str) -> date:
    try:
        return date.fromisoformat(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected YYYY-MM-DD, not {value!r}") from None


MAX_UTC_OFFSET_H = 14.0
"""The largest clock offset from UTC a logger can have (the time zones span −12 to +14 h)."""


def _utc_offset_arg(value: str) -> float:
    """import --utc-offset: hours within ±:data:`MAX_UTC_OFFSET_H`."""
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and abs(x) <= MAX_UTC_OFFSET_H):
        raise argparse.ArgumentTypeError(
            f"expected hours in [-{MAX_UTC_OFFSET_H:g}, {MAX_UTC_OFFSET_H:g}], not {value!r}"
        )
    return x


def _import_presets() -> list[str]:
    from emlogd.offline.importer import PRESETS

    return list(PRESETS)


def cmd_import(args: argparse.Namespace) -> int:
    """Turn NMEA logs or CSV exports into a capture."""
    if not args.port or not args.port.isidentifier():
        raise UsageError(f"--port must be a name (letters, digits, _), not {args.port!r}")
    importers: dict[ImportFormat, Callable[[argparse.Namespace], ImportReport]] = {
        "nmea": _import_nmea,
        "csv": _import_csv,
        "json": _import_json,
        "n2k": _import_json,
    }
    report = importers[args.format](args)
    progress_done()
    if args.json:
        sys.stdout.write(json.dumps(report.to_dict(), indent=2) + "\n")
    else:
        sys.stdout.write(_report_text(report, "rows" if args.format == "csv" else "lines"))
    return 0


CSV_OPTIONS = ("map", "preset", "time_format", "heading_ref", "utc_offset", "variation")
"""The options of ``--format csv`` alone."""


def _refuse_csv_options(args: argparse.Namespace) -> None:
    for opt in CSV_OPTIONS:
        if getattr(args, opt) is not None:
            raise UsageError(f"--{opt.replace('_', '-')} applies to --format csv only")


def _import_nmea(args: argparse.Namespace) -> ImportReport:
    """``--format nmea``: the csv options refused, the logs imported."""
    from emlogd.offline import importer

    _refuse_csv_options(args)
    return importer.import_nmea(
        args.files, args.out, port=args.port, day=args.date, progress=progress
    )


def _import_json(args: argparse.Namespace) -> ImportReport:
    """``--format json`` or ``n2k``: Signal K deltas, canboat analyzer JSON or canboat
    plain text (NMEA 2000), the logs imported."""
    from emlogd.offline import importjson

    _refuse_csv_options(args)
    if args.date is not None:
        raise UsageError(
            f"--date does not apply to --format {args.format} (its messages carry dates)"
        )
    return importjson.import_json(args.files, args.out, port=args.port, progress=progress)


def _import_csv(args: argparse.Namespace) -> ImportReport:
    """``--format csv``: one file, the export imported (``--date`` for times of day alone)."""
    from emlogd.offline import importer

    if len(args.files) != 1:
        raise UsageError("--format csv imports one file at a time")
    return importer.import_csv(
        args.files[0],
        args.out,
        importer.parse_map(args.map) if args.map is not None else None,
        preset=args.preset,
        time_format=args.time_format,
        heading_ref=args.heading_ref,
        utc_offset_h=args.utc_offset,
        day=args.date,
        variation_deg=args.variation,
        port=args.port,
        progress=progress,
    )


def _report_text(report: ImportReport, read: str) -> str:
    """The import report as text (``read``: what the input counts, lines or rows)."""
    span = report.t_end - report.t_start
    skipped = {k: v for k, v in report.skipped.items() if v}
    out = [
        f"{report.out}: {report.written} sentences on port {report.port} "
        f"({span / 60.0:.1f} min) from {report.lines} {read}",
        "written      " + ", ".join(f"{k} {v}" for k, v in sorted(report.sentences.items())),
        "skipped      " + (", ".join(f"{k} {v}" for k, v in sorted(skipped.items())) or "none"),
    ]
    out += [f"cell skipped {k} {v}" for k, v in sorted(report.cells.items())]
    out += [f"note         {k} {v}" for k, v in sorted(report.notes.items())]
    if report.preset is not None:
        out.append(f"preset       {report.preset}")
    return "".join(line + "\n" for line in out + _heading_lines(report))


def _heading_lines(report: ImportReport) -> list[str]:
    """What the report says of the heading: its offset from the course, its variation."""
    out = []
    check = report.heading_check
    if check is not None and isinstance(check.get("offset_deg"), float):
        out.append(
            f"heading      {check['offset_deg']:+.1f}° from the course on straight legs"
            + (
                f" — more than leeway explains ({check['max_offset_deg']}°): is it "
                "magnetic (--heading-ref magnetic), or the compass wrong?"
                if check.get("flagged")
                else ""
            )
        )
    if report.notes["no_heading_column"]:
        out.append(
            "heading      none: no heading column, so the water sentences carry the speed "
            "alone; calibrating against GNSS needs a heading (--map heading=COLUMN, or "
            "heading_mag=COLUMN for a magnetic one, or a compass's log on the same port)"
        )
    if report.variation == "none":
        out.append(
            "heading      magnetic, and no variation nor position: give --variation DEG "
            "(here or to calibrate)"
        )
    elif report.variation is not None:
        out.append(f"heading      magnetic, variation from the {report.variation}")
    return out


def add_parser(sub: Subparsers) -> None:
    """The ``import`` sub-command."""
    p = sub.add_parser(
        "import",
        help="turn NMEA logs or CSV exports into a capture",
        description="Import logs without receive times into a capture v1 file on one port. "
        "nmea: NMEA 0183 logs, timed by their RMC (else ZDA, else GGA or GLL + --date) fixes; "
        "csv: one CSV export with a column map (or --preset expedition), written as VHW, "
        "RMC and VDR sentences at the row times; json: Signal K delta logs or NMEA 2000 as "
        "canboat analyzer JSON, n2k: NMEA 2000 in canboat's plain text, written as VHW and "
        "RMC at the messages' times. Skipped "
        "lines are counted by reason.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="input files, in time order")
    p.add_argument("--format", choices=get_args(ImportFormat), required=True, help="input format")
    p.add_argument("--out", required=True, metavar="FILE.cap", help="capture to write (.gz ok)")
    p.add_argument("--port", default="nmea", help="port name in the capture (default nmea)")
    p.add_argument(
        "--date",
        type=_date_arg,
        metavar="YYYY-MM-DD",
        help="UTC date for times of day alone: nmea, GGA- or GLL-only logs or RMC without "
        "a date (default: the file name's date, else its modification day); csv, a time "
        "column without a date column (the next day after midnight)",
    )
    p.add_argument(
        "--map",
        metavar="KEY=COL,...",
        help="csv: columns for time, stw (and date, heading, heading_mag, sog, cog, lat, lon, "
        "set, drift, variation); A|B: the first present, Col?: optional; knots unless written "
        "Col[mps], degrees unless Col[rad]",
    )
    p.add_argument(
        "--preset",
        choices=["auto", *_import_presets()],
        help="csv: a known export's columns (default without --map: auto, chosen by the header)",
    )
    p.add_argument(
        "--time-format",
        metavar="ole|iso|epoch|epoch_ms|PATTERN",
        help="csv: the time column (a strptime PATTERN for date + ' ' + time with a date "
        "column); default: the preset's, else told by the first time",
    )
    p.add_argument(
        "--heading-ref",
        choices=get_args(HeadingRef),
        help="csv: the heading's reference (default: as the column's name says it, Hdg (°M) or HDG_true, else the preset's, else true)",
    )
    p.add_argument(
        "--utc-offset",
        type=_utc_offset_arg,
        metavar="HOURS",
        help="csv: the logger's clock minus UTC (times are taken as UTC without it)",
    )
    p.add_argument(
        "--variation",
        type=key_arg(UutSettings, "magnetic_variation_deg"),
        metavar="DEG",
        help="csv: magnetic variation, + east, when no column gives one (else the IGRF "
        "model at the fixes' positions, at calibration)",
    )
    json_arg(p, "the import report as JSON")
    p.set_defaults(handler=cmd_import)
