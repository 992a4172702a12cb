"""``emlogd import``: NMEA logs timed by their fixes, CSV exports through a column map.

The first lines of ``IRENE`` are from the yacht Irene's log on Lake Geneva (2014-06-27),
published in the jpilet/anemomind repository under the MIT licence (© Anemomind SàRL).
"""

from __future__ import annotations

import json
import math
from datetime import UTC, date, datetime
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.framing import with_checksum
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vdr, Vhw, encode_gga, encode_rmc, encode_vhw, encode_zda
from drivers.records import KNOT_MPS
from emlogd.cli import main
from emlogd.offline.importer import (
    EXPEDITION,
    ImportFormatError,
    import_csv,
    import_nmea,
    parse_map,
)

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "real"

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


def _records(path: Path) -> list[tuple[float, str, str]]:
    reader = CaptureReader(path)
    return [(r.t, r.port, r.payload) for r in reader]


class TestNmea:
    """NMEA logs: time from the fixes, sentences spread between them, rejects counted."""

    def test_real_excerpt(self, tmp_path: Path) -> None:
        """Irene's log: three RMC fixes 1 s apart time the 11 sentences from the first fix."""
        src = tmp_path / "irene.nmea"
        src.write_text(IRENE)
        out = tmp_path / "irene.cap"
        rep = import_nmea([src], out)
        recs = _records(out)
        assert rep.lines == 14 and rep.written == 11 == len(recs)
        assert rep.skipped == {"before_first_fix": 3}
        assert rep.sentences["RMC"] == 3 and rep.sentences["VHW"] == 3
        times = [t for t, _, _ in recs]
        # first fix at 13:22:20 with the 5 sentences up to the next fix spread over 1 s
        assert times[:6] == pytest.approx([T0, T0 + 0.2, T0 + 0.4, T0 + 0.6, T0 + 0.8, T0 + 1])
        # after the last fix: the previous interval's rate (1 s over 4 sentences)
        assert times[-2:] == pytest.approx([T0 + 2.0, T0 + 2.25])
        assert {p for _, p, _ in recs} == {"nmea"}
        assert recs[0][2].startswith("$IIRMC,132220")

    def test_rejects_counted_by_reason(self, tmp_path: Path) -> None:
        """Bad checksums, text and empty lines are counted, never written or fatal."""
        t = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
        good = encode_rmc(t, 2.0, 90.0)
        bad = good[:-2] + ("00" if good[-2:] != "00" else "11")
        src = tmp_path / "log.nmea"
        src.write_text("\n".join([good, encode_vhw(2.0), bad, "hello", "", "$VWVHW,no,sum"]))
        rep = import_nmea([src], tmp_path / "o.cap")
        assert rep.written == 2
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
        ]
        src = tmp_path / "log.nmea"
        src.write_text("\r\n".join(lines) + "\r\n")
        out = tmp_path / "o.cap.gz"
        rep = import_nmea([src], out)
        recs = _records(out)
        assert [r[0] - t.timestamp() for r in recs] == pytest.approx([0.0, 0.5, 1.0, 1.5])
        assert rep.notes == {}

    def test_gga_only_needs_a_date(self, tmp_path: Path) -> None:
        """GGA alone has no date: the import refuses without --date and works with it."""
        t = datetime(2026, 3, 4, 10, 0, 0, tzinfo=UTC)
        src = tmp_path / "gga.nmea"
        src.write_text(f"{encode_gga(t, 1.0, 2.0)}\n{encode_vhw(1.0)}\n")
        with pytest.raises(ImportFormatError, match="--date"):
            import_nmea([src], tmp_path / "o.cap")
        rep = import_nmea([src], tmp_path / "o.cap", day=date(2026, 3, 4))
        assert rep.t_start == t.timestamp() and rep.written == 2

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

    def test_imported_capture_decodes_to_the_values_written(self, tmp_path: Path) -> None:
        """The capture replays through the NMEA decoder to the log's own values."""
        src = tmp_path / "irene.nmea"
        src.write_text(IRENE)
        rep = import_nmea([src], tmp_path / "o.cap")
        dec = make_decoder("nmea0183", "nmea", errors="skip")
        recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        rmc = [r for r in recs if isinstance(r, Rmc)]
        vhw = [r for r in recs if isinstance(r, Vhw)]
        assert len(rmc) == 3 and len(vhw) == 3 and rep.written == 11
        assert rmc[1].sog_mps == pytest.approx(2.4 * KNOT_MPS)
        assert vhw[0].heading_mag_deg == 263.0


def _csv(tmp_path: Path, rows: list[str], header: str = "Utc,Bsp,Hdg,Sog,Cog,iSet,iDrift") -> Path:
    p = tmp_path / "log.csv"
    p.write_text(header + "\n" + "\n".join(rows) + "\n")
    return p


OLE_2005 = 38516.5  # 2005-06-13 12:00 UTC


