"""NMEA 0183 decoder: VHW/VBW units and validity, rejects, checksum and length policies, streams."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.base import DecoderOptions
from drivers.errors import ChecksumError, FieldError, OutOfRangeError, UnknownSentenceError
from drivers.framing import with_checksum
from drivers.nmea0183 import Heading, NmeaDecoder, NmeaRecord, Vbw, Vhw, encode_vbw, encode_vhw
from drivers.records import KMH_MPS, KNOT_MPS, Rejected
from tests.chunks import feed_in_chunks
from tests.profiles import by_profile


def _parse(body: str) -> NmeaRecord:
    return NmeaDecoder("x").parse_frame(with_checksum(body).encode())


def _feed_all(data: bytes, **kw: object) -> tuple[list[object], NmeaDecoder]:
    dec = NmeaDecoder("x", errors="yield", **kw)  # type: ignore[arg-type]
    return list(dec.decode_all(data)), dec


def test_vhw_units_and_disagreement() -> None:
    """VHW speed is taken from knots, else km/h, a knots/km/h pair that disagrees beyond rounding
    is refused as out of range (5 kn vs 50 km/h, 3.5 kn vs 9 km/h) while one within rounding is
    read, astern stays negative, and the speed record carries port, stw, role speed, VHW and the
    true and magnetic headings apart."""
    r = _parse("VWVHW,,T,,M,3.50,N,6.48,K")
    assert isinstance(r, Vhw) and r.stw_mps == pytest.approx(3.5 * KNOT_MPS)
    r = _parse("VWVHW,,T,,M,,N,6.48,K")
    assert isinstance(r, Vhw) and r.stw_mps == pytest.approx(6.48 * KMH_MPS)
    r = _parse("VWVHW,,T,,M,5,N,9,K")  # 9.26 km/h sent with no decimals: within rounding
    assert isinstance(r, Vhw) and r.stw_mps == pytest.approx(5 * KNOT_MPS)
    for body in ("VWVHW,,T,,M,3.50,N,9.00,K", "VWVHW,,T,,M,5.0,N,50.0,K"):
        with pytest.raises(OutOfRangeError, match="disagree"):
            _parse(body)
    r = _parse("VWVHW,,T,,M,-1.2,N,-2.2,K")  # astern
    assert isinstance(r, Vhw) and r.stw_mps == pytest.approx(-1.2 * KNOT_MPS)
    (sp,) = NmeaDecoder("p").speed_records(_parse("VWVHW,10,T,12,M,2,N,3.7,K"))
    assert (
        sp.port,
        sp.kind,
        sp.role,
        sp.source,
        sp.heading_true_deg,
        sp.heading_mag_deg,
        sp.valid,
    ) == ("p", "stw", "speed", "VHW", 10.0, 12.0, True)


def test_vbw_water_pair_valid_even_when_ground_is_v() -> None:
    """A VBW whose water pair is A but ground pair V yields one valid stw record, and one whose
    water pair is V but ground pair A yields an invalid stw and a valid VBW:G sog record."""
    r = _parse("VMVBW,2.0,-0.3,A,,,V")
    assert isinstance(r, Vbw) and r.water_valid and not r.ground_valid
    sps = NmeaDecoder("p").speed_records(r)
    assert len(sps) == 1 and sps[0].source == "VBW" and sps[0].valid
    assert sps[0].transverse_mps == pytest.approx(-0.3 * KNOT_MPS)
    both = NmeaDecoder("p").speed_records(_parse("VMVBW,2.0,0.1,V,2.1,0.2,A"))
    assert [(s.source, s.kind, s.role, s.valid) for s in both] == [
        ("VBW", "stw", "speed", False),
        ("VBW:G", "sog", "ground", True),
    ]


@pytest.mark.parametrize(
    ("body", "error"),
    [
        ("VWVHW,x,T,,M,3.5,N,,K", FieldError),
        ("VWVHW,,T,,M,3.5,N,,K,extra", FieldError),
        ("VWVHW,,Q,,M,3.5,N,,K", FieldError),
        ("VWVHW,400,T,,M,3.5,N,,K", OutOfRangeError),
        ("VWVHW,,T,,M,100,N,,K", OutOfRangeError),
        ("VWVHW,,T,,M,nan,N,,K", FieldError),
        ("VWVHW,,T,,M,1_0,N,,K", FieldError),
        ("VMVBW,1,2,B,,,V", FieldError),
        ("VMVBW,1,2,A", FieldError),
        ("VWMTW,99,C", OutOfRangeError),
        ("VWVLW,-1,N,2,N", OutOfRangeError),
        ("GPGGA,1,2,3", FieldError),
        ("GPGSV,1,1,00", UnknownSentenceError),
        ("PXYZ,1", UnknownSentenceError),
        ("VW,1", FieldError),
        ("VWVHW", FieldError),
        ("PRTI01,1,2,x,0,0,0,0,,,,,0000", FieldError),
        ("HCHDG,10.0,1e308,E,1e308,E", OutOfRangeError),
        ("HCHDG,10.0,180.1,E,,", OutOfRangeError),
        ("HCHDG,10.0,,,181,W", OutOfRangeError),
        ("HCHDG,-0.1,,,,", OutOfRangeError),
        ("HEHDT,360.1,T", OutOfRangeError),
        ("VWVDR,,T,,M,-1,N", OutOfRangeError),
        ("GPRMC,120000,A,,,,,1.0,,010125,180.5,E,A", OutOfRangeError),
        ("GPGGA,120000,,,,,12,05,1.0,,M,,M,,", OutOfRangeError),
        ("GPGGA,120000,,,,,1,05,150,,M,,M,,", OutOfRangeError),
        ("PRTI01,100,2,9000,0,0,0,0,,,,,0000", OutOfRangeError),
        ("PRTI01,100,2,1500,0,0,0,-5,,,,,0000", OutOfRangeError),
        ("GPZDA,000003.00,4294967296,01,2026,00,00", OutOfRangeError),
        ("GPZDA,235960.50,31,12,9999,00,00", OutOfRangeError),
    ],
)
def test_field_errors(body: str, error: type[Exception]) -> None:
    """Each malformed, out-of-range, unknown or wrongly sized sentence raises its specific decoder
    error."""
    with pytest.raises(error):
        _parse(body)


def test_ranges_at_their_limits_are_read() -> None:
    """Deviation and variation of exactly ±180 are read, and a heading sent as 360 is read as 0
    (directions come out in [0, 360))."""
    r = _parse("HCHDG,360.0,180.0,W,180.0,E")
    assert isinstance(r, Heading)
    assert (r.heading_deg, r.deviation_deg, r.variation_deg) == (0.0, -180.0, 180.0)
    r = _parse("VWVHW,360.0,T,359.9,M,3.50,N,6.48,K")
    assert isinstance(r, Vhw) and (r.heading_true_deg, r.heading_mag_deg) == (0.0, 359.9)


def test_an_unforeseen_exception_is_an_internal_reject(monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame whose parsing fails with an exception that is no FrameError is counted as an
    internal reject naming the exception, and the next frame of the chunk is still decoded."""
    import drivers.nmea0183.decoder as nmea

    def boom(*args: object) -> object:
        raise ValueError("math domain error")

    monkeypatch.setattr(nmea, "parse_vhw", boom)
    data = (with_checksum("VWVHW,,T,,M,3.5,N,,K") + "\r\n").encode()
    data += (with_checksum("VMVBW,1,2,A,,,V") + "\r\n").encode()
    out, dec = _feed_all(data)
    assert isinstance(out[0], Rejected) and out[0].reason == "internal"
    assert "ValueError: math domain error" in out[0].detail
    assert isinstance(out[1], Vbw)
    assert dec.counters.rejects["internal"] == 1 and dec.counters.records == 1


