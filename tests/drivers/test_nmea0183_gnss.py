"""NMEA 0183 GNSS and current sentences: RMC, VTG, GGA, ZDA, VDR decoded and encoded.

Real sentences below are from the yacht Irene's log on Lake Geneva (2014-06-27), published
in the jpilet/anemomind repository under the MIT licence (© Anemomind SàRL).
"""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import FieldError, OutOfRangeError
from drivers.framing import with_checksum
from drivers.nmea0183 import (
    Gga,
    Heading,
    NmeaDecoder,
    Rmc,
    Vdr,
    Vhw,
    Vtg,
    Zda,
    encode_gga,
    encode_hdg,
    encode_hdm,
    encode_hdt,
    encode_rmc,
    encode_vtg,
    encode_zda,
)
from drivers.records import KMH_MPS, KNOT_MPS

IRENE = [
    b"$IIRMC,132220,A,4613.353,N,00610.289,E,01.9,238,270614,01,E,A*0B",
    b"$IIVHW,,,263,M,01.0,N,,*62",
    b"$IIHDG,263,,,01,E*14",
]


def _parse(body: str) -> object:
    return NmeaDecoder("x").parse_frame(with_checksum(body).encode())


class TestReal:
    """Sentences written by a real instrument bus decode to the values they carry."""

    def test_rmc(self) -> None:
        """Time, position, SOG (kn → m/s), COG, variation east, mode A."""
        r = NmeaDecoder("x").parse_frame(IRENE[0])
        assert isinstance(r, Rmc)
        assert r.time_utc == datetime(2014, 6, 27, 13, 22, 20, tzinfo=UTC)
        assert r.time_of_day_s == 13 * 3600 + 22 * 60 + 20
        assert r.lat_deg == pytest.approx(46 + 13.353 / 60)
        assert r.lon_deg == pytest.approx(6 + 10.289 / 60)
        assert r.sog_mps == pytest.approx(1.9 * KNOT_MPS)
        assert r.cog_true_deg == 238.0
        assert r.variation_deg == 1.0
        assert r.mode == "A" and r.valid

    def test_vhw_magnetic_heading_and_hdg_variation(self) -> None:
        """VHW carries only the magnetic heading; HDG gives the variation to make it true."""
        vhw = NmeaDecoder("x").parse_frame(IRENE[1])
        assert isinstance(vhw, Vhw)
        assert vhw.heading_true_deg is None and vhw.heading_mag_deg == 263.0
        assert vhw.stw_mps == pytest.approx(1.0 * KNOT_MPS)
        hdg = NmeaDecoder("x").parse_frame(IRENE[2])
        assert isinstance(hdg, Heading)
        assert hdg.variation_deg == 1.0


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


class TestRejects:
    """Malformed GNSS sentences are rejected with a reason, never decoded to nonsense."""

    @pytest.mark.parametrize(
        ("body", "error"),
        [
            ("GPRMC,120000,A,,,,,5.0,90.0,010125", FieldError),
            ("GPRMC,1200,A,,,,,5.0,90.0,010125,,,A", FieldError),
            ("GPRMC,250000,A,,,,,5.0,90.0,010125,,,A", OutOfRangeError),
            ("GPRMC,120000,A,,,,,5.0,90.0,320125,,,A", OutOfRangeError),
            ("GPRMC,120000,A,4661.0,N,,,5.0,90.0,010125,,,A", OutOfRangeError),
            ("GPRMC,120000,A,4613.0,X,,,5.0,90.0,010125,,,A", FieldError),
            ("GPRMC,120000,A,,,,,-5.0,90.0,010125,,,A", OutOfRangeError),
            ("GPRMC,120000,A,,,,,5.0,400.0,010125,,,A", OutOfRangeError),
            ("GPRMC,120000,A,,,,,5.0,90.0,010125,,,AB", FieldError),
            ("GPVTG,10.0,X,,M,4.0,N,,K,A", FieldError),
            ("GPVTG,10.0,T,,M,4.0,N", FieldError),
            ("GPZDA,120000,31,02,2025,00,00", OutOfRangeError),
            ("IIVDR,10,T,,M,-1,N", OutOfRangeError),
        ],
    )
    def test_reject(self, body: str, error: type[Exception]) -> None:
        """Each malformed sentence raises the error that names its fault."""
        with pytest.raises(error):
            _parse(body)


