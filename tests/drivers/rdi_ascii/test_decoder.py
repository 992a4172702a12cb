"""PD6/PD13 decoder: the TRDI manual example, ensemble assembly, invalid markers, sign, round trip."""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import FrameError, RejectReason
from drivers.rdi_ascii import Pd6Ensemble, PdAsciiDecoder, PdHealth, encode_pd6
from drivers.records import Rejected
from tests.chunks import feed_in_chunks
from tests.profiles import by_profile

EXAMPLE = (
    Path(__file__).resolve().parents[2] / "data" / "dvl" / "trdi_pathfinder_guide_pd13_example.txt"
)
TS = datetime(2025, 6, 12, 8, 0, 1, 230000, tzinfo=UTC)


def _lines(**kw: object) -> bytes:
    args: dict[str, object] = {
        "timestamp": TS,
        "heading_deg": 90.0,
        "bottom_ship_mps": (0.1, 1.5, 0.0),
        "range_m": 25.3,
    }
    args.update(kw)
    return "".join(x + "\r\n" for x in encode_pd6(**args)).encode()  # type: ignore[arg-type]


def test_manual_pd13_example() -> None:
    """The TRDI manual's PD13 example decodes to its attitude, timestamp, environment, beam ranges,
    bottom track and no water track, and its speed record takes :BS as vessel motion with the
    heading."""
    dec = PdAsciiDecoder("dvl", errors="yield")
    (e,) = dec.decode_all(EXAMPLE.read_bytes())
    assert isinstance(e, Pd6Ensemble)
    assert (e.pitch_deg, e.roll_deg, e.heading_deg) == (-2.31, 1.92, 75.2)
    assert e.timestamp == "04081111563644"
    assert (e.salinity_ppt, e.temperature_c, e.depth_m, e.sound_speed_mps, e.bit) == (
        35.0,
        21.0,
        0.0,
        1524.0,
        0,
    )
    assert e.pressure_kpa == 0.0
    assert e.beam_ranges_m == pytest.approx((7.131, 7.132, 7.132, 7.131))
    assert e.water_ship is None and e.water_earth is None  # -32768, V
    assert e.bottom_instrument is not None and e.bottom_instrument.error == pytest.approx(-0.004)
    assert e.bottom_ship is not None
    assert (e.bottom_ship.a, e.bottom_ship.b, e.bottom_ship.c) == (-0.013, 0.021, -0.02)
    assert e.bottom_earth is not None and (e.bottom_earth.a, e.bottom_earth.b) == (0.017, 0.018)
    assert e.bottom_range_m == 7.13
    (sp,) = dec.speed_records(e)
    # PD6 :BS is the vessel's motion: longitudinal = L, transverse = T, no sign change
    assert (sp.longitudinal_mps, sp.transverse_mps, sp.source, sp.kind) == (
        0.021,
        -0.013,
        "PD6:BS",
        "sog",
    )
    assert (sp.role, sp.heading_true_deg, sp.heading_mag_deg) == ("bottom", 75.2, None)


def test_round_trip_and_water_track() -> None:
    """An encoded PD6 ensemble with water track decodes to its bottom ship and earth velocities and
    timestamp, and gives a PD6:BS then a PD6:WS stw record."""
    dec = PdAsciiDecoder("dvl")
    (e,) = dec.decode_all(_lines(water_ship_mps=(0.05, 1.4, 0.0)))
    assert isinstance(e, Pd6Ensemble)
    assert e.bottom_ship is not None and (e.bottom_ship.a, e.bottom_ship.b) == (0.1, 1.5)
    assert (
        e.bottom_earth is not None
        and e.bottom_earth.a == pytest.approx(1.5)
        and e.bottom_earth.b == pytest.approx(-0.1)
    )
    assert e.timestamp == "25061208000123"
    sps = dec.speed_records(e)
    assert [(s.source, s.role) for s in sps] == [("PD6:BS", "bottom"), ("PD6:WS", "water")]
    assert sps[1].kind == "stw" and sps[1].longitudinal_mps == 1.4


def test_no_bottom_lock() -> None:
    """An ensemble without bottom lock has no bottom velocities and gives an invalid speed
    record."""
    dec = PdAsciiDecoder("dvl")
    (e,) = dec.decode_all(_lines(bottom_ship_mps=None, range_m=None))
    assert isinstance(e, Pd6Ensemble) and e.bottom_ship is None and e.bottom_earth is None
    (sp,) = dec.speed_records(e)
    assert not sp.valid and sp.longitudinal_mps is None


