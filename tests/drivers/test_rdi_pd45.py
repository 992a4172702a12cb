"""PD4/PD5: layout round trip, sign convention, frames, resync (no real capture exists)."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.rdi_pd45 import Pd45Decoder, Pd45Ensemble, encode_pd45
from drivers.records import Rejected
from tests.chunks import feed_in_chunks
from tests.drivers.rdi_cases import OUT_OF_RANGE_LEADER


@pytest.mark.parametrize("pd5", [False, True])
def test_round_trip_ship_frame(pd5: bool) -> None:
    """A PD4 (47 bytes) or PD5 (88 bytes) ship-frame ensemble round-trips its velocities as vessel
    motion (X transverse, Y longitudinal), ranges, temperature, PD5's heading and its source."""
    b = encode_pd45(
        pd5=pd5, bottom_ship_mps=(1.5, -0.25), range_m=20.0, heading_deg=30.0, temperature_c=12.34
    )
    assert len(b) == (88 if pd5 else 47)
    dec = Pd45Decoder("dvl")
    (e,) = dec.decode_all(b)
    assert isinstance(e, Pd45Ensemble)
    assert e.format == ("PD5" if pd5 else "PD4")
    assert e.coord_frame == "ship"
    assert e.bottom_mms[:2] == (-250, 1500)  # X transverse, Y longitudinal, vessel motion
    assert e.bottom_range_cm == (2000,) * 4
    assert e.temperature_c == pytest.approx(12.34)
    assert e.heading_deg == (30.0 if pd5 else None)
    (sp,) = dec.speed_records(e)
    assert (sp.longitudinal_mps, sp.transverse_mps, sp.valid) == (1.5, -0.25, True)
    assert sp.source == ("PD5:BT" if pd5 else "PD4:BT")


def test_earth_frame_needs_a_heading() -> None:
    """Earth-frame velocities give an invalid speed record from PD4 (no heading) and the ship-frame
    speeds from PD5, rotated with its heading."""
    dec = Pd45Decoder("dvl")
    pd4 = dec.decode_all(encode_pd45(bottom_ship_mps=(1.0, 0.0), range_m=5, coord_frame="earth"))[0]
    assert isinstance(pd4, Pd45Ensemble)
    (sp,) = dec.speed_records(pd4)
    assert not sp.valid  # PD4 carries no heading: earth velocities cannot be rotated
    pd5 = dec.decode_all(
        encode_pd45(
            pd5=True, bottom_ship_mps=(1.0, 0.3), range_m=5, coord_frame="earth", heading_deg=77
        )
    )[0]
    assert isinstance(pd5, Pd45Ensemble)
    (sp,) = dec.speed_records(pd5)
    assert sp.valid
    assert sp.longitudinal_mps == pytest.approx(1.0, abs=2e-3)
    assert sp.transverse_mps == pytest.approx(0.3, abs=2e-3)


def test_no_bottom_lock() -> None:
    """An ensemble without bottom lock has no velocities and gives an invalid speed record."""
    dec = Pd45Decoder("dvl")
    (e,) = dec.decode_all(encode_pd45(bottom_ship_mps=None))
    assert isinstance(e, Pd45Ensemble)
    assert e.bottom_mms[0] is None and not e.bottom_lock
    (sp,) = dec.speed_records(e)
    assert not sp.valid


def test_bad_checksum_and_resync() -> None:
    """Leading junk, a corrupted frame and a stray header are rejected (one checksum, framing at
    least once) and both good frames decode."""
    good = encode_pd45(bottom_ship_mps=(1.0, 0.0), range_m=5)
    bad = bytearray(good)
    bad[10] ^= 0xFF
    dec = Pd45Decoder("dvl", errors="yield")
    out = dec.decode_all(b"junk" + bytes(bad) + good + b"\x7d\x00" + good)
    assert sum(isinstance(r, Pd45Ensemble) for r in out) == 2
    assert dec.counters.rejects["checksum"] == 1
    assert dec.counters.rejects["framing"] >= 1


def test_wrong_length_for_the_structure_is_not_a_frame() -> None:
    """A PD4 id carrying PD5's length is not decoded as a frame and is counted as rejected."""
    frame = bytearray(encode_pd45(bottom_ship_mps=(1.0, 0.0), range_m=5))
    struct.pack_into("<H", frame, 2, 86)  # PD4 id with the PD5 length
    dec = Pd45Decoder("dvl", errors="skip")
    assert dec.decode_all(bytes(frame)) == []
    assert dec.counters.rejected >= 1


@settings(max_examples=200, deadline=None)
@given(
    fwd=st.floats(-20, 20),
    stb=st.floats(-5, 5),
    pd5=st.booleans(),
    cuts=st.lists(st.integers(0, 200), max_size=8),
)
def test_round_trip_and_chunking(fwd: float, stb: float, pd5: bool, cuts: list[int]) -> None:
    """Two ensembles of any speed decode to two records however they are chunked, the longitudinal
    speed exact to the mm."""
    data = encode_pd45(pd5=pd5, bottom_ship_mps=(fwd, stb), range_m=10) * 2
    dec = Pd45Decoder("dvl")
    out = feed_in_chunks(dec, data, cuts)
    assert len(out) == 2
    assert isinstance(out[0], Pd45Ensemble)
    (sp,) = dec.speed_records(out[0])
    assert sp.longitudinal_mps == pytest.approx(round(fwd * 1000) / 1000, abs=1e-9)


@pytest.mark.parametrize("bad", [*OUT_OF_RANGE_LEADER, {"first_ping": (25, 0, 0, 0)}])
def test_an_out_of_range_field_is_a_reject(bad: dict[str, object]) -> None:
    """A PD5 ensemble whose attitude, temperature, sound speed or first-ping time is outside its
    range is an out_of_range reject, not a record; the same ensemble in range is read."""
    assert isinstance(Pd45Decoder("d").decode_all(encode_pd45(pd5=True))[0], Pd45Ensemble)
    dec = Pd45Decoder("d", errors="yield")
    (out,) = dec.decode_all(encode_pd45(pd5=True, **bad))  # type: ignore[arg-type]
    assert isinstance(out, Rejected) and out.reason == "out_of_range"
