"""The Decoder contract: error policies, counters, queued frames, options."""

from __future__ import annotations

import importlib
import json
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, get_args

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import drivers
from drivers import rdi_pd0, rdi_pd45
from drivers.base import Decoder, DecoderOptions
from drivers.errors import FieldError, FrameError
from drivers.framing import LineFramer, with_checksum
from drivers.nmea0183 import encode_rmc, encode_vbw, encode_vhw
from drivers.rdi import CoordFrame
from drivers.rdi_ascii import encode_pd6
from drivers.rdi_pd0 import encode_pd0
from drivers.rdi_pd45 import encode_pd45
from drivers.records import Rejected, SpeedRecord, SpeedRole
from tests import nmea_encoders as enc
from tests.profiles import by_profile

DATA = Path(__file__).resolve().parents[1] / "data"


class _Digits(Decoder[int]):
    """A toy line protocol: ``#<digits>`` lines decode to ints; anything else is bad."""

    protocol = "digits"
    binary = False

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._framer = LineFramer(b"#", 82)

    def _split(self, data: bytes) -> Iterable[bytes | FrameError]:
        return list(self._framer.feed(data))

    def _flush(self) -> Iterable[bytes | FrameError]:
        return list(self._framer.flush())

    def parse_frame(self, frame: bytes) -> int:
        if not frame[1:].isdigit():
            raise FieldError("not digits", frame)
        return int(frame[1:])


class TestErrorPolicies:
    """raise / yield / skip, and the counters under each."""

    STREAM = b"#1\n#x\n#2\ngarbage\n#3\n"

    def test_skip_counts_and_drops(self) -> None:
        """errors='skip' yields only good records and counts every reject by reason."""
        dec = _Digits("p", errors="skip")
        assert dec.decode_all(self.STREAM) == [1, 2, 3]
        assert dec.counters.records == 3
        assert dec.counters.rejects["bad_field"] == 1
        assert dec.counters.rejects["framing"] == 1

    def test_yield_reports_rejects_in_order(self) -> None:
        """errors='yield' yields a Rejected record in place of each bad frame."""
        out = _Digits("p", errors="yield").decode_all(self.STREAM)
        assert [type(o).__name__ for o in out] == ["int", "Rejected", "int", "Rejected", "int"]
        rej = out[1]
        assert isinstance(rej, Rejected)
        assert (rej.port, rej.reason, rej.raw) == ("p", "bad_field", b"#x")

    def test_raise_keeps_the_rest_of_the_chunk(self) -> None:
        """errors='raise' raises, and the frames after the bad one come out on the next call."""
        dec = _Digits("p")
        got: list[object] = []
        with pytest.raises(FieldError):
            got.extend(dec.feed(self.STREAM))
        with pytest.raises(FrameError):
            got.extend(dec.feed(b""))
        got.extend(dec.feed(b""))
        assert got == [1, 2, 3]
        assert dec.counters.rejected == 2

    def test_flush_reports_unterminated_line(self) -> None:
        """An unterminated line at end of stream is a counted framing reject."""
        dec = _Digits("p", errors="skip")
        assert dec.decode_all(b"#1\n#2") == [1]
        assert dec.counters.rejects["framing"] == 1

    def test_bad_policy_rejected(self) -> None:
        """An unknown error policy is a ValueError."""
        with pytest.raises(ValueError, match="errors"):
            _Digits("p", errors="ignore")


class TestOptions:
    """DecoderOptions validation."""

    def test_defaults_are_strict_nmea(self) -> None:
        """Checksums are required and the NMEA length limit applies by default."""
        opts = DecoderOptions()
        assert (opts.checksum, opts.max_length) == ("required", 82)

    @pytest.mark.parametrize(
        "kwargs", [{"checksum": "maybe"}, {"max_length": 4}, {"max_length": 100_000}]
    )
    def test_bad_values_raise(self, kwargs: dict[str, object]) -> None:
        """Out-of-range options raise ValueError naming the option."""
        with pytest.raises(ValueError, match=next(iter(kwargs))):
            DecoderOptions(**kwargs)  # type: ignore[arg-type]


# ---------------------------------------------------------------- typed record unions

T0 = datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)


