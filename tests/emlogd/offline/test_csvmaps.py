"""CSV column maps and presets: the maps a header is tried against, the header found past a
banner, each cell read into SI units within a boat's range, the time format told."""

from __future__ import annotations

import math
from collections import Counter

import pytest

from drivers.records import KNOT_MPS
from emlogd.offline.csvmaps import (
    EXPEDITION,
    LOGGER_TSV,
    PRESETS,
    Col,
    candidate_maps,
    cell_value,
    find_header,
    guess_time_format,
    no_header,
    parse_map,
    unknown_units,
)
from emlogd.offline.importbase import ImportFormatError, ImportReport


@pytest.mark.parametrize(
    ("spec", "match"),
    [("time=Utc,bogus=X", "bogus"), ("time", "key=Column"), ("time=", "key=Column")],
)
def test_bad_map(spec: str, match: str) -> None:
    """A malformed map names the item at fault."""
    with pytest.raises(ImportFormatError, match=match):
        parse_map(spec)


def test_a_unit_the_map_does_not_know_is_named() -> None:
    """``stw=Bsp[furlong]``: the error names the column and its unit, and the units a
    map knows."""
    maps = candidate_maps({"time": "Utc", "stw": "Bsp[furlong]"}, None)
    with pytest.raises(ImportFormatError, match=r"'Bsp\[furlong\]'.*\[mps\] or \[kn\].*\[rad\]"):
        find_header(["Utc,Bsp"], maps)


def test_candidate_maps() -> None:
    """Without a map every preset is tried in order; a map alone is tried as it is; the
    user's columns override a named preset's; an unknown preset or a map without stw is
    refused."""
    assert [p.name for p, _ in candidate_maps(None, None) if p] == list(PRESETS)
    assert candidate_maps({"time": "T", "stw": "S"}, None) == [(None, {"time": "T", "stw": "S"})]
    ((preset, m),) = candidate_maps({"stw": "Speed"}, "expedition")
    assert preset is PRESETS["expedition"] and m == {**EXPEDITION, "stw": "Speed"}
    with pytest.raises(ImportFormatError, match="no preset 'nope'"):
        candidate_maps(None, "nope")
    with pytest.raises(ImportFormatError, match="needs stw="):
        candidate_maps({"time": "T"}, None)


def test_the_header_is_found_past_a_banner_with_its_delimiter() -> None:
    """The header is the first line holding a map's required columns, with the delimiter
    it is written with, its columns matched in any case."""
    lines = ["Logger v2 export", "started 10:00", "DATE\tTIME\tBOATSPEED\tHEADING", "1\t2\t3\t4"]
    found = find_header(lines, candidate_maps(None, None))
    assert found is not None
    index, delim, preset, cols = found
    assert (index, delim, preset) == (2, "\t", PRESETS["logger-tsv"])
    assert {k: c.index for k, c in cols.items()} == {"date": 0, "time": 1, "stw": 2, "heading": 3}
    assert set(cols) <= set(LOGGER_TSV)
    assert find_header(["a,b,c"], candidate_maps(None, None)) is None


def test_names_written_with_spaces_match_the_maps_underscores() -> None:
    """``Boat Speed (kn)``, ``Heading True``, ``Speed Over Ground``, ``Date Time``: the
    generic map's ``boat_speed``, ``heading_true``, ``speed_over_ground``, ``date_time``."""
    head = ["Date Time,Boat Speed (kn),Heading True,Speed Over Ground,Course-Over-Ground"]
    found = find_header(head, candidate_maps(None, None))
    assert found is not None and found[2] is PRESETS["generic"]
    assert {k: c.index for k, c in found[3].items()} == {
        "time": 0,
        "stw": 1,
        "heading": 2,
        "sog": 3,
        "cog": 4,
    }


def test_a_unit_in_a_name_is_read_or_named_as_unknown() -> None:
    """``Bsp (mph)`` is read in miles per hour; a unit no table knows stops the import
    with the column and its unit named, and how to map it."""
    found = find_header(["Utc,Bsp (mph),Hdg"], candidate_maps(None, None))
    assert found is not None and found[3]["stw"].factor == pytest.approx(0.44704)
    head = ["Utc,Bsp (furlongs),Hdg"]
    assert find_header(head, candidate_maps(None, None)) is None
    why = no_header("x.csv", head, candidate_maps(None, None))
    assert "units not known in 'Bsp (furlongs)' ('furlongs')" in why and "[mps]" in why


