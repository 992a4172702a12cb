"""``emlogd import --format nmea``: NMEA logs timed by their fixes.

The first lines of ``IRENE`` are from the yacht Irene's log on Lake Geneva (2014-06-27),
published in the jpilet/anemomind repository under the MIT licence (© Anemomind SàRL).
"""

from __future__ import annotations

import os
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.framing import nmea_checksum
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Gga, Rmc, Vhw, encode_rmc, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline.importer import ImportFormatError, import_nmea
from tests.nmea_encoders import encode_gga, encode_vtg, encode_zda

IRENE = """\
$IIMTW,+00.0,C*38
$IIVHW,,,069,M,00.6,N,,*6D
$IIHDG,069,,,01,E*1C
$IIRMC,132220,A,4613.353,N,00610.289,E,01.9,238,270614,01,E,A*0B
$IIVHW,,,263,M,01.0,N,,*62
$IIVLW,01554,N,000.0,N*56
$IIGLL,4613.353,N,00610.289,E,132220,A,A*51
$IIHDG,263,,,01,E*14
$IIRMC,132221,A,4613.352,N,00610.285,E,02.4,239,270614,01,E,A*08
$IIVHW,,,260,M,01.3,N,,*62
$IIDPT,009.4,-1.0,*4D
$IIHDG,261,,,01,E*16
$IIRMC,132222,A,4613.351,N,00610.279,E,03.2,259,270614,01,E,A*0A
$IIVHW,,,261,M,01.6,N,,*66
"""

T0 = datetime(2014, 6, 27, 13, 22, 20, tzinfo=UTC).timestamp()


def _gll(hms: str, status: str) -> str:
    body = f"GPGLL,4613.353,N,00610.289,E,{hms},{status},A"
    return f"${body}*{nmea_checksum(body.encode('ascii')):02X}"


def _records(path: Path) -> list[tuple[float, str, str]]:
    reader = CaptureReader(path)
    return [(r.t, r.port, r.payload) for r in reader]