def _nmea_samples() -> list[bytes]:
    """Every NMEA log and test vector of tests/data, the encoders' sentences, Rowe PRTI."""
    chunks = [p.read_bytes() for p in sorted((DATA / "nmea").glob("*.log"))]
    with open(DATA / "nmea" / "test_vectors.jsonl", encoding="utf-8") as f:
        vectors = [json.loads(line)["sentence"] for line in f if line.strip()]
    encoded = [
        encode_vhw(2.0, heading_true_deg=10.0, heading_mag_deg=12.0),
        encode_vbw(2.0, 0.1, ground_long_mps=2.1, ground_trans_mps=0.0, ground_valid=True),
        encode_rmc(T0, 3.0, 45.0, lat_deg=50.0, lon_deg=-4.0, variation_deg=-2.0),
        enc.encode_vtg(3.0, 45.0),
        enc.encode_gga(T0, 50.0, -4.0),
        enc.encode_zda(T0),
        enc.encode_hdt(90.0),
        enc.encode_hdm(88.0),
        enc.encode_hdg(88.0, 1.0, -2.0),
        with_checksum("IIVLW,10.1,N,3.2,N"),
        with_checksum("YXMTW,15.2,C"),
        with_checksum("IIVDR,10.0,T,12.0,M,0.5,N"),
        "$PRTI01,379550,1,1468,-99999,-99999,-99999,0,,,,,0004*09",
        "$PRTI02,379550,1,1468,-99999,-99999,-99999,0,,,,,0004,3,0*09",
    ]
    chunks.append("".join(s + "\r\n" for s in [*vectors, *encoded]).encode("ascii"))
    return chunks


def _pd6_samples() -> list[bytes]:
    """The Pathfinder guide's PD13 ensemble, encoded PD6 with and without water track, an :HM
    line and a broken block."""
    lines = [
        *encode_pd6(timestamp=T0, heading_deg=10.0, bottom_ship_mps=(0.1, 2.0, 0.0), range_m=9.0),
        *encode_pd6(timestamp=T0, heading_deg=10.0, water_ship_mps=(0.0, 1.5, 0.0)),
        ":HM,1,2,3",
        ":SA,+00.00,+00.00,010.00",
        ":BS,+00010,+02000,+00000,A",
    ]
    text = "".join(line + "\r\n" for line in lines).encode("ascii")
    return [(DATA / "dvl" / "trdi_pathfinder_guide_pd13_example.txt").read_bytes(), text]


FRAMES: tuple[CoordFrame, ...] = ("ship", "earth", "instrument", "beam")


def _pd0_samples() -> list[bytes]:
    """The PD0 files of tests/data (one corrupted) and encoded ensembles in each frame."""
    files = [p.read_bytes() for p in sorted((DATA / "dvl").glob("*.[pP][dD]0"))]
    enc = b"".join(
        encode_pd0(
            ensemble_number=i,
            timestamp=T0,
            heading_deg=30.0,
            bottom_ship_mps=None if i == 0 else (2.0, 0.1),
            range_m=10.0,
            coord_frame=frame,
        )
        for i, frame in enumerate(FRAMES)
    )
    return [*files, enc + b"\x7f\x7f\x00garbage"]


def _pd45_samples() -> list[bytes]:
    """Encoded PD4 and PD5 frames in each coordinate frame, with and without bottom lock."""
    frames = [
        encode_pd45(pd5=pd5, bottom_ship_mps=mps, range_m=10.0, coord_frame=frame, heading_deg=30.0)
        for pd5 in (False, True)
        for frame in ("ship", "earth", "beam")
        for mps in (None, (2.0, 0.1))
    ]
    return [b"".join(frames) + b"\x7d\x00\x2d\x00junk"]


SAMPLES = {
    "nmea0183": _nmea_samples,
    "pd6": _pd6_samples,
    "pd13": _pd6_samples,
    "pd0": _pd0_samples,
    "pd4": _pd45_samples,
    "pd5": _pd45_samples,
}


def _union(cls: type[Decoder[Any]]) -> object:
    """The record type a decoder class declares as its ``Decoder[R]`` argument."""
    for klass in cls.__mro__:
        for base in getattr(klass, "__orig_bases__", ()):
            args = get_args(base)
            if args:
                return args[0]
    raise AssertionError(f"{cls.__name__} declares no record type")


def _members(union: object) -> tuple[Any, ...]:
    """The member types of a record union (a single record type is its own member)."""
    args = get_args(union)
    return args if args else (union,)


START = {
    "nmea0183": b"$",
    "pd6": b":",
    "pd13": b":",
    "pd0": rdi_pd0.HEADER,
    "pd4": rdi_pd45.HEADER,
    "pd5": rdi_pd45.HEADER,
}
"""The first bytes of each protocol's frames: random bytes after them reach its parser."""


@pytest.mark.fuzz
@pytest.mark.parametrize("name", sorted(drivers.PROTOCOLS))
@settings(max_examples=by_profile(300), deadline=None)
@given(data=st.binary(max_size=3000))
def test_random_bytes_never_raise_in_skip_mode(name: str, data: bytes) -> None:
    """Arbitrary bytes after the start of any protocol's frame never raise in skip mode
    and yield only members of its record union (no Rejected: rejects are only counted)."""
    dec = drivers.make_decoder(name, "p", errors="skip")
    members = _members(_union(type(dec)))
    for r in dec.decode_all(START[name] + data):
        assert isinstance(r, members), type(r)


