"""``emlogd import`` of a CSV whose row under the header gives the columns' units
(Expedition's and several loggers' second header line). Synthetic files only."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw
from drivers.records import KNOT_MPS
from emlogd.offline.importer import ImportFormatError, import_csv

OLE = 38516.5
"""2005-06-13 12:00 UTC as an OLE date."""


def _rows(n: int = 4) -> list[str]:
    return [
        f"{OLE + i / 86_400:.6f},2.0,{math.radians(90 + i):.5f},{7.2 + i / 10:.1f},95"
        for i in range(n)
    ]


def _write(tmp_path: Path, units: str, header: str = "Utc,Bsp,Hdg,Sog,Cog") -> Path:
    src = tmp_path / "log.csv"
    src.write_text("\n".join([header, units, *_rows()]) + "\n")
    return src


def _records(cap: Path) -> list[object]:
    dec = make_decoder("nmea0183", "nmea")
    return [x for r in CaptureReader(cap) for x in dec.feed(r.data)]


def test_a_units_row_sets_the_columns_units(tmp_path: Path) -> None:
    """``days,m/s,rad,km/h,deg`` under the header: the speed through the water read in
    m/s, the heading in radians, the ground speed in km/h; the row is no data row
    (nothing skipped) and is noted."""
    src = _write(tmp_path, "days,m/s,rad,km/h,deg")
    rep = import_csv(src, tmp_path / "o.cap")
    assert rep.notes["units_row"] == 1 and rep.skipped == {} and rep.cells == {}
    assert rep.lines == 4 and rep.sentences == {"VHW": 4, "RMC": 4}
    recs = _records(tmp_path / "o.cap")
    vhw = [x for x in recs if isinstance(x, Vhw)]
    rmc = [x for x in recs if isinstance(x, Rmc)]
    assert vhw[0].stw_knots == pytest.approx(2.0 / KNOT_MPS, abs=0.01)
    assert [v.heading_true_deg for v in vhw] == pytest.approx([90.0, 91.0, 92.0, 93.0], abs=0.05)
    assert rmc[0].sog_mps == pytest.approx(2.0, abs=0.01) and rmc[0].cog_true_deg == 95.0


def test_knots_in_the_units_row_and_empty_cells_keep_the_default(tmp_path: Path) -> None:
    """``kt`` (and empty cells) leave a speed in knots, as without the row."""
    src = tmp_path / "log.csv"
    rows = [f"{OLE + i / 86_400:.6f},3.2,90,5.0,95" for i in range(3)]
    src.write_text("\n".join(["Utc,Bsp,Hdg,Sog,Cog", ",kt,,,", *rows]) + "\n")
    rep = import_csv(src, tmp_path / "o.cap")
    assert rep.notes["units_row"] == 1 and rep.lines == 3
    vhw = [x for x in _records(tmp_path / "o.cap") if isinstance(x, Vhw)]
    assert vhw[0].stw_knots == pytest.approx(3.2)


def test_a_magnetic_degree_in_the_units_row_makes_the_heading_magnetic(tmp_path: Path) -> None:
    """``degM`` under a generic table's heading: the heading is read as magnetic (the
    preset would take it as true), unless ``--heading-ref`` says otherwise."""
    src = tmp_path / "log.csv"
    rows = [f"2024-07-18T11:14:5{i}Z,5.0,{100 + i},5.2,102" for i in range(3)]
    src.write_text("\n".join(["time,stw,hdg,sog,cog", ",kn,degM,kn,degT", *rows]) + "\n")
    rep = import_csv(src, tmp_path / "o.cap", variation_deg=2.0)
    assert rep.heading_ref == "magnetic"
    vhw = [x for x in _records(tmp_path / "o.cap") if isinstance(x, Vhw)]
    assert vhw[0].heading_mag_deg == 100.0 and vhw[0].heading_true_deg is None
    again = import_csv(src, tmp_path / "p.cap", heading_ref="true")
    assert again.heading_ref == "true"


@pytest.mark.parametrize(
    ("units", "column", "unit"),
    [
        ("days,furlongs,deg,kt,deg", "'Bsp' (stw)", "'furlongs'"),
        ("days,kt,grad,kt,deg", "'Hdg' (heading)", "'grad'"),
        ("days,kt,deg,deg,deg", "'Sog' (sog)", "'deg'"),
        ("days,kt,deg,kt,m/s", "'Cog' (cog)", "'m/s'"),
    ],
)
def test_an_unknown_unit_stops_the_import_naming_the_column(
    tmp_path: Path, units: str, column: str, unit: str
) -> None:
    """A unit not known for the column's kind (a speed's, an angle's): the import stops
    with an error naming the column, its key and the unit, and writes nothing."""
    src = _write(tmp_path, units)
    with pytest.raises(
        ImportFormatError, match=re.escape(f"column {column}") + f".*unit {unit}"
    ) as err:
        import_csv(src, tmp_path / "o.cap")
    assert "known:" in str(err.value)
    assert not (tmp_path / "o.cap").exists()


def test_a_units_row_contradicting_a_unit_in_the_name_is_an_error(tmp_path: Path) -> None:
    """``Bsp (kn)`` over ``m/s``: which one holds is not known; the error names both."""
    src = _write(tmp_path, "days,m/s,deg,kt,deg", header="Utc,Bsp (kn),Hdg,Sog,Cog")
    with pytest.raises(ImportFormatError, match=r"'Bsp \(kn\)'.*'m/s'.*'kn'"):
        import_csv(src, tmp_path / "o.cap")


@pytest.mark.parametrize(
    "first", [f"{OLE - 1e-5:.6f},-,-,-,-", f"{OLE - 1e-5:.6f},3.1,N/A,,", "start,n/a,n/a,n/a,"]
)
def test_a_first_data_row_is_not_taken_for_units(tmp_path: Path, first: str) -> None:
    """A first row with a time, and numbers or dashes for values not yet known, is data;
    so is a row of text with no unit known in it: no units row, every row read."""
    src = tmp_path / "log.csv"
    rows = [first, *_rows(3)]
    src.write_text("\n".join(["Utc,Bsp,Hdg,Sog,Cog", *rows]) + "\n")
    rep = import_csv(src, tmp_path / "o.cap")
    assert rep.notes["units_row"] == 0 and rep.lines == 4