def test_angles_in_radians_are_read_as_degrees() -> None:
    """A logger writing Signal K's SI units: ``Hdg (rad)``, ``COG [rad]``, ``heading_rad``
    and the map's ``[rad]`` make the angle's factor to degrees; a speed keeps its own
    (m/s in its name, else knots); degrees stay degrees."""
    head = ["time;speed (m/s);hdg (rad);sog (km/h);cog [rad];set (deg)"]
    found = find_header(head, candidate_maps(None, None))
    assert found is not None
    factors = {k: c.factor for k, c in found[3].items()}
    deg = 180.0 / math.pi
    assert factors == pytest.approx(
        {"time": 1.0, "stw": 1.0, "heading": deg, "sog": 1 / 3.6, "cog": deg, "set": 1.0}
    )
    assert unknown_units(head[0].split(";")) == []
    found = find_header(["time,speed,heading_rad"], candidate_maps(None, None))
    assert found is not None and found[3]["heading"].factor == pytest.approx(deg)
    maps = candidate_maps({"time": "T", "stw": "B[mps]", "heading": "H[rad]"}, None)
    found = find_header(["T,B,H"], maps)
    assert found is not None
    assert (found[3]["stw"].factor, found[3]["heading"].factor) == pytest.approx((1.0, deg))
    rep = ImportReport([], "", "")
    assert cell_value("3.14159265", found[3]["heading"], rep) == pytest.approx(180.0)


def test_nmea_field_names_and_true_degrees_are_read() -> None:
    """Another logger's NMEA field names (``SOW``, ``HDT``, ``HdgMag``) and an ECDIS
    logbook's (``Log (kt)``, ``Heading (˚)``) are the generic map's; ``°T``, ``˚`` and
    ``º`` after a name are an angle's unit, ``°M`` a magnetic heading's, ``°F`` one no
    table knows."""
    found = find_header(["UTC,SOW,HDT,SOG,COG,TWD"], candidate_maps(None, None))
    assert found is not None and found[2] is PRESETS["generic"]
    keys = ("time", "stw", "heading", "sog", "cog")
    assert {k: c.index for k, c in found[3].items()} == dict(zip(keys, range(5), strict=True))
    found = find_header(["Timestamp,BSP (kt),HdgMag (°),COG (°T)"], candidate_maps(None, None))
    assert found is not None and set(found[3]) == {"time", "stw", "heading_mag", "cog"}
    assert unknown_units(["Hdg (°M)", "Cog (°T)", "Bsp (kt)", "Tmp (°F)"]) == ["'Tmp (°F)' ('°F')"]
    found = find_header(["Utc,Bsp,Hdg (°M)"], candidate_maps(None, None))
    assert found is not None and found[3]["heading"].ref == "magnetic"
    found = find_header(
        ["Date Time,Log (kt),Heading (˚),COG (º),SOG (kt)"], candidate_maps(None, None)
    )
    assert found is not None and set(found[3]) == {"time", "stw", "heading", "cog", "sog"}


def test_cells_in_si_units_within_a_boats_range() -> None:
    """Speeds in knots become m/s, angles wrap into [0, 360), ddmm.mmmm positions become
    degrees; a cell beyond a boat's range (the speed the NMEA decoder takes, which reads
    the sentences written from it) or no number is counted by column and reason."""
    report = ImportReport([], "", "p")
    stw = Col("stw", 0, KNOT_MPS)
    assert cell_value("10", stw, report) == pytest.approx(10 * KNOT_MPS)
    assert cell_value("-10", Col("heading", 0, 1.0), report) == 350.0
    assert cell_value("4530.0000S", Col("lat", 0, 1.0), report) == pytest.approx(-45.5)
    assert cell_value("3,5", stw, report) == pytest.approx(3.5 * KNOT_MPS)  # a decimal comma
    assert cell_value("77", stw, report) == pytest.approx(77 * KNOT_MPS)
    assert cell_value("79", stw, report) is None  # past the NMEA decoder's MAX_SPEED_MPS
    assert cell_value("fast", stw, report) is None
    assert cell_value("4530.0000E", Col("lat", 0, 1.0), report) is None
    assert report.cells == Counter(
        {"stw: out_of_range": 1, "stw: not_a_number": 1, "lat: not_a_number": 1}
    )


@pytest.mark.parametrize(
    ("cell", "fmt"),
    [
        ("1700000000", "epoch"),
        ("1700000000123", "epoch_ms"),
        ("38353.5", "ole"),
        ("2005-01-01T12:00:00", "iso"),
        ("12", None),
        ("13/06/2005 09:19:33", "%d/%m/%Y %H:%M:%S"),
        ("13/06/05 09:19:33.25", "%d/%m/%y %H:%M:%S.%f"),
        ("13.06.2005 09:19:33", "%d.%m.%Y %H:%M:%S"),
        ("2005/06/13 09:19:33", "%Y/%m/%d %H:%M:%S"),
        ("06/13/2005 09:19:33", None),
        ("6/13/2005 9:19:33 AM", "%m/%d/%Y %I:%M:%S %p"),
        ("6/13/2005 9:19:33 PM", "%m/%d/%Y %I:%M:%S %p"),
        ("13/06/2005 09:19", None),
    ],
)
def test_the_time_format_is_told_by_the_first_cell(cell: str, fmt: str | None) -> None:
    """Epoch seconds or milliseconds, an OLE date, ISO 8601, a day-first date and time or a month-first
    one with AM/PM are told apart; anything else (a month-first date past the 12th on a
    24-h clock, minutes alone) is not guessed."""
    assert guess_time_format(cell) == fmt