class TestCsv:
    """CSV exports: a column map, sparse rows carried forward, each row as VHW/RMC/VDR."""

    def test_expedition_rows(self, tmp_path: Path) -> None:
        """Expedition's columns give VHW with the true heading, RMC and VDR at the row times."""
        sec = 1.0 / 86400.0
        src = _csv(
            tmp_path,
            [
                f"{OLE_2005},3.0,90.0,3.2,95.0,199.6,0.074",
                f"{OLE_2005 + sec},3.1,,3.3,,,",  # sparse: Hdg, Cog, iSet, iDrift carried
                f"{OLE_2005 + 2 * sec},,,,,,",  # nothing new: all carried forward
            ],
        )
        mapping = {k: v for k, v in EXPEDITION.items() if k not in ("lat", "lon")}
        rep = import_csv(src, tmp_path / "o.cap", mapping)
        assert rep.lines == 3 and rep.sentences == {"VHW": 3, "RMC": 3, "VDR": 3}
        dec = make_decoder("nmea0183", "nmea")
        recs = [(r.t, x) for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        t0 = datetime(2005, 6, 13, 12, tzinfo=UTC).timestamp()
        assert recs[0][0] == pytest.approx(t0, abs=1e-3)
        vhw = [x for _, x in recs if isinstance(x, Vhw)]
        assert [v.stw_mps for v in vhw] == pytest.approx(
            [3.0 * KNOT_MPS, 3.1 * KNOT_MPS] * 1 + [3.1 * KNOT_MPS], abs=0.003
        )
        assert all(v.heading_true_deg == 90.0 and v.heading_mag_deg is None for v in vhw)
        rmc = [x for _, x in recs if isinstance(x, Rmc)]
        assert rmc[1].cog_true_deg == 95.0 and rmc[1].sog_mps == pytest.approx(
            3.3 * KNOT_MPS, abs=0.003
        )
        vdr = [x for _, x in recs if isinstance(x, Vdr)]
        assert vdr[2].set_true_deg == pytest.approx(199.6)
        assert vdr[2].drift_mps == pytest.approx(0.074 * KNOT_MPS, abs=0.003)

    def test_carry_is_bounded(self, tmp_path: Path) -> None:
        """A value older than carry_s is not carried: the row has no speed and is counted."""
        src = _csv(tmp_path, ["0,2.0", "5,", "30,"], header="T,S")
        rep = import_csv(src, tmp_path / "o.cap", {"time": "T", "stw": "S"}, time_format="epoch")
        assert rep.written == 2 and rep.skipped == {"no_speed": 1}

    def test_units_magnetic_iso_and_bad_cells(self, tmp_path: Path) -> None:
        """[mps] columns, a magnetic heading, ISO times; bad numbers and times are counted."""
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
        assert rep.skipped == {"bad_number": 1, "no_time": 1, "negative_speed": 1}
        assert rep.notes == {"bad_cell_ignored": 1} and rep.sentences == {"VHW": 2}
        dec = make_decoder("nmea0183", "nmea")
        (first, *_) = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
        assert isinstance(first, Vhw)
        assert first.stw_mps == pytest.approx(2.5, abs=0.003)
        assert first.heading_mag_deg == 10.0 and first.heading_true_deg is None

    @pytest.mark.parametrize(
        ("spec", "match"),
        [("time=Utc,bogus=X", "bogus"), ("time", "key=Column"), ("time=", "key=Column")],
    )
    def test_bad_map(self, spec: str, match: str) -> None:
        """A malformed map names the item at fault."""
        with pytest.raises(ImportFormatError, match=match):
            parse_map(spec)

    def test_missing_column_or_key(self, tmp_path: Path) -> None:
        """A mapped column not in the header, or a map without stw, is refused."""
        src = _csv(tmp_path, [f"{OLE_2005},3.0,90,3,90,0,0"])
        with pytest.raises(ImportFormatError, match="'Speed'"):
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
        assert doc["written"] == 11 and doc["skipped"] == {"before_first_fix": 3}
        assert doc["span_s"] == pytest.approx(2.25) and out.exists()

    def test_csv_needs_a_map(self, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
        """csv without --map or --preset is a usage error; nmea options are refused for csv."""
        src = _csv(tmp_path, [f"{OLE_2005},3.0,90,3,90,0,0"])
        out = str(tmp_path / "o.cap")
        assert main(["import", str(src), "--format", "csv", "--out", out]) == 2
        assert "--preset expedition" in capsys.readouterr().err
        args = ["import", str(src), "--format", "csv", "--out", out, "--preset", "expedition"]
        assert main([*args, "--date", "2026-01-01"]) == 2
        assert main(["import", str(src), "--format", "nmea", "--out", out, "--map", "time=X"]) == 2

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

    def test_irene(self, tmp_path: Path) -> None:
        """Irene 06-27: all but the 9 lines before the first RMC fix are written."""
        rep = import_nmea([REAL / "irene-2014-06-27-leman.nmea"], tmp_path / "i.cap.gz")
        assert rep.written + sum(rep.skipped.values()) == rep.lines
        assert rep.skipped == {"before_first_fix": 9}
        assert rep.sentences["RMC"] == rep.sentences["VHW"] > 7000
        assert 130 * 60 < rep.t_end - rep.t_start < 140 * 60

    def test_valencia(self, tmp_path: Path) -> None:
        """Expedition's Valencia log: every row gives VHW, RMC and VDR over 204 minutes."""
        rep = import_csv(REAL / "expedition-valencia.csv", tmp_path / "v.cap.gz", dict(EXPEDITION))
        assert rep.skipped == {} and rep.lines == rep.sentences["VHW"] == rep.sentences["VDR"]
        assert math.isclose(rep.t_end - rep.t_start, 204 * 60, rel_tol=0.01)

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

    def test_irene_calibrated_log_stays_calibrated(self, tmp_path: Path) -> None:
        """Irene 06-27 (a lake, a log already calibrated): the GNSS fit finds a scale
        within 3 % and a corrected speed no worse than raw — the noisy GNSS reference
        does not shrink the scale (a per-sample fit says −8 %)."""
        from emlogd.offline.jobs import calibrate, load_captures
        from emlogd.pipeline.settings import UutSettings

        cap = tmp_path / "i.cap.gz"
        import_nmea([REAL / "irene-2014-06-27-leman.nmea"], cap)
        s = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)
        res = calibrate(load_captures([str(cap)], s), s, "ls", lag=0.0)
        assert abs(res.params.m) < 0.03
        assert res.rmse_cal <= res.rmse_raw