class TestNmea:
    """NMEA logs: time from the fixes, sentences spread between them, rejects counted."""

    def test_real_excerpt(self, tmp_path: Path) -> None:
        """Irene's log: three RMC fixes 1 s apart time the sentences from the first fix to
        the last; those before the first and after the last have no time."""
        src = tmp_path / "irene.nmea"
        src.write_text(IRENE)
        out = tmp_path / "irene.cap"
        rep = import_nmea([src], out)
        recs = _records(out)
        assert rep.lines == 14 and rep.written == 10 == len(recs)
        assert rep.skipped == {"before_first_fix": 3, "after_last_fix": 1}
        assert rep.sentences["RMC"] == 3 and rep.sentences["VHW"] == 2
        times = [t for t, _, _ in recs]
        # first fix at 13:22:20 with the 5 sentences up to the next fix spread over 1 s
        assert times[:6] == pytest.approx([T0, T0 + 0.2, T0 + 0.4, T0 + 0.6, T0 + 0.8, T0 + 1])
        # never past the last fix
        assert times[-1] == pytest.approx(T0 + 2.0) and recs[-1][2].startswith("$IIRMC,132222")
        assert {p for _, p, _ in recs} == {"nmea"}
        assert recs[0][2].startswith("$IIRMC,132220")

    def test_rejects_counted_by_reason(self, tmp_path: Path) -> None:
        """Bad checksums, text and empty lines are counted, never written or fatal."""
        t = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
        good = encode_rmc(t, 2.0, 90.0)
        bad = good[:-2] + ("00" if good[-2:] != "00" else "11")
        src = tmp_path / "log.nmea"
        later = encode_rmc(t + timedelta(seconds=1), 2.0, 90.0)
        lines = [good, encode_vhw(2.0), bad, "hello", "", "$VWVHW,no,sum", later]
        src.write_text("\n".join(lines))
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 3
        assert rep.skipped["checksum"] == 1
        assert rep.skipped["not_nmea"] == 1 and rep.skipped["empty"] == 1
        assert sum(rep.skipped.values()) == 4

    def test_zda_then_gga_with_the_date_learnt(self, tmp_path: Path) -> None:
        """Without RMC, ZDA times the log and gives the date GGA's times of day need."""
        t = datetime(2026, 3, 4, 23, 59, 58, tzinfo=UTC)
        lines = [
            encode_zda(t),
            encode_vhw(1.0),
            encode_gga(t.replace(second=59), 46.0, 6.0),
            encode_vhw(1.1),
            encode_zda(t + timedelta(seconds=2)),
        ]
        src = tmp_path / "log.nmea"
        src.write_text("\r\n".join(lines) + "\r\n")
        out = tmp_path / "o.cap.gz"
        rep = import_nmea([src], out)
        recs = _records(out)
        assert [r[0] - t.timestamp() for r in recs] == pytest.approx([0.0, 0.5, 1.0, 1.5, 2.0])
        assert rep.notes == {}

    def test_gga_only_takes_the_given_date_else_the_files(self, tmp_path: Path) -> None:
        """GGA alone has no date: --date gives it; without it, a log with no dated fix
        takes the date in its file's name, else the day the file was last written
        (noted); a log with no fix at all is refused, naming --date."""
        t = datetime(2026, 3, 4, 10, 0, 0, tzinfo=UTC)
        t2 = t + timedelta(seconds=1)
        text = f"{encode_gga(t, 1.0, 2.0)}\n{encode_vhw(1.0)}\n{encode_gga(t2, 1.0, 2.0)}\n"
        src = tmp_path / "gga.nmea"
        src.write_text(text)
        written = datetime(2026, 3, 4, 23, 0, tzinfo=UTC).timestamp()
        os.utime(src, (written, written))
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 3, 5))
        assert rep.t_start == t.timestamp() + 86_400.0 and rep.written == 3 and not rep.notes
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.t_start == t.timestamp() and rep.notes == {"date_from_file_time": 1}
        named = tmp_path / "log_2026-03-04.nmea"
        named.write_text(text)
        rep = import_nmea([named], tmp_path / "o.cap")
        assert rep.t_start == t.timestamp() and rep.notes == {"date_from_file_name": 1}
        src.write_text(f"{encode_vhw(1.0)}\n{encode_vhw(1.1)}\n")
        with pytest.raises(ImportFormatError, match="GLL, or RMC without a date, with --date"):
            import_nmea([src], tmp_path / "o.cap")

    def test_gll_alone_times_the_log(self, tmp_path: Path) -> None:
        """A GNSS sending GLL (time of day) and VTG alone: GLL's valid fixes time the
        log on the given date, each written as a GGA after it too (its position for
        the pipeline, which reads none from GLL); a void GLL times nothing."""
        lines = [
            _gll("100000", "A"),
            encode_vtg(1.0, 90.0),
            encode_vhw(1.0),
            _gll("100001", "V"),
            encode_vhw(1.1),
            _gll("100002", "A"),
            encode_vhw(1.2),
        ]
        src = tmp_path / "gll.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 3, 4))
        t0 = datetime(2026, 3, 4, 10, 0, 0, tzinfo=UTC).timestamp()
        recs = _records(tmp_path / "o.cap")
        assert [r[0] - t0 for r in recs] == pytest.approx([k / 3 for k in range(7)])
        assert rep.skipped == {"after_last_fix": 2} and rep.sentences["VTG"] == 1
        assert rep.notes == {"gga_from_gll": 2} and rep.sentences["GGA"] == 1
        (gga,) = make_decoder("nmea0183", "n").decode_all(recs[1][2].encode() + b"\r\n")
        assert isinstance(gga, Gga) and gga.quality == 1 and gga.time_of_day_s == 36_000.0
        assert (gga.lat_deg, gga.lon_deg) == pytest.approx((46 + 13.353 / 60, 6 + 10.289 / 60))

    def test_gll_beside_rmc_times_nothing(self, tmp_path: Path) -> None:
        """Beside RMC (an instrument bus repeating the fix, late), GLL is no time
        source once an RMC has come: a GLL a second behind costs no note."""
        t = datetime(2026, 3, 4, 10, 0, 0, tzinfo=UTC)
        lines = [encode_rmc(t, 1.0, 0.0), encode_vhw(1.0), _gll("095959", "A")]
        lines += [encode_rmc(t + timedelta(seconds=1), 1.0, 0.0)]
        src = tmp_path / "both.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        times = [r[0] - t.timestamp() for r in _records(tmp_path / "o.cap")]
        assert times == pytest.approx([0.0, 1 / 3, 2 / 3, 1.0]) and not rep.notes

    def test_fix_time_going_back_is_not_a_time_source(self, tmp_path: Path) -> None:
        """A repeated or earlier fix time is kept as a sentence but times nothing."""
        t = datetime(2026, 1, 1, 0, 0, 10, tzinfo=UTC)
        early = t.replace(second=5)
        lines = [encode_rmc(t, 1.0, 0.0), encode_rmc(early, 1.0, 0.0)]
        lines += [encode_vhw(1.0), encode_rmc(t.replace(second=12), 1.0, 0.0)]
        src = tmp_path / "log.nmea"
        src.write_text("\n".join(lines))
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.notes == {"fix_time_not_increasing": 1}
        times = [r[0] - t.timestamp() for r in _records(tmp_path / "o.cap")]
        assert times == pytest.approx([0.0, 2 / 3, 4 / 3, 2.0])

    def test_a_gap_between_fixes_times_nothing(self, tmp_path: Path) -> None:
        """Fixes more than MAX_FIX_GAP_S apart (a logger paused): the sentences between
        them are counted, not spread over the gap; the later fix times what follows."""
        from emlogd.offline.importer import MAX_FIX_GAP_S

        t = datetime(2026, 1, 1, 12, tzinfo=UTC)
        late = t + timedelta(seconds=MAX_FIX_GAP_S + 1.0)
        lines = [encode_rmc(t, 1.0, 0.0), encode_vhw(1.0), encode_vhw(1.1)]
        lines += [encode_rmc(late, 1.0, 0.0), encode_vhw(1.2)]
        lines += [encode_rmc(late + timedelta(seconds=1), 1.0, 0.0)]
        src = tmp_path / "log.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.skipped == {"fix_gap": 2}
        times = [r[0] - t.timestamp() for r in _records(tmp_path / "o.cap")]
        gap = MAX_FIX_GAP_S + 1.0
        assert times == pytest.approx([0.0, gap, gap + 0.5, gap + 1.0])

    def test_a_fix_outside_the_years_times_nothing(self, tmp_path: Path) -> None:
        """A ZDA dated 2150 between fixes of 2026 is noted and kept as a sentence, and the
        log goes on being timed by the good fixes."""
        t = datetime(2026, 1, 1, 12, tzinfo=UTC)
        lines = [encode_rmc(t, 1.0, 0.0), encode_zda(t.replace(year=2150))]
        lines += [encode_rmc(t + timedelta(seconds=2), 1.0, 0.0)]
        src = tmp_path / "log.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.notes == {"fix_time_out_of_range": 1} and rep.written == 3
        times = [r[0] - t.timestamp() for r in _records(tmp_path / "o.cap")]
        assert times == pytest.approx([0.0, 1.0, 2.0])

    def test_gzip_input(self, tmp_path: Path) -> None:
        """A gzip-compressed log is read as the plain one."""
        import gzip

        src = tmp_path / "irene.nmea.gz"
        src.write_bytes(gzip.compress(IRENE.encode()))
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 10

    def test_imported_capture_decodes_to_the_values_written(self, tmp_path: Path) -> None:
        """The capture replays through the NMEA decoder to the log's own values."""
        src = tmp_path / "irene.nmea"
        src.write_text(IRENE)
        rep = import_nmea([src], tmp_path / "o.cap")
        dec = make_decoder("nmea0183", "nmea", errors="skip")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        rmc = [r for r in recs if isinstance(r, Rmc)]
        vhw = [r for r in recs if isinstance(r, Vhw)]
        assert len(rmc) == 3 and len(vhw) == 2 and rep.written == 10
        assert rmc[1].sog_mps == pytest.approx(2.4 * KNOT_MPS)
        assert vhw[0].heading_mag_deg == 263.0


