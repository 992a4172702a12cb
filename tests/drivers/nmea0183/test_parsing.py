"""NMEA 0183 GNSS and heading sentences as instruments send them, and malformed ones refused.

Real sentences below are from the yacht Irene's log on Lake Geneva (2014-06-27), published
in the jpilet/anemomind repository under the MIT licence (© Anemomind SàRL).
"""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from drivers.errors import FieldError, OutOfRangeError, UnknownSentenceError
from drivers.framing import with_checksum
from drivers.nmea0183 import (
    Heading,
    Mtw,
    NmeaDecoder,
    Rmc,
    Vhw,
    Vlw,
)
from drivers.records import KNOT_MPS

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


@pytest.mark.parametrize(
    "body",
    [
        "VWVLW,12 .5,N,3.0,N",
        "VWVLW,12.5,N,3_0,N",
        "IIMTW, 17.9,C",
        "HEHDT,1_80.0,T",
        "HCHDM,nan,M",
        "HCHDG,100.0,,,1 .3,E",
        "HCHDG,100.0,2.0,W,inf,E",
    ],
)
def test_distances_temperatures_and_headings_follow_the_number_rule(body: str) -> None:
    """A VLW, MTW or HDx number with a blank, an underscore, or no finite value is a bad field,
    as in VHW and VBW (Python's float would read the first two)."""
    with pytest.raises(FieldError, match="is not a number"):
        _parse(body)


@pytest.mark.parametrize(
    ("body", "heading"),
    [
        ("GPTHS,123.4,A", 123.4),
        ("INTHS,359.9,E", 359.9),
        ("HETHS,12.0,M", 12.0),
        ("GPTHS,123.4,V", None),
        ("GPTHS,123.4,S", None),
        ("GPTHS,,A", None),
    ],
)
def test_ths_is_a_true_heading_in_a_valid_mode(body: str, heading: float | None) -> None:
    """THS (a GNSS compass's true heading): the heading in modes A, E and M, none when the
    sender says it is simulated or not valid."""
    r = _parse(body)
    assert isinstance(r, Heading) and r.true and r.sentence == "THS"
    assert r.heading_deg == heading


@pytest.mark.parametrize("body", ["GPTHS,123.4,X", "GPTHS,123.4", "GPTHS,400.0,A"])
def test_ths_with_a_bad_mode_field_count_or_heading_is_refused(body: str) -> None:
    """An unknown mode letter, a missing field, a heading past 360: rejects, no record."""
    with pytest.raises(FieldError):
        _parse(body)


@pytest.mark.parametrize(
    ("body", "heading"),
    [
        ("PASHR,085335.000,224.19,T,-01.26,+00.83,+00.00,0.101,0.113,0.267,1,0", 224.19),
        ("PASHR,085335.000,,T,-01.26,+00.83,+00.00,0.101,0.113,0.267,0,0", None),
        ("PASHR,ATT,085335.0,224.19,-0.83,1.26,0.003,0.004,0", 224.19),
    ],
)
def test_pashr_is_a_true_heading(body: str, heading: float | None) -> None:
    """$PASHR (an INS's or a GNSS compass's attitude, and Ashtech's ATT): its heading,
    true."""
    r = _parse(body)
    assert isinstance(r, Heading) and r.true and r.sentence == "PASHR"
    assert r.heading_deg == heading


@pytest.mark.parametrize(
    ("body", "error"),
    [
        ("PASHR,POS,0,07,085335.00,4613.35,N,00610.28,E", UnknownSentenceError),
        ("PASHR,085335.000,224.19,M,-01.26,+00.83,+00.00,0.101,0.113,0.267,1,0", FieldError),
        ("PASHR,085335.000,224.19,T,-01.26", FieldError),
        ("PASHR,ATT,085335.0,400.0,-0.83,1.26,0.003,0.004,0", FieldError),
    ],
)
def test_other_pashr_forms_are_refused(body: str, error: type[Exception]) -> None:
    """Another $PASHR form is not decoded; a magnetic flag, a short sentence or a
    heading past 360 are rejects."""
    with pytest.raises(error):
        _parse(body)