class TestEncoders:
    """What the encoders write decodes back to the values given."""

    T = datetime(2026, 11, 25, 10, 30, 15, 250000, tzinfo=UTC)

    @settings(max_examples=200, deadline=None)
    @given(
        sog=st.floats(0.0, 30.0),
        cog=st.floats(0.0, 359.9),
        lat=st.floats(-89.9, 89.9),
        lon=st.floats(-179.9, 179.9),
        var=st.floats(-30.0, 30.0),
    )
    def test_rmc_round_trip(
        self, sog: float, cog: float, lat: float, lon: float, var: float
    ) -> None:
        """RMC: knots to 2 decimals, course to 0.1°, position to 1e-4 minute."""
        r = NmeaDecoder("x").parse_frame(
            encode_rmc(self.T, sog, cog, lat_deg=lat, lon_deg=lon, variation_deg=var).encode()
        )
        assert isinstance(r, Rmc) and r.valid
        assert r.time_utc == self.T.replace(microsecond=250000)
        assert r.sog_mps == pytest.approx(sog, abs=0.006 * KNOT_MPS)
        assert r.cog_true_deg is not None
        assert abs((r.cog_true_deg - cog + 180.0) % 360.0 - 180.0) <= 0.051
        assert r.lat_deg == pytest.approx(lat, abs=1e-5)
        assert r.lon_deg == pytest.approx(lon, abs=1e-5)
        assert r.variation_deg == pytest.approx(var, abs=0.051)

    def test_rmc_void_and_empty(self) -> None:
        """A void fix and missing values encode as status V and empty fields."""
        r = NmeaDecoder("x").parse_frame(encode_rmc(None, math.nan, None, active=False).encode())
        assert isinstance(r, Rmc) and not r.valid
        assert r.time_utc is None and r.sog_mps is None and r.cog_true_deg is None

    def test_vtg_gga_zda_round_trip(self) -> None:
        """VTG, GGA and ZDA decode back to what was encoded."""
        v = NmeaDecoder("x").parse_frame(encode_vtg(3.0, 359.96, cog_mag_deg=12.0).encode())
        assert isinstance(v, Vtg) and v.sog_mps == pytest.approx(3.0, abs=0.003)
        assert v.cog_true_deg == 0.0 and v.cog_mag_deg == 12.0
        g = NmeaDecoder("x").parse_frame(encode_gga(self.T, -33.5, 151.25, 4).encode())
        assert isinstance(g, Gga) and g.quality == 4
        assert g.lat_deg == pytest.approx(-33.5) and g.lon_deg == pytest.approx(151.25)
        z = NmeaDecoder("x").parse_frame(encode_zda(self.T).encode())
        assert isinstance(z, Zda) and z.time_utc == self.T

    def test_heading_sentences(self) -> None:
        """HDT is true, HDM magnetic, HDG carries deviation and variation with their sign."""
        t = NmeaDecoder("x").parse_frame(encode_hdt(359.99).encode())
        assert isinstance(t, Heading) and t.true and t.heading_deg == 0.0
        m = NmeaDecoder("x").parse_frame(encode_hdm(45.0).encode())
        assert isinstance(m, Heading) and not m.true and m.heading_deg == 45.0
        g = NmeaDecoder("x").parse_frame(encode_hdg(100.0, -2.0, 3.5).encode())
        assert isinstance(g, Heading) and not g.true and g.heading_deg == 100.0
        assert (g.deviation_deg, g.variation_deg) == (-2.0, 3.5)

    def test_bad_mode_refused(self) -> None:
        """A mode indicator must be one letter."""
        with pytest.raises(ValueError, match="mode"):
            encode_rmc(self.T, 1.0, 0.0, mode="AA")


def test_position_minutes_that_round_to_sixty_carry_into_the_degree() -> None:
    """A longitude a hair under 2° is written 00200.0000, not the invalid 00160.0000."""
    t = datetime(2026, 1, 1, tzinfo=UTC)
    s = encode_rmc(t, 1.0, 0.0, lat_deg=45.99999999999, lon_deg=1.9999999999999964)
    assert ",4600.0000,N,00200.0000,E," in s
    r = NmeaDecoder("x").parse_frame(s.encode())
    assert isinstance(r, Rmc) and r.lon_deg == pytest.approx(2.0)
