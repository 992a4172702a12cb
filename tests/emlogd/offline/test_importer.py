"""``emlogd import``: CSV exports through a column map, the command, real logs (NMEA
logs timed by their fixes are tests/emlogd/offline/test_importnmea.py's)."""

from __future__ import annotations

import json
import math
import os
from datetime import UTC, date, datetime
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import make_decoder
from drivers.framing import with_checksum
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vdr, Vhw
from drivers.records import KNOT_MPS
from emlogd.cli import main
from emlogd.offline.importer import (
    EXPEDITION,
    ImportFormatError,
    import_csv,
    parse_map,
)
from tests.emlogd.offline.test_importnmea import IRENE
from tests.jumping import ROOT, run_twice
from tests.once import Imported

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "real"


def _csv(tmp_path: Path, rows: list[str], header: str = "Utc,Bsp,Hdg,Sog,Cog,iSet,iDrift") -> Path:
    p = tmp_path / "log.csv"
    p.write_text(header + "\n" + "\n".join(rows) + "\n")
    return p


OLE_2005 = 38516.5  # 2005-06-13 12:00 UTC


class TestCsv:
    """CSV exports: a column map, sparse rows carried forward, each row as VHW/RMC/VDR."""

    def test_expedition_rows(self, tmp_path: Path) -> None:
        """Expedition's columns give RMC, VHW with the true heading and VDR at the row
        times; an empty cell is no update, and a row with nothing new gives nothing."""
        sec = 1.0 / 86400.0
        src = _csv(
            tmp_path,
            [
                f"{OLE_2005},3.0,90.0,3.2,95.0,199.6,0.074",
                f"{OLE_2005 + sec},3.1,,3.3,,,",  # sparse: Hdg, Cog, iSet, iDrift as they were
                f"{OLE_2005 + 2 * sec},,,,,,",  # nothing written: no sample
            ],
        )
        mapping = {k: v for k, v in EXPEDITION.items() if k not in ("lat", "lon")}
        rep = import_csv(src, tmp_path / "o.cap", mapping)
        assert rep.lines == 3 and rep.sentences == {"VHW": 2, "RMC": 2, "VDR": 1}
        assert rep.skipped == {"no_new_value": 1}
        dec = make_decoder("nmea0183", "nmea")
        recs = [(r.t, x) for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        t0 = datetime(2005, 6, 13, 12, tzinfo=UTC).timestamp()
        assert recs[0][0] == pytest.approx(t0, abs=1e-3)
        assert isinstance(recs[0][1], Rmc)  # the fix first in its row
        vhw = [x for _, x in recs if isinstance(x, Vhw)]
        assert [v.stw_mps for v in vhw] == pytest.approx(
            [3.0 * KNOT_MPS, 3.1 * KNOT_MPS], abs=0.003
        )
        assert all(v.heading_true_deg == 90.0 and v.heading_mag_deg is None for v in vhw)
        rmc = [x for _, x in recs if isinstance(x, Rmc)]
        assert rmc[1].cog_true_deg == 95.0
        assert rmc[1].sog_mps == pytest.approx(3.3 * KNOT_MPS, abs=0.003)
        (vdr,) = [x for _, x in recs if isinstance(x, Vdr)]
        assert vdr.set_true_deg == pytest.approx(199.6)
        assert vdr.drift_mps == pytest.approx(0.074 * KNOT_MPS, abs=0.003)

    def test_a_carried_forward_cell_is_not_a_sample(self, tmp_path: Path) -> None:
        """Cells written equal to the previous row are the export carrying the value
        forward: no new fix, no new current; the repeats are counted as evidence."""
        sec = 1.0 / 86400.0
        rows = [
            f"{OLE_2005},3.00,90.0,3.2,95.0,199.6,0.074",
            f"{OLE_2005 + sec},3.01,90.0,3.2,95.0,199.6,0.074",  # only Bsp is new
            f"{OLE_2005 + 2 * sec},3.02,90.0,3.4,95.0,199.6,0.074",  # Bsp and Sog new
            f"{OLE_2005 + 3 * sec},3.02,90.0,3.4,95.0,199.6,0.074",  # all repeats
        ]
        rep = import_csv(_csv(tmp_path, rows), tmp_path / "o.cap", dict(EXPEDITION))
        assert rep.sentences == {"VHW": 3, "RMC": 2, "VDR": 1}
        assert rep.notes == {"fix_repeat": 2, "current_repeat": 3, "water_repeat": 1}
        assert rep.skipped == {"no_new_value": 1}

    def test_a_repeat_a_full_period_later_is_a_sample(self, tmp_path: Path) -> None:
        """Rows every second, the fix updated every 2 s (carried forward between): a
        repeat 1 s after a sample is the carry, one 2 s after it (when the next update
        was due) is the instrument reading the same again."""
        t0 = 1_750_000_000
        sog = [3.0 + 0.1 * (k // 2) for k in range(30)]
        sog[20] = sog[21] = sog[19]  # the update due at k=20 brings the same value
        rows = [f"{t0 + k},5.0,{v:.1f},90" for k, v in enumerate(sog)]
        src = _csv(tmp_path, rows, header="T,S,SOG,COG")
        rep = import_csv(src, tmp_path / "o.cap", parse_map("time=T,stw=S,sog=SOG,cog=COG"))
        assert rep.sentences["RMC"] == 15
        assert rep.notes["fix_repeat_kept"] == 1 and rep.notes["fix_repeat"] == 15
        dec = make_decoder("nmea0183", "nmea")
        times = [r.t - t0 for r in CaptureReader(tmp_path / "o.cap")
                 for x in dec.feed(r.data) if isinstance(x, Rmc)]  # fmt: skip
        assert times == [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28]

    def test_carry_is_bounded(self, tmp_path: Path) -> None:
        """A group's other cell older than carry_s is not used: a heading alone, 30 s after
        the last speed, makes no VHW (counted as incomplete)."""
        t0 = 1_750_000_000
        rows = [f"{t0},2.0,10", f"{t0 + 5},,20", f"{t0 + 30},,30"]
        src = _csv(tmp_path, rows, header="T,S,H")
        rep = import_csv(src, tmp_path / "o.cap", parse_map("time=T,stw=S,heading=H"))
        assert rep.written == 2 and rep.skipped == {"incomplete": 1}
        dec = make_decoder("nmea0183", "nmea")
        vhw = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        assert [(v.stw_knots, v.heading_true_deg) for v in vhw] == [(2.0, 10.0), (2.0, 20.0)]  # type: ignore[union-attr]

    def test_units_magnetic_iso_and_bad_cells(self, tmp_path: Path) -> None:
        """[mps] columns, a magnetic heading, ISO times; bad cells and times are counted by
        column and reason, and the rest of the row is still used."""
        src = _csv(
            tmp_path,
            ["2026-01-01T00:00:00,2.5,10", "2026-01-01T00:00:01,x,10", "nope,2.0,10",
             "2026-01-01T00:00:02,-1.0,10", "2026-01-01T00:00:03,2.0,north"],
            header="When,Speed,Heading",
        )  # fmt: skip
        rep = import_csv(
            src,
            tmp_path / "o.cap",
            parse_map("time=When,stw=Speed[mps],heading=Heading"),
            time_format="iso",
            heading_ref="magnetic",
        )
        assert rep.skipped == {"bad_cell": 2, "bad_time": 1}
        assert rep.cells == {
            "stw: not_a_number": 1,
            "stw: out_of_range": 1,
            "heading: not_a_number": 1,
        }
        assert rep.sentences == {"VHW": 2} and rep.variation == "none"
        dec = make_decoder("nmea0183", "nmea")
        (first, *_) = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        assert isinstance(first, Vhw)
        assert first.stw_mps == pytest.approx(2.5, abs=0.003)
        assert first.heading_mag_deg == 10.0 and first.heading_true_deg is None

    def test_impossible_values_are_counted_never_a_crash(self, tmp_path: Path) -> None:
        """A 51 kn current, a 1e308 kn speed, an infinite course, a latitude of 95° and a
        year-1970 time are each counted, not written, and do not stop the import."""
        t0 = 1_750_000_000
        rows = [
            f"{t0},5.0,90,5.1,92,46.2,6.2,10,0.4",
            f"{t0 + 1},1e308,91,inf,93,95.0,6.2,20,51.0",
            f"{t0 + 2},5.2,92,5.2,94,46.2,6.3,30,0.5",
            "5,5.0,90,5.1,92,46.2,6.2,10,0.4",
        ]
        src = _csv(tmp_path, rows, header="T,S,H,SOG,COG,LAT,LON,SET,DRIFT")
        m = "time=T,stw=S,heading=H,sog=SOG,cog=COG,lat=LAT,lon=LON,set=SET,drift=DRIFT"
        rep = import_csv(src, tmp_path / "o.cap", parse_map(m))
        assert rep.cells == {
            "stw: out_of_range": 1,
            "sog: out_of_range": 1,
            "lat: out_of_range": 1,
            "drift: out_of_range": 1,
        }
        assert rep.skipped == {"time_out_of_range": 1}
        dec = make_decoder("nmea0183", "nmea")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        assert max(x.stw_knots or 0.0 for x in recs if isinstance(x, Vhw)) == 5.2
        assert all(x.drift_mps < 1.0 for x in recs if isinstance(x, Vdr))  # type: ignore[operator]

    def test_expedition_variants_choose_by_header(self, tmp_path: Path) -> None:
        """Without a preset or map the header chooses Expedition, in its variants: the
        current as Set/Drift, or no current at all (then no VDR)."""
        row = f"{OLE_2005},3.0,90.0,3.2,95.0,199.6,0.074"
        a = _csv(tmp_path, [row], header="Utc,Bsp,Hdg,Sog,Cog,Set,Drift")
        rep = import_csv(a, tmp_path / "a.cap")
        assert rep.preset == "expedition" and rep.sentences == {"VHW": 1, "RMC": 1, "VDR": 1}
        b = tmp_path / "b.csv"
        b.write_text(f"Utc,Bsp,Hdg,Awa\n{OLE_2005},3.0,90.0,-30\n")
        rep = import_csv(b, tmp_path / "b.cap")
        assert rep.preset == "expedition" and rep.sentences == {"VHW": 1}

    def test_semicolons_decimal_commas_and_any_case(self, tmp_path: Path) -> None:
        """A European spreadsheet's Expedition export: semicolons, decimal commas, the
        column names in capitals."""
        src = tmp_path / "log.csv"
        ole = str(OLE_2005).replace(".", ",")
        src.write_text(f"UTC;BSP;HDG;SOG;COG\n{ole};3,25;90,5;3,4;95,0\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "expedition" and rep.cells == {}
        assert rep.t_start == datetime(2005, 6, 13, 12, tzinfo=UTC).timestamp()
        dec = make_decoder("nmea0183", "nmea")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        (vhw,) = [x for x in recs if isinstance(x, Vhw)]
        assert vhw.stw_knots == 3.25 and vhw.heading_true_deg == 90.5

    def test_logger_tsv_banner_date_time_local_and_ddmm(self, tmp_path: Path) -> None:
        """A tab-separated logger export: a banner before the header, Date and Time
        columns in local time, ddmm.mmmmN positions, a magnetic heading (its variation
        left to the model at the fixes' positions)."""
        src = tmp_path / "log.tsv"
        header = "Date\tTime\tBoatspeed\tHeading\tExt_SOG\tExt_COG\tLatitudine\tLongitudine"
        src.write_text(
            "------ log1Hz.log ------\n"
            + header
            + "\n08/07/17\t12:39:06\t5.10\t309\t4.10\t312\t4540.8145N\t01341.0614E\t\n"
            + "08/07/17\t12:39:07\t4.70\t299\t4.20\t312\t4540.8154S\t01341.0602W\t\n"
        )
        rep = import_csv(src, tmp_path / "o.cap", utc_offset_h=2.0)
        assert rep.preset == "logger-tsv" and rep.notes["banner_lines"] == 1
        assert rep.heading_ref == "magnetic" and rep.variation == "model"
        assert rep.t_start == datetime(2017, 7, 8, 10, 39, 6, tzinfo=UTC).timestamp()
        dec = make_decoder("nmea0183", "nmea")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        rmc = [x for x in recs if isinstance(x, Rmc)]
        assert rmc[0].lat_deg == pytest.approx(45 + 40.8145 / 60, abs=1e-5)
        assert rmc[0].lon_deg == pytest.approx(13 + 41.0614 / 60, abs=1e-5)
        assert rmc[1].lat_deg < 0 and rmc[1].lon_deg < 0  # type: ignore[operator]
        assert [x.heading_mag_deg for x in recs if isinstance(x, Vhw)] == [309.0, 299.0]
        no_offset = import_csv(src, tmp_path / "p.cap")
        assert no_offset.notes["local_time_taken_as_utc"] == 1

    def test_any_delimiter_separate_date_and_a_pattern(self, tmp_path: Path) -> None:
        """A semicolon export mapped by hand: date and time columns joined and read with a
        strptime pattern; --variation goes into the RMC for the magnetic heading."""
        src = tmp_path / "log.csv"
        src.write_text(
            "day;clock;stw;hdg;sog;cog\n2024-07-18;10:00:00;5.0;100;5.2;110\n"
            "2024-07-18;10:00:01;5.1;101;5.3;111\n"
        )
        rep = import_csv(
            src,
            tmp_path / "o.cap",
            parse_map("date=day,time=clock,stw=stw,heading=hdg,sog=sog,cog=cog"),
            time_format="%Y-%m-%d %H:%M:%S",
            heading_ref="magnetic",
            variation_deg=-3.5,
        )
        assert rep.t_start == datetime(2024, 7, 18, 10, tzinfo=UTC).timestamp()
        assert rep.variation == "option" and rep.sentences == {"VHW": 2, "RMC": 2}
        dec = make_decoder("nmea0183", "nmea")
        rmc = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        assert [x.variation_deg for x in rmc if isinstance(x, Rmc)] == [-3.5, -3.5]

    @pytest.mark.parametrize(
        "day", ["08/07/17", "08/07/2017", "2017/07/08", "2017-07-08", "08.07.2017"]
    )
    @pytest.mark.parametrize("clock", ["12:39:06", "12:39:06.0"])
    def test_logger_tsv_dates_of_any_kind(self, tmp_path: Path, day: str, clock: str) -> None:
        """The logger's Date and Time in another firmware's or a spreadsheet's writing
        (the year in full, year first, dots, fractions of a second) are told by the first
        row, as any automatic time: the same instant."""
        src = tmp_path / "log.tsv"
        src.write_text(
            "Date\tTime\tBoatspeed\tHeading\tExt_SOG\tExt_COG\n"
            f"{day}\t{clock}\t5.10\t309\t4.10\t312\n"
        )
        rep = import_csv(src, tmp_path / "o.cap", utc_offset_h=2.0)
        assert rep.preset == "logger-tsv"
        assert rep.t_start == datetime(2017, 7, 8, 10, 39, 6, tzinfo=UTC).timestamp()

    @pytest.mark.parametrize(
        ("day", "clock"),
        [("13/06/2005", "12:00:01"), ("2005-06-13", "12:00:01"), ("", "2005-06-13T12:00:01")],
    )
    def test_a_plain_table_joins_its_date_to_a_time_of_day(
        self, tmp_path: Path, day: str, clock: str
    ) -> None:
        """A plain table with Date and Time columns: a time of day is joined to the date;
        a time cell that holds its own date is read alone."""
        src = tmp_path / "log.csv"
        src.write_text(f"Date,Time,Bsp,Hdg,Sog,Cog\n{day},{clock},3.2,90,3.4,95\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "generic"
        assert rep.t_start == datetime(2005, 6, 13, 12, 0, 1, tzinfo=UTC).timestamp()

    @pytest.mark.parametrize(
        ("bsp", "sog", "stw_mps", "sog_mps"),
        [
            ("Bsp (kn)", "Sog [m/s]", 3.2 * KNOT_MPS, 2.0),
            ("BSP [kts]", "SOG (km/h)", 3.2 * KNOT_MPS, 2.0 / 3.6),
            ("bsp_mps", "sog_kn", 3.2, 2.0 * KNOT_MPS),
            ("BSP KTS", "SOG M/S", 3.2 * KNOT_MPS, 2.0),
        ],
    )
    def test_a_unit_after_a_column_name_is_the_columns(
        self, tmp_path: Path, bsp: str, sog: str, stw_mps: float, sog_mps: float
    ) -> None:
        """Column names with their unit after them match the preset's names, and a
        speed's unit is the column's (knots, m/s, km/h); an angle's is degrees."""
        src = tmp_path / "log.csv"
        src.write_text(f"Utc,{bsp},Hdg (deg),{sog},Cog (deg)\n{OLE_2005},3.2,90,2.0,95\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "expedition"
        dec = make_decoder("nmea0183", "nmea")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        (vhw,) = [x for x in recs if isinstance(x, Vhw)]
        (rmc,) = [x for x in recs if isinstance(x, Rmc)]
        assert vhw.stw_mps == pytest.approx(stw_mps, abs=0.003) and vhw.heading_true_deg == 90
        assert rmc.sog_mps == pytest.approx(sog_mps, abs=0.003) and rmc.cog_true_deg == 95

    def test_epoch_milliseconds_are_told(self, tmp_path: Path) -> None:
        """A JavaScript or Signal K export's epoch milliseconds: read as such."""
        src = tmp_path / "log.csv"
        t0 = datetime(2024, 7, 18, 11, 14, 55, 250_000, tzinfo=UTC).timestamp()
        ms = round(t0 * 1000)
        src.write_text(f"timestamp,stw,hdg\n{ms},5.0,90\n{ms + 1000},5.1,91\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.t_start == pytest.approx(t0) and rep.t_end - rep.t_start == 1.0

    def test_a_time_it_cannot_tell_is_quoted_with_the_option(self, tmp_path: Path) -> None:
        """Times of minutes alone are no format told by itself: the error quotes the first
        cell and names --time-format, and the pattern given reads them."""
        src = tmp_path / "log.csv"
        src.write_text("Utc,Bsp,Hdg\n13/06/2005 12:00,3.2,90\n13/06/2005 12:01,3.3,91\n")
        with pytest.raises(ImportFormatError, match=r"'13/06/2005 12:00'.*--time-format"):
            import_csv(src, tmp_path / "o.cap")
        rep = import_csv(src, tmp_path / "p.cap", time_format="%d/%m/%Y %H:%M")
        assert rep.t_end - rep.t_start == 60.0

    def test_a_time_of_day_without_a_date_takes_the_files(self, tmp_path: Path) -> None:
        """Times of day alone and no date column: the date in the file's name, else the
        day the file was last written (noted); without either (a file time before
        1980), the error says a time needs its date and names --map date= (not a time
        format, which would not help)."""
        text = "Time,Speed (kts),Heading\n12:00:00,3.1,100\n12:00:01,3.2,101\n"
        src = tmp_path / "log.csv"
        src.write_text(text)
        written = datetime(2024, 7, 18, 15, 0, tzinfo=UTC).timestamp()
        os.utime(src, (written, written))
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.t_start == datetime(2024, 7, 18, 12, tzinfo=UTC).timestamp()
        assert rep.notes["date_from_file_time"] == 1
        named = tmp_path / "log_20240719.csv"
        named.write_text(text)
        rep = import_csv(named, tmp_path / "o.cap")
        assert rep.t_start == datetime(2024, 7, 19, 12, tzinfo=UTC).timestamp()
        assert rep.notes["date_from_file_name"] == 1
        os.utime(src, (0, 0))
        with pytest.raises(ImportFormatError, match=r"time of day alone.*'12:00:00'.*date="):
            import_csv(src, tmp_path / "o.cap")

    def test_times_of_day_take_the_given_date_past_midnight(self, tmp_path: Path) -> None:
        """Times of day alone with --date: that day's, the next day's after midnight."""
        src = tmp_path / "log.csv"
        src.write_text("Time,Speed (kts),Heading\n23:59:59,3.1,100\n00:00:01,3.2,101\n")
        rep = import_csv(src, tmp_path / "o.cap", day=date(2024, 7, 18))
        t0 = datetime(2024, 7, 18, 23, 59, 59, tzinfo=UTC).timestamp()
        assert (rep.t_start, rep.t_end) == (t0, t0 + 2.0)

    @pytest.mark.parametrize(("error", "flagged"), [(0.0, False), (20.0, True)])
    def test_the_heading_is_checked_against_the_course(
        self, tmp_path: Path, error: float, flagged: bool
    ) -> None:
        """The import runs the heading-against-course check: a heading 20° off the course
        (a magnetic one taken as true where the variation is 20°) is flagged, with the
        offset; a good one is not."""
        t0 = 1_750_000_000
        rows = []
        for k in range(900):
            psi = (k // 60) * 135.0 % 360.0
            sog = 5.0 + 0.3 * math.sin(k / 7.0)  # a new fix every row
            rows.append(f"{t0 + k},5.0,{(psi - error) % 360.0:.1f},{sog:.2f},{psi:.1f}")
        src = _csv(tmp_path, rows, header="T,S,H,SOG,COG")
        rep = import_csv(
            src, tmp_path / "o.cap", parse_map("time=T,stw=S,heading=H,sog=SOG,cog=COG")
        )
        check = rep.heading_check
        assert check is not None and check["flagged"] is flagged
        assert check["offset_deg"] == pytest.approx(error, abs=0.5)

    def test_a_failed_import_leaves_no_capture(self, tmp_path: Path) -> None:
        """An import that finds nothing to write leaves neither the capture nor a part file."""
        src = _csv(tmp_path, [",3.0,90,3,90,0,0"])
        with pytest.raises(ImportFormatError, match="no_time 1"):
            import_csv(src, tmp_path / "o.cap", dict(EXPEDITION))
        assert [p.name for p in tmp_path.iterdir()] == [src.name]

    def test_missing_column_or_key(self, tmp_path: Path) -> None:
        """A mapped column not in the header, or a map without stw, is refused."""
        src = _csv(tmp_path, [f"{OLE_2005},3.0,90,3,90,0,0"])
        with pytest.raises(ImportFormatError, match="'Speed' for stw"):
            import_csv(src, tmp_path / "o.cap", {"time": "Utc", "stw": "Speed"})
        with pytest.raises(ImportFormatError, match="stw="):
            import_csv(src, tmp_path / "o.cap", {"time": "Utc"})


class TestCli:
    """The ``import`` command: a summary or JSON report, one-line errors."""

    def test_nmea_json(self, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
        """--json prints the report with the counts by reason."""
        src = tmp_path / "irene.nmea"
        src.write_text(IRENE)
        out = tmp_path / "o.cap.gz"
        assert main(["import", str(src), "--format", "nmea", "--out", str(out), "--json"]) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["written"] == 10
        assert doc["skipped"] == {"before_first_fix": 3, "after_last_fix": 1}
        assert doc["span_s"] == pytest.approx(2.0) and out.exists()

    def test_the_capture_is_a_function_of_the_log(self, tmp_path: Path) -> None:
        """A receiver's log (4950 sentences timed by its fixes) imported in two processes,
        one with every clock jumping and another hash seed, gives the same capture byte
        for byte and the same report."""
        log = ROOT / "tests" / "data" / "nmea" / "gpsd_bundg_zeus_9.log"
        out = tmp_path / "o.cap"
        args = ["import", str(log), "--format", "nmea", "--out", str(out), "--json"]
        runs = [(doc, out.read_bytes()) for doc in run_twice(args)]
        assert json.loads(runs[0][0])["written"] > 4000
        assert runs[1] == runs[0]

    def test_csv_without_a_known_header(
        self, tmp_path: Path, capsys: pytest.CaptureFixture[str]
    ) -> None:
        """csv without --map takes the preset the header names; a header no preset knows
        is one line naming what each preset lacks; csv options are refused for nmea."""
        src = _csv(tmp_path, [f"{OLE_2005},3.0,90,3,90,0,0"])
        out = str(tmp_path / "o.cap")
        assert main(["import", str(src), "--format", "csv", "--out", out]) == 0
        capsys.readouterr()
        other = _csv(tmp_path, ["1,2"], header="A,B")
        assert main(["import", str(other), "--format", "csv", "--out", out]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "expedition lacks 'Utc' for time" in err
        assert main(["import", str(src), "--format", "nmea", "--out", out, "--map", "time=X"]) == 2
        assert main(["import", str(src), "--format", "nmea", "--out", out, "--variation", "2"]) == 2

    def test_no_time_is_one_line_error(
        self, tmp_path: Path, capsys: pytest.CaptureFixture[str]
    ) -> None:
        """A log without any fix exits 1 with one line that says what is missing."""
        src = tmp_path / "x.nmea"
        src.write_text(with_checksum("VWVHW,,T,,M,1.0,N,,K") + "\n")
        assert main(["import", str(src), "--format", "nmea", "--out", str(tmp_path / "o")]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "RMC or ZDA" in err


@pytest.mark.skipif(not REAL.is_dir(), reason="the shared real recordings are not here")
class TestRealLogs:
    """The real recordings import whole, every skipped line accounted for."""

    def test_irene(self, imported: Imported) -> None:
        """Irene 06-27: all but the 9 lines before the first RMC fix and the 9 after the
        last are written, none timed past the last fix."""
        rep, _ = imported(REAL / "irene-2014-06-27-leman.nmea")
        assert rep.written + sum(rep.skipped.values()) == rep.lines
        assert rep.skipped == {"before_first_fix": 9, "after_last_fix": 9}
        assert abs(rep.sentences["RMC"] - rep.sentences["VHW"]) <= 1 and rep.sentences["VHW"] > 7000
        assert 130 * 60 < rep.t_end - rep.t_start < 140 * 60

    def test_valencia(self, tmp_path: Path) -> None:
        """Expedition's Valencia log, preset chosen by its header: the speed (to 0.001 kn)
        is new in nearly every row; Expedition's current, repeated in half the rows at
        its own slower rate, is written only when new or a period later."""
        rep = import_csv(REAL / "expedition-valencia.csv", tmp_path / "v.cap.gz")
        assert rep.preset == "expedition" and rep.cells == {}
        assert rep.sentences["VHW"] > 0.99 * rep.lines
        assert rep.notes["current_repeat"] > 0.3 * rep.lines
        assert rep.sentences["VDR"] < 0.7 * rep.lines
        assert math.isclose(rep.t_end - rep.t_start, 204 * 60, rel_tol=0.01)

    def test_logger_tsv(self, tmp_path: Path) -> None:
        """The Trieste race logger's TSV: found by its header past the banner, magnetic
        heading, positions in ddmm.mmmm; the speed repeats in most rows and only its
        updates are written."""
        rep = import_csv(REAL / "astra-race-2017-07-08-trieste.tsv", tmp_path / "a.cap.gz")
        assert rep.preset == "logger-tsv" and rep.notes["banner_lines"] == 1
        assert rep.heading_ref == "magnetic" and rep.variation == "model"
        assert rep.cells == {} and 225 * 60 < rep.t_end - rep.t_start < 235 * 60
        assert rep.sentences["VHW"] < 0.5 * rep.lines
        dec = make_decoder("nmea0183", "nmea", errors="skip")
        rmc = next(
            x for r in CaptureReader(tmp_path / "a.cap.gz") for x in dec.feed(r.data)
            if isinstance(x, Rmc)
        )  # fmt: skip
        assert rmc.lat_deg == pytest.approx(45.68, abs=0.02)
        assert rmc.lon_deg == pytest.approx(13.68, abs=0.05)

    def test_valencia_calibrates_against_gnss(self, tmp_path: Path) -> None:
        """Imported, then calibrated against GNSS in the water frame: the log's scale is a
        few percent (the instrument was calibrated), the current a few cm/s, and the
        corrected speed is better than raw."""
        from emlogd.offline.jobs import calibrate, load_captures
        from emlogd.pipeline.settings import UutSettings

        cap = tmp_path / "v.cap.gz"
        import_csv(REAL / "expedition-valencia.csv", cap, dict(EXPEDITION))
        s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
        res = calibrate(load_captures([str(cap)], s), s, "ls", lag=0.0)
        assert res.average_s == 20.0 and res.identifiable
        assert 0.0 < res.params.m < 0.08
        assert res.current_mps is not None and math.hypot(*res.current_mps) < 0.15
        assert res.rmse_cal < 0.9 * res.rmse_raw

    def test_irene_calibrated_log_stays_calibrated(self, imported: Imported) -> None:
        """Irene 06-27 (a lake, a log already calibrated): the GNSS fit finds a scale
        within 5 % (the real-recording suite's tolerance) and a corrected speed no worse than raw — the noisy GNSS reference
        does not shrink the scale (a per-sample fit says −8 %)."""
        from emlogd.offline.jobs import calibrate, load_captures
        from emlogd.pipeline.settings import UutSettings

        _, cap = imported(REAL / "irene-2014-06-27-leman.nmea")
        s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
        res = calibrate(load_captures([str(cap)], s), s, "ls", lag=0.0)
        assert abs(res.params.m) < 0.05
        assert res.rmse_cal <= res.rmse_raw


_CELLS = st.one_of(
    st.sampled_from(["", "nan", "inf", "-inf", "1e308", "-1e308", "-", "4540.8145N", "91S"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet=st.characters(blacklist_categories=["Cs"]), max_size=8),
)


@given(st.lists(st.lists(_CELLS, min_size=0, max_size=10), min_size=1, max_size=12))
@settings(max_examples=60, deadline=None)
def test_any_cells_are_counted_never_a_crash(
    tmp_path_factory: pytest.TempPathFactory, rows: list[list[str]]
) -> None:
    """Whatever the cells of an Expedition-shaped export hold, the import writes a capture
    or says in one ImportFormatError why not; every row is accounted for."""
    import csv as csv_module

    d = tmp_path_factory.mktemp("fuzz")
    src = d / "log.csv"
    with open(src, "w", newline="", encoding="utf-8") as f:
        w = csv_module.writer(f)
        w.writerow(["Utc", "Bsp", "Hdg", "Sog", "Cog", "Lat", "Lon", "iSet", "iDrift", "Extra"])
        for k, row in enumerate(rows):
            w.writerow([f"{OLE_2005 + k / 86400.0}", *row])
    try:
        rep = import_csv(src, d / "o.cap")
    except ImportFormatError:
        assert not (d / "o.cap").exists()
        return
    assert rep.lines == len(rows) and rep.written > 0
    assert rep.lines >= sum(rep.skipped.values())