def test_checksum_policies_and_counters() -> None:
    """By default a missing checksum, a wrong checksum and a line without a start character are each
    rejected and counted, and with checksum optional only the unchecksummed VHW is let through."""
    good = encode_vhw(2.0) + "\r\n"
    data = (
        good
        + "$VWVHW,,T,,M,3.50,N,6.48,K\r\n"
        + good[:-4]
        + ("00" if not good.endswith("*00\r\n") else "11")
        + "\r\n"
        + "x" * 100
        + "\r\n"
    ).encode()
    out, dec = _feed_all(data)
    assert [type(r).__name__ for r in out] == ["Vhw", "Rejected", "Rejected", "Rejected"]
    assert dec.counters.rejects["missing_checksum"] == 1
    assert dec.counters.rejects["checksum"] == 1
    assert dec.counters.rejects["framing"] == 1
    assert dec.counters.records == 1
    out, dec = _feed_all(data, options=DecoderOptions(checksum="optional"))
    assert sum(isinstance(r, Vhw) for r in out) == 2  # the wrong checksum is still rejected
    assert dec.counters.rejects["checksum"] == 1


def test_length_limit_and_leniency() -> None:
    """A sentence over 82 characters is rejected as too_long unless the port's max_length allows
    it."""
    long = with_checksum(
        "VWVHW,,T,,M,3.50000000000000000000000000000000000000000000000000000000000,N,,K"
    )
    out, _ = _feed_all((long + "\r\n").encode())
    assert isinstance(out[0], Rejected) and out[0].reason == "too_long"
    out, _ = _feed_all((long + "\r\n").encode(), options=DecoderOptions(max_length=200))
    assert isinstance(out[0], Vhw)


