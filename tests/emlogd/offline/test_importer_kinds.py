"""``emlogd import`` on the kinds of log a held-out recording may be: NMEA written
without checksums, GGA times of day across midnight, Expedition's own sparse log with
FILETIME or OLE times. Synthetic, no shared files."""

from __future__ import annotations

import math
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw, encode_rmc, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline.importer import import_csv, import_nmea
from emlogd.offline.importnmea import DAY_ROLLOVER_S
from tests.nmea_encoders import encode_gga


def _decoded(cap: Path) -> list[tuple[float, object]]:
    dec = make_decoder("nmea0183", "nmea")
    return [(r.t, x) for r in CaptureReader(cap) for x in dec.feed(r.data)]


def _bare(line: str) -> str:
    return line[: line.rindex("*")]


T = datetime(2026, 5, 6, 10, 0, 0, tzinfo=UTC)


class TestChecksums:
    def test_a_log_without_checksums_is_read_with_them_added(self, tmp_path: Path) -> None:
        """A logger that writes no checksums: every well-formed sentence is taken, its
        checksum added and counted; what the capture holds decodes."""
        lines = [
            encode_rmc(T, 2.0, 90.0),
            encode_vhw(1.9),
            encode_rmc(T + timedelta(seconds=1), 2.0, 91.0),
        ]
        src = tmp_path / "log.nmea"
        src.write_text("\n".join(_bare(x) for x in lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 3 and rep.skipped == {}
        assert rep.notes["checksum_added"] == 3
        recs = [x for _, x in _decoded(tmp_path / "o.cap")]
        assert [type(x) for x in recs] == [Rmc, Vhw, Rmc]

    def test_in_a_log_with_checksums_a_line_without_is_cut(self, tmp_path: Path) -> None:
        """Where the log's sentences carry checksums, one without is a cut line: skipped
        and counted, not given a checksum."""
        t1 = T + timedelta(seconds=1)
        lines = [encode_rmc(T, 2.0, 90.0), encode_vhw(1.9), _bare(encode_vhw(1.0))[:12]]
        lines += [encode_rmc(t1, 2.0, 90.0)]
        src = tmp_path / "log.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.skipped == {"missing_checksum": 1} and rep.written == 3
        assert "checksum_added" not in rep.notes

    def test_text_without_an_address_is_no_sentence(self, tmp_path: Path) -> None:
        """A line without checksum and without a sentence's address is never taken."""
        src = tmp_path / "log.nmea"
        src.write_text(f"$hello world\n{_bare(encode_rmc(T, 1.0, 0.0))}\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.skipped == {"missing_checksum": 1} and rep.written == 1


class TestPrefixes:
    def test_a_receive_time_before_each_sentence_is_passed_over(self, tmp_path: Path) -> None:
        """A logger that writes its own time (or a tag) before each sentence: the
        sentence is read from its ``$``; the fixes time the log as without it."""
        t1 = T + timedelta(seconds=1)
        lines = [encode_rmc(T, 2.0, 90.0), encode_vhw(1.9), encode_rmc(t1, 2.0, 90.0)]
        src = tmp_path / "log.nmea"
        stamps = ["2026-05-06T10:00:00.120Z ", "1778061600.5;N;", "[nmea0] "]
        src.write_text("\n".join(p + x for p, x in zip(stamps, lines, strict=True)) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 3 and rep.notes["line_prefix"] == 3 and rep.skipped == {}
        assert [type(x) for _, x in _decoded(tmp_path / "o.cap")] == [Rmc, Vhw, Rmc]

    def test_a_receive_time_after_each_sentence_is_passed_over(self, tmp_path: Path) -> None:
        """A logger that writes its time after each sentence (a space, a comma or a tab
        after the checksum): the sentence is read to its checksum (it was refused as a
        log without a sentence with its checksum, and told to use --format nmea); a
        sentence whose checksum is wrong stays refused."""
        t1 = T + timedelta(seconds=1)
        lines = [encode_rmc(T, 2.0, 90.0), encode_vhw(1.9), encode_rmc(t1, 2.0, 90.0)]
        stamps = [" 2026-05-06T10:00:00.120Z", ",1778061600500", "\t10:00:01.2"]
        bad = encode_vhw(2.5)[:-2] + "00 2026-05-06T10:00:01.500Z"
        src = tmp_path / "log.nmea"
        rows = [x + p for x, p in zip(lines, stamps, strict=True)]
        src.write_text("\n".join([*rows[:2], bad, rows[2]]) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 3 and rep.notes["line_suffix"] == 3
        assert rep.skipped == {"checksum": 1}
        assert [type(x) for _, x in _decoded(tmp_path / "o.cap")] == [Rmc, Vhw, Rmc]

    def test_a_sentence_quoted_last_in_a_csv_row(self, tmp_path: Path) -> None:
        """OpenCPN's data log in CSV: the sentence is the row's last cell, quoted; the
        header rows are no sentences."""
        t1 = T + timedelta(seconds=1)
        lines = [encode_rmc(T, 2.0, 90.0), encode_vhw(1.9), encode_rmc(t1, 2.0, 90.0)]
        head = "# timestamp_format: EPOCH_MILLIS\nreceived_at,protocol,msg_type,source,raw_data\n"
        rows = [f'177806160{k}000,NMEA0183,{x[1:6]},ttyUSB0,"{x}"' for k, x in enumerate(lines)]
        src = tmp_path / "log.csv"
        src.write_text(head + "\n".join(rows) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 3 and rep.skipped == {"not_nmea": 2}
        assert [type(x) for _, x in _decoded(tmp_path / "o.cap")] == [Rmc, Vhw, Rmc]

    def test_text_with_a_dollar_is_no_sentence(self, tmp_path: Path) -> None:
        """A dollar amount in a text line starts no sentence."""
        src = tmp_path / "log.nmea"
        src.write_text(f"paid $12, thanks\n{encode_rmc(T, 1.0, 0.0)}\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.skipped == {"not_nmea": 1} and "line_prefix" not in rep.notes


class TestMidnight:
    def test_gga_times_of_day_roll_over_to_the_next_day(self, tmp_path: Path) -> None:
        """GGA fixes across midnight with the first day's --date: after 23:59:59 comes
        00:00:00 of the next day, not a time going back half a day."""
        t0 = datetime(2026, 3, 4, 23, 59, 58, tzinfo=UTC)
        lines = []
        for k in range(5):
            lines += [encode_gga(t0 + timedelta(seconds=k), 46.0, 6.0), encode_vhw(1.0)]
        src = tmp_path / "gga.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 3, 4))
        assert rep.notes == {} and rep.skipped == {"after_last_fix": 1}
        assert rep.t_end - rep.t_start == pytest.approx(4.0)
        assert rep.t_end == (t0 + timedelta(seconds=4)).timestamp()

    def test_a_small_step_back_is_no_rollover(self, tmp_path: Path) -> None:
        """A GGA a few seconds before the last fix is a fix going back (noted), not the
        next day's: only a step of DAY_ROLLOVER_S or more rolls over."""
        t0 = datetime(2026, 3, 4, 12, 0, 10, tzinfo=UTC)
        back = t0 - timedelta(seconds=DAY_ROLLOVER_S - 60.0)
        lines = [encode_gga(t0, 46.0, 6.0), encode_gga(back, 46.0, 6.0)]
        lines += [encode_gga(t0 + timedelta(seconds=1), 46.0, 6.0)]
        src = tmp_path / "gga.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 3, 4))
        assert rep.notes == {"fix_time_not_increasing": 1}
        assert rep.t_end == (t0 + timedelta(seconds=1)).timestamp()


def _settings_banner(lines: int) -> list[str]:
    """A logger's settings before its header: section rulers, ``NAME:<TAB>value`` lines,
    tables with tabs and commas."""
    out = ["------------ log1Hz20260506_1000 ------------", "------------ DAMPING ------------"]
    out += [f"CH{k}:\t0.{500 + k}" for k in range(lines // 2)]
    out += ["------------ TABLES ------------"]
    out += [
        f"POINT {k} - SPEED: {k}.0\t GAIN: 1.{k:03d}\tCURVE:\t0.0,0.0,0.0"
        for k in range(lines // 2)
    ]
    return [*out, "------------ LOG ------------"]


class TestLoggerFirmware:
    def test_other_names_a_long_banner_and_dashes(self, tmp_path: Path) -> None:
        """The race logger's other firmware: BS/HDG/SOG/COG/Lat/Lon/Set/Drift, a banner
        of settings longer than fifty lines, ``-`` while its current is unknown: the
        preset reads it, the dashes are no value (not bad cells)."""
        header = "Date\tTime\tTs\tBS\tAWA\tHDG\tSOG\tCOG\tLat\tLon\tSet\tDrift\tFreezeTide"
        rows = []
        for k in range(4):
            cur = "-\t-" if k < 2 else f"{80 + k}\t0.{k}0"
            rows.append(
                f"06/05/26\t10:00:0{k}\t{k}\t5.{k}0\t40\t{300 + k}\t5.50\t305\t"
                f"4533.0557N\t1338.5131E\t{cur}\tNO"
            )
        src = tmp_path / "log1Hz.log"
        src.write_text("\r\n".join([*_settings_banner(80), header, *rows]) + "\r\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "logger-tsv" and rep.notes["banner_lines"] == 84
        assert rep.cells == {}
        assert rep.sentences["VHW"] == 4 and rep.sentences["VDR"] == 2
        assert rep.sentences["RMC"] == 1  # the fix repeats: one sample
        assert rep.t_start == datetime(2026, 5, 6, 10, 0, tzinfo=UTC).timestamp()


class TestGenericTable:
    def test_a_plain_table_is_read_by_its_short_names(self, tmp_path: Path) -> None:
        """A processed log with the usual short names (``time`` in ISO with a zone,
        ``speed`` through the water, ``hdg``, ``sog``, ``cog``, ``lat``, ``lng``) is read
        without a map; columns it does not name are left alone."""
        src = tmp_path / "table.csv"
        rows = [
            f"2024-07-18 11:14:5{k}+00:00,59.05,22.78,8.{k},334.0,31{k}.0,90.0,7.{k}"
            for k in range(3)
        ]
        src.write_text("time,lat,lng,sog,cog,hdg,awa,speed\n" + "\n".join(rows) + "\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "generic" and rep.cells == {}
        assert rep.sentences["VHW"] == 3 and rep.sentences["RMC"] == 3
        assert rep.t_start == datetime(2024, 7, 18, 11, 14, 50, tzinfo=UTC).timestamp()
        vhw = [x for _, x in _decoded(tmp_path / "o.cap") if isinstance(x, Vhw)]
        assert [v.stw_knots for v in vhw] == [7.0, 7.1, 7.2]
        assert [v.heading_true_deg for v in vhw] == [310.0, 311.0, 312.0]
        rmc = [x for _, x in _decoded(tmp_path / "o.cap") if isinstance(x, Rmc)]
        assert rmc[0].lon_deg == pytest.approx(22.78)


class TestWindowsExports:
    """A table written on Windows: its code page, units after the names."""

    def test_a_magnetic_degree_column_is_a_magnetic_heading(self, tmp_path: Path) -> None:
        """``Hdg (°M)`` in a cp1252 file: the column is the heading, read as magnetic
        (the model's variation at the fixes), ``°T`` columns and the rest are read."""
        rows = [f"{38516.4 + i / 86_400:.6f},3.1,147,{150 + i},3.4" for i in range(5)]
        text = "Utc,Bsp (kt),Hdg (°M),Cog (°T),Sog (kt)\n" + "\n".join(rows) + "\n"
        src = tmp_path / "x.csv"
        src.write_bytes(text.encode("cp1252"))
        rep = import_csv(src, tmp_path / "x.cap")
        assert not any(k.startswith("unit_not_known") for k in rep.notes)
        assert rep.heading_ref == "magnetic" and "no_heading_column" not in rep.notes
        assert rep.sentences["VHW"] == 1 and rep.sentences["RMC"] == 5


class TestSiUnits:
    def test_a_logger_in_si_units_with_a_zone_offset(self, tmp_path: Path) -> None:
        """A logger of Signal K's SI units: ``;`` with decimal commas, ISO times at
        +02:00, speeds in m/s and km/h, angles in radians: knots and degrees out, the
        times UTC."""
        rows = [
            f"2024-07-18T13:14:5{k}+02:00;{2 + k / 10:.1f};{math.radians(90 + k):.6f};"
            f"{7.2 + k:.1f};{math.radians(95):.6f}".replace(".", ",")
            for k in range(3)
        ]
        src = tmp_path / "si.csv"
        src.write_text("time;speed (m/s);hdg (rad);sog (km/h);cog (rad)\n" + "\n".join(rows))
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.cells == {} and rep.sentences == {"VHW": 3, "RMC": 3}
        assert rep.t_start == datetime(2024, 7, 18, 11, 14, 50, tzinfo=UTC).timestamp()
        recs = [x for _, x in _decoded(tmp_path / "o.cap")]
        vhw = [x for x in recs if isinstance(x, Vhw)]
        assert [v.stw_knots for v in vhw] == pytest.approx(
            [2.0 / KNOT_MPS, 2.1 / KNOT_MPS, 2.2 / KNOT_MPS], abs=0.01
        )
        assert [v.heading_true_deg for v in vhw] == pytest.approx([90.0, 91.0, 92.0])
        rmc = [x for x in recs if isinstance(x, Rmc)]
        assert rmc[0].sog_mps == pytest.approx(2.0, abs=0.01)
        assert rmc[0].cog_true_deg == pytest.approx(95.0)
