"""The heading behind an offline GNSS calibration: the variation used, a wrong heading
refused with its figures, and the cause named when nothing pairs."""

from __future__ import annotations

import dataclasses
import math
from datetime import UTC, datetime
from pathlib import Path

import pytest

from drivers.framing import with_checksum
from drivers.io.capture import CaptureWriter
from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.offline.jobs import OfflineError, calibrate, load_captures
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.variation import model_variation
from tests.nmea_encoders import encode_hdt
from tests.once import Imported

REAL = Path(__file__).resolve().parents[3].parent / "shared" / "real"
T0 = datetime(2014, 8, 22, 16, 0, tzinfo=UTC).timestamp()
LAT, LON = 46.2, 6.17  # Lake Geneva
GNSS = UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", current=True)


def _sail(
    path: Path,
    *,
    heading: str = "hdg",
    heading_error: float = 0.0,
    position: bool = True,
    fix_every: int = 1,
    n: int = 1200,
) -> Path:
    """A yacht on legs of 60 s through eight headings at 3 m/s (no current, log exact):
    RMC (with or without a position, never a variation), the heading as ``hdg`` (a
    magnetic HDG with empty variation fields), ``hdt`` or ``ths`` (true) or none, and VHW;
    ``fix_every`` 0: no fix at all."""
    var = model_variation(LAT, LON, T0) or 0.0
    with CaptureWriter(path, {"nmea": "nmea0183"}) as w:
        for k in range(n):
            t = T0 + k
            psi = ((k // 60) * 135.0) % 360.0
            u = 3.0 + 0.5 * math.sin(k / 50.0)
            sent = (psi - heading_error) % 360.0
            if heading == "hdg":
                w.write_line(
                    t, "nmea", with_checksum(f"IIHDG,{(sent - var) % 360.0:.1f},,,,").encode()
                )
            elif heading == "hdt":
                w.write_line(t, "nmea", encode_hdt(sent).encode())
            elif heading == "ths":
                w.write_line(t, "nmea", with_checksum(f"GPTHS,{sent:.1f},A").encode())
            if fix_every and k % fix_every == 0:
                fix = encode_rmc(
                    datetime.fromtimestamp(t, UTC),
                    u,
                    psi,
                    lat_deg=LAT if position else None,
                    lon_deg=LON if position else None,
                )
                w.write_line(t + 0.1, "nmea", fix.encode())
            w.write_line(t + 0.2, "nmea", encode_vhw(u / 1.05, talker="II").encode())
    return path


class TestVariation:
    """A magnetic heading without a variation in the log."""

    def test_the_model_gives_it_and_the_result_says_so(self, tmp_path: Path) -> None:
        """Magnetic HDG + RMC with a position: calibrated with the IGRF variation, the
        log's 5 % over-reading found, and the JSON names the variation's source."""
        cap = _sail(tmp_path / "m.cap")
        res = calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        assert res.params.m == pytest.approx(-1.0 / 21.0, abs=0.01)
        h = res.to_dict()["heading"][str(cap)]  # type: ignore[index]
        assert h["variation_source"] == "model"
        assert h["variation_deg"] == pytest.approx(model_variation(LAT, LON, T0), abs=0.01)
        assert abs(h["check"]["offset_deg"]) < 1.0 and not h["check"]["flagged"]

    def test_without_a_position_the_error_names_the_cause_and_the_option(
        self, tmp_path: Path
    ) -> None:
        """No position for the model, no variation: the error says the heading is
        magnetic without a variation, and --variation; given, it calibrates."""
        cap = _sail(tmp_path / "m.cap", position=False)
        with pytest.raises(OfflineError, match=r"heading is magnetic .* --variation DEG"):
            calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        given = dataclasses.replace(GNSS, magnetic_variation_deg=model_variation(LAT, LON, T0))
        res = calibrate(load_captures([str(cap)], given), given, "ls", lag=0.0)
        assert res.params.m == pytest.approx(-1.0 / 21.0, abs=0.01)
        assert res.heading[str(cap)]["variation_source"] == "config"


class TestCauses:
    """The error names what is missing, with the option that helps."""

    def test_no_heading(self, tmp_path: Path) -> None:
        """GNSS without any heading: the error says so, names --heading and says why a
        course over ground alone cannot stand in (never that leaving out --current
        helps: the GNSS reference needs the heading either way)."""
        cap = _sail(tmp_path / "n.cap", heading="none")
        with pytest.raises(OfflineError, match=r"no heading arrived.*--heading PORT") as err:
            calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        assert "course over ground alone" in str(err.value)
        assert "without --current" not in str(err.value)

    def test_no_fix_at_all(self, tmp_path: Path) -> None:
        """A log with the water and the heading but no GNSS fix: the error says no fix
        arrived and what a GNSS reference is made of (not that the heading is missing)."""
        cap = _sail(tmp_path / "f.cap", heading="hdt", fix_every=0)
        with pytest.raises(OfflineError, match=r"no GNSS fix arrived at all.*RMC, or VTG"):
            calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)

    def test_no_reading_of_the_log_at_all(self, tmp_path: Path) -> None:
        """Fixes and a heading but no VHW: the error says no reading of the log arrived
        (not that no reading is near a reference), and that VLW's distances are no
        speed."""
        cap = _sail(tmp_path / "r.cap", heading="hdt")
        s = dataclasses.replace(GNSS, uut_source="VBW")
        with pytest.raises(OfflineError, match=r"no VBW reading of the log arrived on port") as e:
            calibrate(load_captures([str(cap)], s), s, "ls", lag=0.0)
        assert "VLW's distances alone give no usable speed" in str(e.value)

    def test_a_gnss_compass_ths_is_the_heading(self, tmp_path: Path) -> None:
        """THS (a GNSS compass's true heading) alone: the log's 5 % over-reading found
        as with HDT."""
        cap = _sail(tmp_path / "t.cap", heading="ths")
        res = calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        assert res.params.m == pytest.approx(-1.0 / 21.0, abs=0.01)

    def test_fixes_3_s_apart_pair(self, tmp_path: Path) -> None:
        """Fixes 3 s apart are within the alignment's cadence gap: every reading pairs
        (a reference too sparse for it is tested in test_jobs)."""
        cap = _sail(tmp_path / "s.cap", heading="hdt", fix_every=3)
        res = calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        assert res.n_samples > 1000

    def test_no_gnss_hints_the_field(self, tmp_path: Path) -> None:
        """Asked for a DVL's bottom track on a log with RMC only: the hint is --ref-field gnss."""
        cap = _sail(tmp_path / "b.cap", heading="hdt")
        s = UutSettings(port="nmea", reference_port="nmea")
        with pytest.raises(OfflineError, match=r"'bottom' has no valid sample.*--ref-field gnss"):
            calibrate(load_captures([str(cap)], s), s, "ls", lag=0.0)


def test_a_wrong_heading_is_refused_with_its_figures(tmp_path: Path) -> None:
    """A true heading 20° off the course: the calibration refuses and gives the offset."""
    cap = _sail(tmp_path / "w.cap", heading="hdt", heading_error=20.0)
    with pytest.raises(OfflineError, match=r"by \+20\.\d° on straight legs .* not calibrated"):
        calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)


