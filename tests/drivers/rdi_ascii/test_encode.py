"""The PD6 encoder: TRDI widths, the invalid marker, the earth frame turned by the heading."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest

from drivers.rdi_ascii.encode import encode_pd6

TS = datetime(2025, 6, 12, 8, 0, 1, 230000, tzinfo=UTC)


def test_the_lines_are_sent_in_order_at_trdi_widths() -> None:
    """Without water track the encoder sends :SA :TS :BI :BS :BE :BD, velocities as signed
    mm/s five digits wide with status A, the time to the hundredth of a second."""
    lines = encode_pd6(
        timestamp=TS, heading_deg=90.0, bottom_ship_mps=(0.1, 1.5, 0.0), range_m=25.3
    )
    assert [line[1:3] for line in lines] == ["SA", "TS", "BI", "BS", "BE", "BD"]
    assert lines[0] == ":SA,+00.00,+00.00,090.00"
    assert lines[1].startswith(":TS,25061208000123,35.0,+15.0,")
    assert lines[3] == ":BS,+00100,+01500,+00000,A"
    assert lines[5] == ":BD,+0000000.00,+0000000.00,+0000000.00,0025.30,000.00"


def test_no_bottom_lock_sends_the_invalid_marker() -> None:
    """A missing bottom track is sent as -32768 in every component with status V."""
    lines = encode_pd6(timestamp=TS, heading_deg=0.0)
    bs = next(line for line in lines if line.startswith(":BS"))
    assert bs == ":BS,-32768,-32768,-32768,V"


@pytest.mark.parametrize("heading", [0.0, 30.0, 90.0, 200.0])
def test_the_earth_frame_is_the_ship_frame_turned_by_the_heading(heading: float) -> None:
    """:BE and :WE are the ship-frame vector turned by the heading (east, north, up), the water
    lines sent when a water track is given."""
    t, lo = 0.2, 1.5
    lines = encode_pd6(
        timestamp=TS, heading_deg=heading, bottom_ship_mps=(t, lo, 0.0), water_ship_mps=(t, lo, 0.0)
    )
    psi = math.radians(heading)
    east = lo * math.sin(psi) + t * math.cos(psi)
    north = lo * math.cos(psi) - t * math.sin(psi)
    for kind in ("BE", "WE"):
        fields = next(line for line in lines if line.startswith(f":{kind}")).split(",")
        assert int(fields[1]) == round(east * 1000)
        assert int(fields[2]) == round(north * 1000)