class TestLinesAsLoggersWriteThem:
    """NUL padding, a sentence split over two lines, RMC without its date."""

    def test_nul_padding_and_ctrl_z_are_no_part_of_a_line(self, tmp_path: Path) -> None:
        """Irene's lines each padded with NULs, the file ended by NULs and a Ctrl-Z: the
        same sentences as the clean log."""
        src = tmp_path / "pad.nmea"
        src.write_text("".join(ln + "\x00" * 8 + "\n" for ln in IRENE.splitlines()) + "\x00\x1a")
        rep = import_nmea([src], tmp_path / "pad.cap")
        assert rep.written == 10 and rep.skipped["checksum"] == 0

    def test_a_sentence_split_over_two_lines_is_joined(self, tmp_path: Path) -> None:
        """A sentence cut in two lines is written whole (``lines_joined``); a cut line
        followed by a sentence of its own stays a cut line."""
        lines = IRENE.splitlines()
        vhw = lines[4]
        lines[4:5] = [vhw[:12], vhw[12:]]
        lines.insert(10, "$IIDPT,009.4")  # cut, and the next line is a sentence
        src = tmp_path / "split.nmea"
        src.write_text("\n".join(lines) + "\n")
        rep = import_nmea([src], tmp_path / "split.cap")
        assert rep.notes["lines_joined"] == 1 and rep.skipped["missing_checksum"] == 1
        assert rep.written == 10 and rep.sentences["VHW"] == 2
        assert vhw in [p for _, _, p in _records(tmp_path / "split.cap")]

    def test_rmc_without_a_date_takes_the_given_one(self, tmp_path: Path) -> None:
        """RMC with its date field empty times the log from --date (midnight crossed
        moves to the next day); without --date, the day the file was last written
        (noted)."""

        def no_date(t: datetime) -> str:
            body = encode_rmc(t, 2.0, 90.0)[1:].split("*")[0].split(",")
            body[9] = ""
            text = ",".join(body)
            return f"${text}*{nmea_checksum(text.encode('ascii')):02X}"

        t = datetime(2026, 1, 2, 23, 59, 59, tzinfo=UTC)
        src = tmp_path / "nodate.nmea"
        src.write_text("\n".join([no_date(t), encode_vhw(2.0), no_date(t + timedelta(seconds=2))]))
        assert import_nmea([src], tmp_path / "x.cap").notes["date_from_file_time"] == 1
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 1, 2))
        assert rep.written == 3
        assert rep.t_start == pytest.approx(t.timestamp())
        assert rep.t_end == pytest.approx(t.timestamp() + 2.0)

    def test_sentences_run_together_on_one_line_are_split(self, tmp_path: Path) -> None:
        """Line ends lost between sentences: each is read after the checksum before it
        (``sentences_run_together``); a tag block before a sentence is no such end."""
        lines = IRENE.splitlines()
        joined = [lines[0], "".join(lines[1:5]), *lines[5:]]
        joined[-1] = "\\s:GP0001,c:1403875342*6B\\" + joined[-1]
        src = tmp_path / "run.nmea"
        src.write_text("\n".join(joined) + "\n")
        rep = import_nmea([src], tmp_path / "run.cap")
        assert rep.notes["sentences_run_together"] == 3
        assert rep.written == 10 and rep.sentences["VHW"] == 2