@pytest.mark.skipif(not REAL.is_dir(), reason="the shared real recordings are not here")
class TestRealLogs:
    """The real recordings: magnetic headings without variation, and a broken heading."""

    def test_irene_magnetic_heading_calibrates_with_the_model(self, imported: Imported) -> None:
        """Irene 2007-11-03 ($IIHDG magnetic with empty variation fields, RMC without
        one): calibrated with the model's variation (+0.6° there and then) and the scale
        of the independent fit (k 1.075: m ≈ 1/k − 1 = −0.07) within 0.05, the
        tolerance the real-recording suite holds every recording to."""
        _, cap = imported(REAL / "irene-2007-11-03-leman.nmea")
        res = calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
        h = res.heading[str(cap)]
        assert h["variation_source"] == "model"
        assert h["variation_deg"] == pytest.approx(0.6, abs=0.3)
        assert res.params.m == pytest.approx(1.0 / 1.075 - 1.0, abs=0.05)

    def test_estonia_broken_heading_is_refused(self, tmp_path: Path) -> None:
        """The Estonian CSV's heading sensor (median 29° from the course): refused."""
        from emlogd.offline.importer import import_csv, parse_map

        cap = tmp_path / "e.cap.gz"
        m = parse_map("time=time,stw=speed,heading=hdg,sog=sog,cog=cog,lat=lat,lon=lng")
        import_csv(REAL / "regatta-analyser-2024-07-18-estonia.csv", cap, m)
        with pytest.raises(OfflineError, match="disagrees with the course"):
            calibrate(load_captures([str(cap)], GNSS), GNSS, "ls", lag=0.0)
