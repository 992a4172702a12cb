"""``emlogd import`` of logs another boat or tool writes of the kinds the real recordings
are: the same rows under other heading names, units and cell forms read as the
recordings' own are."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Vhw
from emlogd.offline.importer import import_csv

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