def test_raise_mode_keeps_the_rest_of_the_chunk() -> None:
    """In raise mode a bad sentence raises and the good sentence after it in the same chunk comes
    out on the next feed."""
    dec = NmeaDecoder("x")
    data = ("$VWVHW,1*00\r\n" + encode_vhw(1.0) + "\r\n").encode()
    with pytest.raises(ChecksumError):
        list(dec.feed(data))
    assert [type(r).__name__ for r in dec.feed(b"")] == ["Vhw"]


def test_ais_is_an_unknown_sentence() -> None:
    """A correctly checksummed AIS sentence (!AIVDM) is rejected as unknown_sentence."""
    out, _ = _feed_all(b"!AIVDM,1,1,,A,13aI8e?P00PGpU:NR6s00?vT2000,0,0*6C\r\n")
    assert isinstance(out[0], Rejected)
    assert out[0].reason == "unknown_sentence"


STREAM = (
    encode_vhw(2.0) + "\r\n" + encode_vbw(1.0, 0.1) + "\n" + "$GPGGA,bad\r\n"
    + encode_vhw(2.5, heading_true_deg=90) + "\r" + "junk$VWVHW,1,2\r\n" + encode_vbw(0.5, 0.0) + "\r\n"
).encode()  # fmt: skip


@settings(max_examples=200, deadline=None)
@given(cuts=st.lists(st.integers(0, len(STREAM)), max_size=15))
def test_chunk_boundaries_do_not_matter(cuts: list[int]) -> None:
    """A stream mixing good, bad and spliced sentences decodes the same however it is cut into
    chunks."""
    whole, _ = _feed_all(STREAM)
    assert feed_in_chunks(NmeaDecoder("x", errors="yield"), STREAM, cuts) == whole


def test_byte_at_a_time() -> None:
    """The mixed stream fed one byte at a time decodes the same as fed whole."""
    whole, _ = _feed_all(STREAM)
    dec = NmeaDecoder("x", errors="yield")
    out = [r for b in STREAM for r in dec.feed(bytes([b]))] + list(dec.flush())
    assert out == whole


GOOD = (encode_vbw(1.234, -0.567) + "\r\n").encode()


def _flip(pos: int, value: int) -> None:
    data = bytearray(GOOD)
    pos %= len(data) - 2  # leave the terminator alone
    if data[pos] == value:
        return
    data[pos] = value
    out, _ = _feed_all(bytes(data))
    original = NmeaDecoder("x").decode_all(GOOD)[0]
    for r in out:
        assert isinstance(r, Rejected) or r == original


@pytest.mark.fuzz
@settings(max_examples=by_profile(500), deadline=None)
@given(pos=st.integers(0, 200), value=st.integers(0, 255))
def test_a_corrupted_sentence_never_yields_a_wrong_record(pos: int, value: int) -> None:
    """A VBW with any one byte changed is rejected or decodes to the original record, never to a
    different one."""
    _flip(pos, value)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.sampled_from(
            [encode_vhw(1.5), encode_vbw(1.0, 0.2), "$VWVHW", "\r\n", "\n", "$", "*", ",,,", "x"]
        ),
        max_size=30,
    )
)
def test_spliced_and_truncated_frames(parts: list[str]) -> None:
    """Any splice of good sentences, bare addresses and stray characters yields only rejects or the
    original records, and every output is counted once."""
    dec = NmeaDecoder("x", errors="yield")
    out = dec.decode_all("".join(parts).encode())
    good = {
        NmeaDecoder("x").parse_frame(s.encode()) for s in (encode_vhw(1.5), encode_vbw(1.0, 0.2))
    }
    for r in out:
        assert isinstance(r, Rejected) or r in good
    assert dec.counters.records + dec.counters.rejected == len(out)
