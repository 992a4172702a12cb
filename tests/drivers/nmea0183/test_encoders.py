"""NMEA 0183 encoders: what they write fits a sentence and decodes back to the values given."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.nmea0183 import (
    NmeaDecoder,
    Rmc,
    Vbw,
    Vhw,
    encode_rmc,
    encode_vbw,
    encode_vhw,
)
from drivers.records import KNOT_MPS


def test_encoders() -> None:
    """encode_vhw wraps headings into 0..360, keeps knots and km/h consistent, never prints -0.00
    and refuses NaN or a lowercase talker, and encode_vbw with a ground pair decodes with both pairs
    valid."""
    s = encode_vhw(2.0, heading_true_deg=361.0, heading_mag_deg=-1.0)
    r = NmeaDecoder("x").parse_frame(s.encode())
    assert isinstance(r, Vhw)
    assert r.heading_true_deg == 1.0 and r.heading_mag_deg == 359.0
    assert r.stw_kmh == pytest.approx(r.stw_knots * 1.852, abs=0.01)  # type: ignore[operator]
    assert encode_vhw(-0.0001).split(",")[5] == "0.00"  # never "-0.00"
    with pytest.raises(ValueError):
        encode_vhw(float("nan"))
    with pytest.raises(ValueError):
        encode_vhw(1.0, talker="vw")
    v = NmeaDecoder("x").parse_frame(
        encode_vbw(1.0, -0.5, ground_long_mps=1.1, ground_trans_mps=0.0, ground_valid=True).encode()
    )
    assert isinstance(v, Vbw) and v.ground_valid and v.water_valid


speeds = st.floats(min_value=-20.0, max_value=20.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    stw=speeds,
    ht=st.one_of(st.none(), st.floats(0, 359.9)),
    hm=st.one_of(st.none(), st.floats(0, 359.9)),
)
def test_vhw_round_trip(stw: float, ht: float | None, hm: float | None) -> None:
    """Any VHW encoded from a speed within ±20 m/s and optional headings fits 82 characters and
    decodes to that speed within rounding, its units agreeing."""
    s = encode_vhw(stw, heading_true_deg=ht, heading_mag_deg=hm)
    assert len(s) + 2 <= 82
    r = NmeaDecoder("x").parse_frame(s.encode())
    assert isinstance(r, Vhw)
    assert r.stw_mps == pytest.approx(stw, abs=0.006)


@settings(max_examples=300, deadline=None)
@given(lon=speeds, tr=speeds)
def test_vbw_round_trip(lon: float, tr: float) -> None:
    """Any VBW water pair within ±20 m/s fits 82 characters and decodes as valid to the same speeds
    within rounding."""
    s = encode_vbw(lon, tr)
    assert len(s) + 2 <= 82
    r = NmeaDecoder("x").parse_frame(s.encode())
    assert isinstance(r, Vbw) and r.water_valid
    assert r.water_long_mps == pytest.approx(lon, abs=0.006)
    assert r.water_trans_mps == pytest.approx(tr, abs=0.006)


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
