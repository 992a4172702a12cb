"""NMEA 0183 records: when a GNSS record is a measured fix (status, mode, fix quality)."""

from __future__ import annotations

import dataclasses
from datetime import UTC, datetime

import pytest

from drivers.errors import FieldError
from drivers.framing import with_checksum
from drivers.nmea0183 import RECORDS, Gga, NmeaDecoder, Rmc, Vdr, Vtg, Zda
from drivers.records import KMH_MPS, KNOT_MPS


def _parse(body: str) -> object:
    return NmeaDecoder("x").parse_frame(with_checksum(body).encode())


class TestValidity:
    """Status, mode and fix-quality fields decide whether a fix is a measurement."""

    @pytest.mark.parametrize(
        ("status", "mode", "valid"),
        [("A", "A", True), ("A", "D", True), ("V", "A", False), ("A", "E", False),
         ("A", "N", False), ("A", "S", False), ("A", "", True)],
    )  # fmt: skip
    def test_rmc_status_and_mode(self, status: str, mode: str, valid: bool) -> None:
        """A void status or an estimated/not-valid/simulated mode is not a fix."""
        tail = f",{mode}" if mode else ""
        r = _parse(f"GPRMC,120000.00,{status},,,,,5.0,90.0,010125,,{tail}")
        assert isinstance(r, Rmc) and r.valid is valid

    def test_rmc_without_speed_is_not_valid(self) -> None:
        """An active fix with an empty SOG field gives no speed."""
        r = _parse("GPRMC,120000,A,,,,,,,010125,,,A")
        assert isinstance(r, Rmc) and r.sog_mps is None and not r.valid

    def test_vtg_knots_then_kmh(self) -> None:
        """VTG's knots field is preferred; the km/h field is used when it is empty."""
        r = _parse("GPVTG,10.0,T,8.0,M,4.00,N,7.41,K,D")
        assert isinstance(r, Vtg) and r.sog_mps == pytest.approx(4 * KNOT_MPS) and r.valid
        r = _parse("GPVTG,10.0,T,,M,,N,7.20,K,A")
        assert isinstance(r, Vtg) and r.sog_mps == pytest.approx(7.2 * KMH_MPS)
        assert r.cog_mag_deg is None
        r = _parse("GPVTG,10.0,T,,M,4.0,N,,K,N")
        assert isinstance(r, Vtg) and not r.valid

    def test_vtg_before_nmea_2(self) -> None:
        """VTG's form before NMEA 2.0 (four fields, no unit letters: course true and
        magnetic, knots, km/h) as an older receiver sends it; five fields are none."""
        r = _parse("GPVTG,054.7,034.4,005.5,010.2")
        assert isinstance(r, Vtg) and r.cog_true_deg == pytest.approx(54.7)
        assert r.cog_mag_deg == pytest.approx(34.4) and r.sog_mps == pytest.approx(5.5 * KNOT_MPS)
        r = _parse("GPVTG,054.7,,,010.2")
        assert isinstance(r, Vtg) and r.sog_mps == pytest.approx(10.2 * KMH_MPS)
        with pytest.raises(FieldError):
            _parse("GPVTG,054.7,034.4,005.5,010.2,X")

    def test_gga_quality(self) -> None:
        """GGA's fix quality 0 means no fix; an empty field reads as 0."""
        r = _parse("GPGGA,120000.00,4613.353,N,00610.289,E,2,09,0.9,372.0,M,48.0,M,,")
        assert isinstance(r, Gga) and r.quality == 2 and r.satellites == 9
        assert r.time_of_day_s == 43200.0 and r.hdop == pytest.approx(0.9)
        r = _parse("GPGGA,120000.00,,,,,,,,,M,,M,,")
        assert isinstance(r, Gga) and r.quality == 0 and r.lat_deg is None

    def test_zda(self) -> None:
        """ZDA gives the full date; empty date fields give no time."""
        r = _parse("GPZDA,235959.50,31,12,2025,00,00")
        assert isinstance(r, Zda)
        assert r.time_utc == datetime(2025, 12, 31, 23, 59, 59, 500000, tzinfo=UTC)
        r = _parse("GPZDA,235959.50,,,,00,00")
        assert isinstance(r, Zda) and r.time_utc is None

    def test_vdr(self) -> None:
        """VDR's drift is in knots; set is the direction the current flows towards."""
        r = _parse("IIVDR,199.6,T,198.0,M,0.07,N")
        assert isinstance(r, Vdr)
        assert (r.set_true_deg, r.set_mag_deg) == (199.6, 198.0)
        assert r.drift_mps == pytest.approx(0.07 * KNOT_MPS)


@pytest.mark.parametrize("cls", RECORDS, ids=lambda c: c.__name__)
def test_every_record_is_built_by_keyword(cls: type) -> None:
    """Each NMEA record type takes its fields by keyword only."""
    assert all(f.kw_only for f in dataclasses.fields(cls))
