"""PD6/PD13: the TRDI manual example, ensemble assembly, invalid markers, sign, round trip."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.rdi_ascii import Pd6Ensemble, PdAsciiDecoder, PdHealth, encode_pd6
from drivers.records import Rejected

EXAMPLE = (
    Path(__file__).resolve().parents[1] / "data" / "dvl" / "trdi_pathfinder_guide_pd13_example.txt"
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
    assert sp.heading_deg == 75.2


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
    assert [s.source for s in sps] == ["PD6:BS", "PD6:WS"]
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
    ],
)
def test_line_validation(mangle: object, reason: str) -> None:
    """A wrong field count, status letter, out-of-range heading, short timestamp or unknown line id
    discards the ensemble with one reject of the matching reason."""
    dec = PdAsciiDecoder("dvl", errors="yield")
    out = dec.decode_all(mangle(_lines()))  # type: ignore[operator]
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
    out: list[object] = []
    prev = 0
    for c in sorted(cuts):
        out.extend(dec.feed(data[prev:c]))
        prev = c
    out.extend(dec.feed(data[prev:]))
    out.extend(dec.flush())
    (e,) = out
    assert isinstance(e, Pd6Ensemble) and e.bottom_ship is not None
    assert e.bottom_ship.a == pytest.approx(t, abs=6e-4) and e.bottom_ship.b == pytest.approx(
        l_, abs=6e-4
    )


@settings(max_examples=300, deadline=None)
@given(pos=st.integers(0, 400), value=st.integers(0, 255))
def test_a_corrupted_byte_never_yields_a_wrong_ensemble(pos: int, value: int) -> None:
    """One changed byte never yields an ensemble with another timestamp unless the new byte is a
    digit (PD6 has no checksum to catch that)."""
    data = bytearray(_lines())
    original = PdAsciiDecoder("dvl").decode_all(bytes(data))[0]
    pos %= len(data)
    if data[pos] == value:
        return
    data[pos] = value
    for r in PdAsciiDecoder("dvl", errors="skip").decode_all(bytes(data)):
        # a digit changed inside a number is undetectable without a checksum (PD6 has
        # none); anything structural must not produce an ensemble with other fields
        if isinstance(r, Pd6Ensemble):
            assert r.timestamp == original.timestamp or chr(value).isdigit()


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=2000))
def test_random_bytes_never_raise(data: bytes) -> None:
    """Arbitrary bytes after a colon never raise in skip mode."""
    PdAsciiDecoder("dvl", errors="skip").decode_all(b":" + data)


@pytest.mark.fuzz
@settings(max_examples=100_000, deadline=None)
@given(st.binary(max_size=2000))
def test_fuzz_random_bytes(data: bytes) -> None:
    """Arbitrary bytes after a colon never raise in skip mode (fuzz run)."""
    PdAsciiDecoder("dvl", errors="skip").decode_all(b":" + data)


@pytest.mark.fuzz
@settings(max_examples=100_000, deadline=None)
@given(pos=st.integers(0, 400), value=st.integers(0, 255))
def test_fuzz_corrupted_byte(pos: int, value: int) -> None:
    """One changed byte never yields a wrong ensemble (fuzz run)."""
    test_a_corrupted_byte_never_yields_a_wrong_ensemble.hypothesis.inner_test(pos, value)  # type: ignore[attr-defined]


# The one-pattern fast path must agree with the field-by-field path on every line it
# accepts (same value) or rejects with a range error (same error); other lines fall
# through to the field-by-field path, so they need no check.
_TOKENS = [
    "", "+", "-", "0", "-0", "1", "+00123", "-01234", "-32768", "32767", "32768", "-32769",
    " 12 ", "  -7", "1.5", "+1.50", ".5", "5.", "-.5", "1e3", "1_0", "nan", "inf", "0x1",
    "\t1", "99999999", "090.00", "490.00", "1500.0", "1200.0", "35.0", "-5.1", "A", "V",
    " A ", "Q", "O", "W", "X", "25061208000123", "2506120800012", "000",
]  # fmt: skip


_NUMERIC = [t for t in _TOKENS if t.strip().lstrip("+-").replace(".", "", 1).isdigit()]
_LAYOUT = {"SA": "fff", "TS": "sffffiL", "RA": "fffff", "WD": "fffff", "BD": "fffff"}
_LAYOUT |= {k: "iiiiS" for k in ("WI", "BI")} | {k: "iiiS" for k in ("WS", "WE", "BS", "BE")}


_PLAIN = {"f": _NUMERIC, "i": _NUMERIC, "s": ["25061208000123"], "S": ["A", "V"],
          "L": ["O", "W", "X"]}  # fmt: skip


@st.composite
def _pd6_lines(draw: st.DrawFn) -> tuple[str, list[str]]:
    """Lines near the layouts DVLs send (most take the fast path), or any token soup."""
    kind = draw(st.sampled_from([*_LAYOUT, "HM", "XX"]))
    if kind not in _LAYOUT or draw(st.integers(0, 9)) == 0:
        return kind, draw(st.lists(st.sampled_from(_TOKENS), max_size=8))
    layout = _LAYOUT[kind]
    if kind == "TS" and draw(st.booleans()):
        layout = layout[:-1]
    fields = [
        draw(st.sampled_from(_PLAIN[c] if draw(st.integers(0, 19)) else _TOKENS)) for c in layout
    ]
    return kind, fields


@settings(max_examples=3000, deadline=None)
@given(_pd6_lines())
def test_fast_line_agrees_with_field_path(line_fields: tuple[str, list[str]]) -> None:
    """Every line the one-line fast path accepts gives the field-by-field value, and every range
    error it raises is the field-by-field error."""
    from drivers.errors import FrameError
    from drivers.rdi_ascii import _fast_line, _parse_fields

    kind, fields = line_fields
    line = f":{kind}," + ",".join(fields)
    raw = line.encode("ascii")
    try:
        fast = _fast_line(raw)
    except FrameError as exc:
        with pytest.raises(type(exc)) as slow:
            _parse_fields(raw)
        assert str(slow.value) == str(exc)
        return
    if fast is not None:
        assert _parse_fields(raw) == fast


@pytest.mark.parametrize(
    "line",
    [
        b":BS,+00100,-00200,+00003,A",
        b":BI,  +100,  -200,   +3,   +4,V",
        b":WE,-32768,+00000,+00000,A",
        b":SA, -2.31, +1.92, 75.20",
        b":TS,04081111563644,35.0,+21.0,0000.0,1524.0,  0,O",
        b":BD,+0000000.00,+0000000.00,+0000000.00,0025.30,000.00",
    ],
)
def test_fast_line_takes_the_plain_layouts(line: bytes) -> None:
    """The line layouts DVLs send take the one-line fast path and give the field-by-field result."""
    from drivers.rdi_ascii import _fast_line, _parse_fields

    fast = _fast_line(line)
    assert fast is not None  # the layouts DVLs send do take the fast path
    assert fast == _parse_fields(line)


# The whole-ensemble fast path (one chunk holding exactly one usual-layout ensemble)
# must give what the same bytes give line by line: records, rejects and counters.
_VEL = ["+00123", "-01234", "0", "-32768", "32767", " 12 ", "+00000"]
_DMG = ["+0000000.00", "0025.30", "000.00", "+1.50", "7"]
_ENS_PLAIN: dict[str, list[list[str]]] = {
    "SA": [["-2.31", "+01.92", "075.20", "0"]] * 3,
    "TS": [["25061208000123"], ["35.0", "0"], ["+15.0", "-1.5"], ["0000.0", "12.5"],
           ["1500.0", "1524.0"], ["000", "  0"], ["O", "W", "X"]],
    "WD": [_DMG] * 5, "BD": [_DMG] * 5, "RA": [_DMG] * 5, "HM": [["1", "2"]] * 2,
} | {k: [_VEL] * 4 + [["A", "V"]] for k in ("WI", "BI")} | {
    k: [_VEL] * 3 + [["A", "V"]] for k in ("WS", "WE", "BS", "BE")
}  # fmt: skip


@st.composite
def _pd6_chunks(draw: st.DrawFn) -> bytes:
    """An ensemble of the usual layout with plausible values: sometimes a line dropped,
    swapped or added, blanks before CR LF, or a field replaced by any token."""
    water = ["WI", "WS", "WE", "WD"] if draw(st.booleans()) else []
    kinds = ["SA", "TS", *water, "BI", "BS", "BE", "BD"]
    change = draw(st.integers(0, 7))
    if change == 0:
        del kinds[draw(st.integers(0, len(kinds) - 1))]
    elif change == 1:
        i = draw(st.integers(0, len(kinds) - 2))
        kinds[i], kinds[i + 1] = kinds[i + 1], kinds[i]
    elif change == 2:
        kinds.insert(draw(st.integers(0, len(kinds))), draw(st.sampled_from(["RA", "HM", "WS"])))
    lines = []
    for kind in kinds:
        layout = _ENS_PLAIN[kind]
        if kind == "TS" and draw(st.booleans()):
            layout = layout[:-1]
        fields = [
            draw(st.sampled_from(plain if draw(st.integers(0, 79)) else _TOKENS))
            for plain in layout
        ]
        pad = draw(st.sampled_from(["", "", "", " "]))
        lines.append(f":{kind}," + ",".join(fields) + pad + "\r\n")
    return "".join(lines).encode("ascii")


@settings(max_examples=3000, deadline=None)
@given(_pd6_chunks(), st.sampled_from([82, 50]))
def test_whole_ensemble_fast_path_agrees_with_line_by_line(data: bytes, max_length: int) -> None:
    """A chunk holding one ensemble, intact or damaged, gives the same records, rejects and counters
    whole as line by line."""
    from drivers.base import DecoderOptions

    opts = DecoderOptions(max_length=max_length)
    whole = PdAsciiDecoder("dvl", errors="yield", options=opts)
    by_line = PdAsciiDecoder("dvl", errors="yield", options=opts)
    got = [*whole.feed(data), *whole.flush()]
    want = [r for ln in data.splitlines(keepends=True) for r in by_line.feed(ln)]
    assert got == [*want, *by_line.flush()]
    assert whole.counters.as_dict() == by_line.counters.as_dict()


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"bottom_ship_mps": None, "range_m": None},  # no bottom lock: -32768 and V
        {"water_ship_mps": (0.1, 1.4, 0.0)},
        {"pitch_deg": -2.5, "roll_deg": 1.25, "heading_deg": 359.99, "temperature_c": -1.5},
    ],
)
def test_whole_ensemble_fast_path_takes_the_usual_layouts(kw: dict[str, object]) -> None:
    """The ensembles encode_pd6 sends take the whole-ensemble fast path and give the line-by-line
    record."""
    from drivers.rdi_ascii import _fast_ensemble

    data = _lines(**kw)
    fast = _fast_ensemble(data, 82)
    assert fast is not None  # what encode_pd6 and the simulated DVL send
    by_line = PdAsciiDecoder("dvl")
    assert [r for ln in data.splitlines(keepends=True) for r in by_line.feed(ln)] == [fast]