class TestRecordUnions:
    """Each protocol's decoder declares its record union, and yields nothing else."""

    def test_samples_cover_every_registered_protocol(self) -> None:
        """Every built-in protocol has samples here (a new one must add its own)."""
        assert set(SAMPLES) == set(drivers.PROTOCOLS)

    @pytest.mark.parametrize("name", sorted(drivers.PROTOCOLS))
    def test_records_equal_the_declared_union(self, name: str) -> None:
        """The decoder's Decoder[R] argument is the union its module exports, and the module's
        RECORDS are exactly that union's members."""
        module_name, _ = drivers.PROTOCOLS[name]
        module = importlib.import_module(module_name)
        union = _union(drivers.get_decoder(name))
        exported = [v for k, v in vars(module).items() if k.endswith("Record") and v == union]
        assert exported, f"{module_name} does not export its record union"
        assert _members(union) == module.RECORDS
        assert Rejected not in module.RECORDS and SpeedRecord not in module.RECORDS

    @pytest.mark.parametrize("name", sorted(drivers.PROTOCOLS))
    def test_decoders_yield_only_their_union_or_rejected(self, name: str) -> None:
        """On the samples, feed yields members of the declared union or Rejected, at least one
        record of each; speed_records takes every record and gives speed records whose role is
        a SpeedRole."""
        dec = drivers.make_decoder(name, "p", errors="yield")
        members = _members(_union(type(dec)))
        got: list[object] = []
        for chunk in SAMPLES[name]():
            got.extend(dec.feed(chunk))
        got.extend(dec.flush())
        strays = {type(r).__name__ for r in got if not isinstance(r, (*members, Rejected))}
        assert not strays, f"{name} yielded {strays}"
        records = [r for r in got if not isinstance(r, Rejected)]
        assert records and any(isinstance(r, Rejected) for r in got)
        speeds = [sp for r in records for sp in dec.speed_records(r)]
        assert speeds and all(isinstance(sp, SpeedRecord) for sp in speeds)
        assert {sp.role for sp in speeds} <= set(get_args(SpeedRole))

    def test_record_types_lists_unions_and_parts(self) -> None:
        """drivers.record_types() holds every protocol's union members and nested parts."""
        listed = set(drivers.record_types())
        for name in drivers.PROTOCOLS:
            assert set(_members(_union(drivers.get_decoder(name)))) <= listed
        assert {Rejected, SpeedRecord} <= listed

    def test_entry_points_are_read_once_per_process(self, monkeypatch: pytest.MonkeyPatch) -> None:
        """The installed entry points are scanned once, however often the protocols are
        asked for (a config load asks dozens of times), and a plug-in's protocol is listed."""
        calls: list[str] = []

        class _Ep:
            name = "plugin"
            value = "drivers.nmea0183:NmeaDecoder"

        def fake_entry_points(*, group: str) -> list[_Ep]:
            calls.append(group)
            return [_Ep()]

        monkeypatch.setattr(drivers, "entry_points", fake_entry_points)
        drivers._entry_point_protocols.cache_clear()
        try:
            for _ in range(5):
                assert "plugin" in drivers.protocol_names()
            assert drivers.get_decoder("plugin") is drivers.get_decoder("nmea0183")
            assert calls == [drivers.ENTRY_POINT_GROUP]
        finally:
            drivers._entry_point_protocols.cache_clear()

    def test_what_each_protocol_can_serve(self) -> None:
        """The decoders say what a port can be to a calibration: only NMEA 0183 a UUT, an
        EMlog or a GNSS reference; a water track only PD6/PD13; a bottom track every DVL
        protocol and Rowe's PRTI01; and which DVL outputs carry the heading (not PD4)."""
        assert drivers.protocols_for("uut") == ["nmea0183"]
        assert drivers.protocols_for("speed") == drivers.protocols_for("gnss") == ["nmea0183"]
        assert drivers.protocols_for("water") == ["pd6", "pd13"]
        assert drivers.protocols_for("bottom") == list(drivers.PROTOCOLS)
        heading = {n for n in drivers.PROTOCOLS if drivers.get_decoder(n).heading}
        assert heading == {"pd6", "pd13", "pd0", "pd5"}

    def test_literal_overloads_match_the_registry(self) -> None:
        """get_decoder's and make_decoder's typed overloads name the class PROTOCOLS registers."""
        from typing import get_overloads

        for fn, wrap in ((drivers.get_decoder, "type[{}]"), (drivers.make_decoder, "{}")):
            typed: dict[str, str] = {}
            for ov in get_overloads(fn):
                ann = ov.__annotations__
                literal = ann["name"]
                if literal.startswith("Literal["):
                    for n in literal[len("Literal[") : -1].split(", "):
                        typed[n.strip("'\"")] = ann["return"]
            assert typed == {n: wrap.format(c) for n, (_, c) in drivers.PROTOCOLS.items()}