def test_a_bad_line_discards_the_block_and_is_counted_twice() -> None:
    """A bad field discards its ensemble with a bad_field reject plus a framing reject for the torn
    block, and the next ensemble still decodes."""
    block = _lines().replace(b":BS,+00100", b":BS,+0x100")
    dec = PdAsciiDecoder("dvl", errors="yield")
    out = dec.decode_all(block + _lines())
    assert sum(isinstance(r, Pd6Ensemble) for r in out) == 1
    reasons = sorted(r.reason for r in out if isinstance(r, Rejected))
    assert reasons == ["bad_field", "framing"]


@pytest.mark.parametrize(
    ("mangle", "reason"),
    [
        (lambda b: b.replace(b":BS", b":BS,1"), "bad_field"),  # field count
        (lambda b: b.replace(b",A\r\n:BE", b",Q\r\n:BE"), "bad_field"),  # status letter
        (
            lambda b: b.replace(b":SA,+00.00,+00.00,090.00", b":SA,+00.00,+00.00,490.00"),
            "out_of_range",
        ),
        (lambda b: b.replace(b":TS,25061208000123", b":TS,2506120800012"), "bad_field"),
        (lambda b: b.replace(b":BI", b":XX"), "unknown_sentence"),
        (lambda b: b.replace(b":TS,25061208000123", b":TS,25136108000123"), "out_of_range"),
        (lambda b: b.replace(b"+15.0,0000.0", b"+15.0,-010.0"), "out_of_range"),
        (lambda b: b.replace(b":SA,+00.00,+00.00", b":SA,+95.00,+00.00"), "out_of_range"),
    ],
)
def test_line_validation(mangle: Callable[[bytes], bytes], reason: RejectReason) -> None:
    """A wrong field count, status letter, out-of-range heading, short timestamp, unknown line id,
    impossible month, negative depth or pitch beyond 90° discards the ensemble with one reject of
    the matching reason."""
    dec = PdAsciiDecoder("dvl", errors="yield")
    out = dec.decode_all(mangle(_lines()))
    assert not any(isinstance(r, Pd6Ensemble) for r in out)
    assert dec.counters.rejects[reason] == 1


def test_missing_and_out_of_order_lines() -> None:
    """A block missing its last line is one framing reject and the next ensemble decodes, lines out
    of order give no ensemble, and a line outside an ensemble is a framing reject."""
    lines = _lines().split(b"\r\n")
    no_bd = b"\r\n".join(lines[:-2]) + b"\r\n"
    dec = PdAsciiDecoder("dvl", errors="yield")
    out = dec.decode_all(no_bd + _lines())
    assert sum(isinstance(r, Pd6Ensemble) for r in out) == 1  # the next :SA discards the torn block
    assert dec.counters.rejects["framing"] == 1
    swapped = b"\r\n".join([lines[0], lines[1], lines[3], lines[2], *lines[4:]])
    dec = PdAsciiDecoder("dvl", errors="yield")
    assert not any(isinstance(r, Pd6Ensemble) for r in dec.decode_all(swapped))
    dec = PdAsciiDecoder("dvl", errors="yield")
    dec.decode_all(b":BS,+00001,+00002,+00003,A\r\n")
    assert dec.counters.rejects["framing"] == 1  # a line outside an ensemble


def test_parse_frame_takes_a_whole_block() -> None:
    """parse_frame decodes a whole ensemble block (or an :HM line) into the record feed gives,
    rejects a partial or double block, and leaves the decoder's own half block alone."""
    block = EXAMPLE.read_bytes().rstrip(b"\r\n")
    dec = PdAsciiDecoder("dvl", errors="raise")
    fed = PdAsciiDecoder("dvl").decode_all(block + b"\r\n")
    assert dec.parse_frame(block) == fed[0] and isinstance(fed[0], Pd6Ensemble)
    assert dec.parse_frame(b":HM,1,2") == PdHealth(("1", "2"))
    head, _, tail = _lines().partition(b":BS")
    with pytest.raises(FrameError, match="no :BD"):
        dec.parse_frame(head.rstrip(b"\r\n"))
    with pytest.raises(FrameError, match="2 records"):
        dec.parse_frame(block + b"\r\n" + block)
    assert list(dec.feed(head)) == []
    dec.parse_frame(block)
    (done,) = dec.feed(b":BS" + tail)
    assert isinstance(done, Pd6Ensemble) and done.heading_deg == 90.0
    assert dec.counters.records == 1 and dec.counters.rejected == 0


