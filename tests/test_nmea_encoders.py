"""The tests' own encoders (VTG, GGA, ZDA, HDT, HDM, HDG) write what the decoder reads back."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest

from drivers.nmea0183 import Gga, Heading, NmeaDecoder, Vtg, Zda
from tests import nmea_encoders as enc

T = datetime(2026, 11, 25, 10, 30, 15, 250000, tzinfo=UTC)


def test_vtg_gga_zda_round_trip() -> None:
    """VTG, GGA and ZDA decode back to what was encoded."""
    v = NmeaDecoder("x").parse_frame(enc.encode_vtg(3.0, 359.96, cog_mag_deg=12.0).encode())
    assert isinstance(v, Vtg) and v.sog_mps == pytest.approx(3.0, abs=0.003)
    assert v.cog_true_deg == 0.0 and v.cog_mag_deg == 12.0
    g = NmeaDecoder("x").parse_frame(enc.encode_gga(T, -33.5, 151.25, 4).encode())
    assert isinstance(g, Gga) and g.quality == 4
    assert g.lat_deg == pytest.approx(-33.5) and g.lon_deg == pytest.approx(151.25)
    z = NmeaDecoder("x").parse_frame(enc.encode_zda(T).encode())
    assert isinstance(z, Zda) and z.time_utc == T


def test_heading_sentences() -> None:
    """HDT is true, HDM magnetic, HDG carries deviation and variation with their sign."""
    t = NmeaDecoder("x").parse_frame(enc.encode_hdt(359.99).encode())
    assert isinstance(t, Heading) and t.true and t.heading_deg == 0.0
    m = NmeaDecoder("x").parse_frame(enc.encode_hdm(45.0).encode())
    assert isinstance(m, Heading) and not m.true and m.heading_deg == 45.0
    g = NmeaDecoder("x").parse_frame(enc.encode_hdg(100.0, -2.0, 3.5).encode())
    assert isinstance(g, Heading) and not g.true and g.heading_deg == 100.0
    assert (g.deviation_deg, g.variation_deg) == (-2.0, 3.5)
