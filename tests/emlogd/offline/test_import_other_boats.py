"""``emlogd import`` of logs another boat or tool writes of the kinds the real recordings
are: the same rows under other heading names, units and cell forms read as the
recordings' own are."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw, encode_rmc, encode_vhw
from emlogd.offline.csvmaps import Col, cell_value
from emlogd.offline.importbase import ImportReport
from emlogd.offline.importer import import_csv, import_nmea

OLE_2005 = 38516.5  # 2005-06-13 12:00 UTC
SEC = 1.0 / 86400.0


def _vhw(cap: Path) -> list[Vhw]:
    dec = make_decoder("nmea0183", "nmea")
    return [x for r in CaptureReader(cap) for x in dec.feed(r.data) if isinstance(x, Vhw)]


def _expedition(tmp_path: Path, hdg: str) -> Path:
    """An Expedition export whose heading column is named ``hdg``."""
    p = tmp_path / "log.csv"
    rows = [f"{OLE_2005 + i * SEC:.8f},5.0,{90 + i},5.2,92,39.4,-0.3" for i in range(5)]
    p.write_text(f"Utc,Bsp,{hdg},Sog,Cog,Lat,Lon\n" + "\n".join(rows) + "\n")
    return p


@pytest.mark.parametrize(
    "hdg", ["HdgTrue", "Hdg_true", "TrueHdg", "HDT", "Heading", "Hdg (True)", "Hdg (°T)"]
)
def test_an_expedition_heading_under_another_true_name_is_read(tmp_path: Path, hdg: str) -> None:
    """A re-export's name for Expedition's true heading is its heading, not a table
    without one (the import went on with the speed alone, and calibration against
    GNSS then found no heading)."""
    rep = import_csv(_expedition(tmp_path, hdg), tmp_path / "o.cap")
    assert rep.preset == "expedition" and rep.heading_ref == "true"
    assert "no_heading_column" not in rep.notes
    vhw = _vhw(tmp_path / "o.cap")
    assert [v.heading_true_deg for v in vhw] == [90.0, 91.0, 92.0, 93.0, 94.0]


@pytest.mark.parametrize("hdg", ["Hdg (°M)", "HDG_mag", "Hdg [degM]", "Heading (mag)"])
def test_a_heading_named_magnetic_is_read_as_magnetic(tmp_path: Path, hdg: str) -> None:
    """A heading whose name says magnetic is read as magnetic in a preset of true
    headings (not left out, and never taken as true): the model's variation at the
    fixes."""
    rep = import_csv(_expedition(tmp_path, hdg), tmp_path / "o.cap")
    assert rep.heading_ref == "magnetic" and rep.variation == "model"
    vhw = _vhw(tmp_path / "o.cap")
    assert len(vhw) == 5
    assert all(v.heading_true_deg is None and v.heading_mag_deg is not None for v in vhw)


def test_the_loggers_heading_named_with_its_units_keeps_its_preset(tmp_path: Path) -> None:
    """The race logger's TSV with its units in the names (``Boatspeed (kn)``,
    ``Heading (°M)``) is still the logger's (its GNSS columns read, its heading
    magnetic): a unit it did not know sent it to the generic preset, without a heading
    and without the ``Ext_SOG`` fixes. ``Heading (°T)`` there is true."""
    for unit, ref in (("°M", "magnetic"), ("°T", "true")):
        p = tmp_path / "log.tsv"
        head = f"Date\tTime\tBoatspeed (kn)\tHeading ({unit})\tExt_SOG\tExt_COG"
        rows = [f"08/07/17\t12:39:0{i}\t5.1\t309\t4.1\t312" for i in range(5)]
        p.write_text(head + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
        rep = import_csv(p, tmp_path / "o.cap", utc_offset_h=2.0)
        assert rep.preset == "logger-tsv" and rep.heading_ref == ref
        assert rep.sentences.get("RMC") == 1 and rep.sentences.get("VHW") == 1


@pytest.mark.parametrize(
    ("lat", "lon"),
    [
        ("45°40.8145'N", "13°41.0614'E"),
        ("N 45° 40.8145'", "E 013° 41.0614'"),
        ("45 40.8145 N", "013 41.0614 E"),
        ("45°40'48.87\"N", "13°41'03.684\"E"),
    ],
)
def test_positions_in_degrees_and_minutes_are_read(tmp_path: Path, lat: str, lon: str) -> None:
    """The logger's positions written in degrees and minutes with their signs (another
    firmware's, a spreadsheet's): each a position, so the magnetic heading has the
    model's variation (the cells were not numbers, and calibration found no position
    for the model)."""
    p = tmp_path / "log.tsv"
    head = "Date\tTime\tBoatspeed\tHeading\tExt_SOG\tExt_COG\tLatitudine\tLongitudine"
    rows = [f"08/07/17\t12:39:0{i}\t5.{i}\t309\t4.{i}\t312\t{lat}\t{lon}" for i in range(3)]
    p.write_text(head + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    rep = import_csv(p, tmp_path / "o.cap", utc_offset_h=2.0)
    assert rep.cells == {} and rep.variation == "model"
    dec = make_decoder("nmea0183", "nmea")
    fixes = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
    rmc = [x for x in fixes if isinstance(x, Rmc)]
    assert len(rmc) == 3
    assert all(x.lat_deg == pytest.approx(45.680242, abs=2e-6) for x in rmc)
    assert all(x.lon_deg == pytest.approx(13.684357, abs=2e-6) for x in rmc)


@pytest.mark.parametrize("cell", ["45°40.8145'", "45°70.1'N", "45°40.1'E"])
def test_a_degrees_and_minutes_cell_without_its_hemisphere_or_beyond_is_no_position(
    cell: str,
) -> None:
    """Without a hemisphere letter, with one of the other axis, or 60 minutes or more:
    not a position (counted), never a guess."""
    rep = ImportReport([], "", "")
    assert cell_value(cell, Col("lat", 0, 1.0), rep) is None
    assert rep.cells == {"lat: not_a_number": 1}


def test_a_day_first_date_with_dashes_and_a_time_named_utc(tmp_path: Path) -> None:
    """``08-07-2017`` (a day-first date with dashes, as Dutch and Danish locales write
    it) and a ``Time (UTC)`` column beside it: the rows' times as with ``08/07/17`` and
    ``Time`` (the dashes were no format told by itself, and ``(UTC)`` no unit)."""
    caps: list[list[tuple[float, bytes]]] = []
    for date_head, time_head, day in (
        ("date", "time", "08/07/17"),
        ("Date", "Time (UTC)", "08-07-2017"),
        ("Date [UTC]", "Time [GMT]", "08-07-17"),
    ):
        p = tmp_path / f"{len(caps)}.csv"
        rows = [f"{day},12:39:0{i},5.{i},30{i},5.{i},31{i}" for i in range(4)]
        p.write_text(f"{date_head},{time_head},stw,hdg,sog,cog\n" + "\n".join(rows) + "\n")
        cap = tmp_path / f"{len(caps)}.cap"
        rep = import_csv(p, cap)
        assert rep.preset == "generic" and rep.sentences == {"RMC": 4, "VHW": 4}
        caps.append([(r.t, r.data) for r in CaptureReader(cap)])
    assert caps[0][0][0] == datetime(2017, 7, 8, 12, 39, tzinfo=UTC).timestamp()
    assert caps[1] == caps[0] and caps[2] == caps[0]


@pytest.mark.parametrize("missing", ["", "NaN", "nan", "N/A", "NULL", "None", "-"])
def test_a_missing_value_written_as_a_word_is_an_empty_cell(tmp_path: Path, missing: str) -> None:
    """A pandas export's ``NaN``, a spreadsheet's ``N/A``, a database's ``NULL``: the
    cell is empty (its column's last value carried), not a bad cell in the report."""
    p = tmp_path / "log.csv"
    rows = [
        f"2024-07-18T11:14:5{i}Z,7.{i},{missing if i % 2 else '313'},8.{i},334" for i in range(4)
    ]
    p.write_text("time,speed,hdg,sog,cog\n" + "\n".join(rows) + "\n")
    rep = import_csv(p, tmp_path / "o.cap")
    assert rep.cells == {} and rep.sentences == {"RMC": 4, "VHW": 4}
    assert [v.heading_true_deg for v in _vhw(tmp_path / "o.cap")] == [313.0] * 4


def test_an_export_without_sog_or_cog_says_so(tmp_path: Path) -> None:
    """An Expedition export with its positions but without ``Sog``/``Cog``: no RMC, and
    the report says why (it said nothing, and calibration against GNSS then found no
    fix); with both columns, no such note."""
    p = tmp_path / "log.csv"
    rows = [f"{OLE_2005 + i * SEC:.8f},5.0,{90 + i},39.4,-0.3" for i in range(3)]
    p.write_text("Utc,Bsp,Hdg,Lat,Lon\n" + "\n".join(rows) + "\n")
    rep = import_csv(p, tmp_path / "o.cap")
    assert rep.notes["no_sog_cog_column"] == 1 and "RMC" not in rep.sentences
    rep = import_csv(_expedition(tmp_path, "Hdg"), tmp_path / "o.cap")
    assert "no_sog_cog_column" not in rep.notes and rep.sentences["RMC"] >= 1


def test_two_logs_on_one_port_are_noted(tmp_path: Path) -> None:
    """VHW from two talkers, each a share of the speeds (a second log on the
    multiplexer): the import keeps both and notes it; a few sentences under another
    talker (a line error in its address) are not noted."""
    t0 = datetime(2026, 5, 6, 10, tzinfo=UTC)
    lines = []
    for k in range(40):
        lines += [encode_rmc(t0 + timedelta(seconds=k), 5.0, 90.0), encode_vhw(4.8, talker="II")]
        if k % 2:
            lines.append(encode_vhw(5.5, talker="VW"))
    src = tmp_path / "two.nmea"
    src.write_text("\n".join(lines) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    # both kept: 40 + 20, less the two after the last fix (untimed)
    assert rep.notes["water_talkers II+VW"] == 1 and rep.sentences["VHW"] == 58
    one = [x for x in lines if "VWVHW" not in x]
    one[5] = encode_vhw(4.8, talker="GP")
    src.write_text("\n".join(one) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    assert not any(k.startswith("water_talkers") for k in rep.notes)