def test_distances_temperatures_and_headings_are_read() -> None:
    """VLW's four distances, MTW's temperature, HDT's true and HDM's magnetic heading and HDG's
    deviation and variation with their E/W sign are read from their fields."""
    r = _parse("VWVLW,1109.4,N,54.6,N,1110.0,N,55.1,N")
    assert isinstance(r, Vlw)
    assert (r.total_nm, r.trip_nm, r.ground_total_nm, r.ground_trip_nm) == (
        1109.4,
        54.6,
        1110.0,
        55.1,
    )
    r = _parse("VWVLW,,N,54.6,N")
    assert isinstance(r, Vlw) and (r.total_nm, r.trip_nm, r.ground_total_nm) == (None, 54.6, None)
    r = _parse("IIMTW,-1.5,C")
    assert isinstance(r, Mtw) and r.temperature_c == -1.5
    r = _parse("HEHDT,359.9,T")
    assert isinstance(r, Heading) and r.true and r.heading_deg == 359.9
    r = _parse("HCHDM,12.0,M")
    assert isinstance(r, Heading) and not r.true and r.heading_deg == 12.0
    r = _parse("HCHDG,100.0,2.0,W,3.5,E")
    assert isinstance(r, Heading) and (r.deviation_deg, r.variation_deg) == (-2.0, 3.5)
    with pytest.raises(OutOfRangeError):
        _parse("VWVLW,-1.0,N,54.6,N")


@pytest.mark.parametrize(
    ("body", "tod", "active", "valid"),
    [
        ("IIGLL,4613.353,N,00610.289,E,132220,A,A", 48140.0, True, True),  # Irene's, 2.3
        ("GPGLL,4613.353,N,00610.289,E,132220.50,A", 48140.5, True, True),  # 2.0
        ("GPGLL,4613.353,N,00610.289,E,132220,V,N", 48140.0, False, False),  # void
        ("GPGLL,4613.353,N,00610.289,E,132220,A,N", 48140.0, True, False),  # not valid mode
        ("GPGLL,4613.353,N,00610.289,E", None, True, True),  # 1.5: no time
    ],
)
def test_gll_gives_its_time_of_day_and_status(
    body: str, tod: float | None, active: bool, valid: bool
) -> None:
    """GLL (parsed for the import's timing, not yielded by the decoder): its position,
    time of day, status and mode."""
    from drivers.nmea0183 import parse_gll

    raw = with_checksum(body).encode("ascii")
    rec = parse_gll(body[:2], body.split(",")[1:], raw)
    assert rec.time_of_day_s == tod and rec.status_active is active and rec.valid is valid
    assert rec.lat_deg == pytest.approx(46 + 13.353 / 60)
    assert rec.lon_deg == pytest.approx(6 + 10.289 / 60)
    with pytest.raises(UnknownSentenceError, match="GLL not decoded"):
        NmeaDecoder("n").decode_all(raw + b"\r\n")


@pytest.mark.parametrize(
    "body",
    [
        "GPGLL,4613.353,N,00610.289,E,132220",  # 5 fields
        "GPGLL,4613.353,N,00610.289,E,132220,X",  # bad status
        "GPGLL,4613.353,N,00610.289,E,256000,A",  # bad time
        "GPGLL,4613.353,Q,00610.289,E,132220,A",  # bad hemisphere
    ],
)
def test_a_malformed_gll_is_refused(body: str) -> None:
    """A GLL of another field count, status, time or hemisphere raises its reason."""
    from drivers.nmea0183 import parse_gll

    with pytest.raises((FieldError, OutOfRangeError)):
        parse_gll(body[:2], body.split(",")[1:], body.encode("ascii"))


@pytest.mark.parametrize(
    ("body", "variation"),
    [
        ("GPRMC,132220,A,4613.353,N,00610.289,E,01.9,238,270614,2.5,W,A", -2.5),
        ("GPRMC,132220,A,4613.353,N,00610.289,E,01.9,238,270614,-2.5,,A", -2.5),
        ("HCHDG,263,,,-2.5,", -2.5),
        ("HCHDG,263,,,2.5,W", -2.5),
    ],
)
def test_a_variation_written_signed_without_its_direction(body: str, variation: float) -> None:
    """A variation signed (west negative) with its E/W field empty reads as the signed
    value, as ``2.5,W`` does."""
    (rec,) = NmeaDecoder("n").decode_all(with_checksum(body).encode("ascii") + b"\r\n")
    assert getattr(rec, "variation_deg", None) == variation