def test_pathfinder_health_line() -> None:
    """A Pathfinder :HM line after an ensemble comes out as a PdHealth record holding its fields."""
    dec = PdAsciiDecoder("dvl")
    out = dec.decode_all(_lines() + b":HM,G,G,0000,0000,12.345,1.234,10.000\r\n")
    assert isinstance(out[0], Pd6Ensemble) and isinstance(out[1], PdHealth)
    assert out[1].fields[0] == "G"


@settings(max_examples=200, deadline=None)
@given(
    t=st.floats(-10, 10),
    l_=st.floats(-10, 10),
    heading=st.floats(0, 359.99),
    cuts=st.lists(st.integers(0, 400), max_size=8),
)
def test_round_trip_any_chunking(t: float, l_: float, heading: float, cuts: list[int]) -> None:
    """Any bottom velocity and heading survive encoding and decoding within the format's rounding
    however the bytes are chunked."""
    data = _lines(bottom_ship_mps=(t, l_, 0.0), heading_deg=heading)
    dec = PdAsciiDecoder("dvl")
    out = feed_in_chunks(dec, data, cuts)
    (e,) = out
    assert isinstance(e, Pd6Ensemble) and e.bottom_ship is not None
    assert e.bottom_ship.a == pytest.approx(t, abs=6e-4) and e.bottom_ship.b == pytest.approx(
        l_, abs=6e-4
    )


@pytest.mark.fuzz
@settings(max_examples=by_profile(300), deadline=None)
@given(pos=st.integers(0, 400), value=st.integers(0, 255))
def test_a_corrupted_byte_never_yields_a_wrong_ensemble(pos: int, value: int) -> None:
    """One changed byte never yields an ensemble whose time or bottom-track speed (what the
    calibration uses) differs from the original, unless the new byte is a digit, a sign or
    a leading blank (PD6 has no checksum to catch those); a flipped status may only lose it."""
    data = bytearray(_lines())
    original = PdAsciiDecoder("dvl").decode_all(bytes(data))[0]
    assert isinstance(original, Pd6Ensemble)
    pos %= len(data)
    if data[pos] == value:
        return
    data[pos] = value
    for r in PdAsciiDecoder("dvl", errors="skip").decode_all(bytes(data)):
        # a digit changed inside a number is undetectable without a checksum (PD6 has
        # none); anything structural must not produce an ensemble with other fields
        if isinstance(r, Pd6Ensemble) and not (chr(value).isdigit() or chr(value) in "+- "):
            assert r.timestamp == original.timestamp
            assert r.bottom_ship in (original.bottom_ship, None)


@pytest.mark.parametrize("value", [ord(c) for c in "_e.E,:\r\nAVx\t"] + [0, 0xFF])
def test_every_position_corrupted_by_a_structural_byte(value: int) -> None:
    """At every position of an ensemble, a byte that is not a digit, a sign or a blank never
    changes its time or bottom-track speed (underscores, exponents and trailing blanks are
    not numbers)."""
    for pos in range(len(_lines())):
        test_a_corrupted_byte_never_yields_a_wrong_ensemble.hypothesis.inner_test(pos, value)


def test_an_unforeseen_exception_is_an_internal_reject(monkeypatch: pytest.MonkeyPatch) -> None:
    """A line whose parsing fails with an exception that is no FrameError discards its ensemble
    with an internal reject naming the exception, and the next ensemble still decodes."""
    import drivers.rdi_ascii.decoder as pd6
    from drivers.rdi_ascii.parse import _parse_line as real

    calls = [0]

    def boom(frame: bytes) -> tuple[str, object]:
        calls[0] += 1
        if calls[0] == 3:
            raise ZeroDivisionError("division by zero")
        return real(frame)

    monkeypatch.setattr(pd6, "_parse_line", boom)
    dec = PdAsciiDecoder("dvl", errors="yield")
    out = dec.decode_all(_lines() + _lines())
    assert sum(isinstance(r, Pd6Ensemble) for r in out) == 1
    internal = [r for r in out if isinstance(r, Rejected) and r.reason == "internal"]
    assert len(internal) == 1 and "ZeroDivisionError" in internal[0].detail
    assert dec.counters.rejects["internal"] == 1
