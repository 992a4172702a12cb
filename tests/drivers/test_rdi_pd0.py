"""PD0: OOI's real ExplorerDVL ensembles and their expected decodes, resync, sign, round trip."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import binframe
from drivers.binframe import BinaryFramer, sum16
from drivers.errors import ChecksumError
from drivers.rdi_pd0 import Pd0Decoder, Pd0Ensemble, encode_pd0
from drivers.records import Rejected
from tests.chunks import feed_in_chunks
from tests.drivers.rdi_cases import HOSTILE_HEADER, OUT_OF_RANGE_LEADER
from tests.profiles import by_profile

DATA = Path(__file__).resolve().parents[1] / "data" / "dvl"


def _ensembles(name: str) -> tuple[list[Pd0Ensemble], Pd0Decoder]:
    dec = Pd0Decoder("dvl", errors="yield")
    out = dec.decode_all((DATA / name).read_bytes())
    return [r for r in out if isinstance(r, Pd0Ensemble)], dec


def _expected(name: str) -> list[dict[str, int]]:
    """OOI's expected particles, one dict per ensemble (merged particle types)."""
    doc = yaml.safe_load((DATA / name).read_text())
    rows: list[dict[str, int]] = []
    for p in doc["data"]:
        if p["particle_type"].startswith("adcp_velocity"):
            rows.append(dict(p))
        else:
            rows[-1].update(p)
    return rows


def test_ooi_auv_51_every_ensemble_matches_the_yml() -> None:
    """All 51 ensembles of OOI's AUV file decode without a reject to the ensemble numbers, attitude,
    raw bottom-track velocities and ranges of OOI's expected particles, in ship frame."""
    ens, dec = _ensembles("ooi_adcp_auv_51.pd0")
    expected = _expected("ooi_adcp_auv_51.yml")
    assert len(ens) == len(expected) == 51
    assert dec.counters.rejected == 0
    for e, x in zip(ens, expected, strict=True):
        assert e.ensemble_number == x["ensemble_number"]
        assert round(e.heading_deg * 100) == x["heading"]
        assert round(e.pitch_deg * 100) == x["pitch"]
        assert round(e.roll_deg * 100) == x["roll"]
        assert e.bt_velocity_mms == (
            x["bt_forward_velocity"],  # OOI label for raw velocity 1
            x["bt_starboard_velocity"],  # raw velocity 2
            x["bt_vertical_velocity"],
            x["bt_error_velocity"],
        )
        assert e.bt_range_cm == tuple(x[f"bt_beam{i}_range"] for i in range(1, 5))
        assert e.coord_frame == "ship"


def test_ooi_auv_3_values_from_sources_md() -> None:
    """OOI's 3-ensemble file decodes to the numbers, velocities, ranges, attitude, frequency, serial
    number, cell count and data types SOURCES.md records."""
    ens, _ = _ensembles("ooi_adcp_auv_3.pd0")
    assert [e.ensemble_number for e in ens] == [14, 15, 16]
    assert [e.bt_velocity_mms for e in ens] == [
        (-58, -137, 12, -3),
        (-8, -281, -14, 2),
        (35, -125, 45, 1),
    ]
    assert ens[0].bt_range_cm == (1423, 1426, 1369, 1481)
    assert (ens[2].heading_deg, ens[2].pitch_deg, ens[2].roll_deg) == (259.41, -3.27, 12.6)
    assert ens[0].frequency_khz == 600
    assert ens[0].serial_number == 22076
    assert ens[0].n_cells == 8
    assert ens[0].data_types == (0x0000, 0x0080, 0x0100, 0x0200, 0x0300, 0x0400, 0x0600, 0x2000)


def test_invalid_bottom_track_gives_an_invalid_speed_record() -> None:
    """An earth-frame ensemble with invalid bottom track has no velocities, zero ranges and no lock,
    and gives an invalid PD0:BT speed record."""
    ens, dec = _ensembles("ooi_NE051351.PD0")
    assert len(ens) == 1
    e = ens[0]
    assert e.coord_frame == "earth"
    assert e.bt_velocity_mms == (None, None, None, None)
    assert e.bt_range_cm == (0, 0, 0, 0)
    assert not e.bottom_lock
    (sp,) = dec.speed_records(e)
    assert not sp.valid and sp.longitudinal_mps is None and sp.source == "PD0:BT"


def test_corrupted_ensemble_is_one_checksum_reject_and_the_rest_decodes() -> None:
    """OOI's corrupted file gives ensembles 1 and 3 and exactly one checksum reject for ensemble
    2."""
    dec = Pd0Decoder("dvl", errors="yield")
    out = dec.decode_all((DATA / "ooi_LB180210_3_corrupted.PD0").read_bytes())
    ens = [r for r in out if isinstance(r, Pd0Ensemble)]
    rejects = [r for r in out if isinstance(r, Rejected)]
    assert [e.ensemble_number for e in ens] == [1, 3]
    assert len(rejects) == 1 and rejects[0].reason == "checksum"
    assert dec.counters.rejects["checksum"] == 1
    assert dec.counters.rejected == 1


def test_raise_mode_loses_nothing_after_a_corrupted_ensemble() -> None:
    """In raise mode the corrupted ensemble raises ChecksumError and ensembles 1 and 3 still come
    out on the following feeds."""
    dec = Pd0Decoder("dvl", errors="raise")
    data = (DATA / "ooi_LB180210_3_corrupted.PD0").read_bytes()
    got: list[object] = []
    with pytest.raises(ChecksumError):
        got.extend(dec.feed(data))
    got.extend(dec.feed(b""))
    got.extend(dec.flush())
    assert [e.ensemble_number for e in got if isinstance(e, Pd0Ensemble)] == [1, 3]


def test_sign_convention_vessel_motion_is_minus_bottom_velocity() -> None:
    """PD0 BT is the bottom's motion: the vessel moving ahead reads v2 < 0."""
    ens, dec = _ensembles("ooi_adcp_auv_3.pd0")
    (sp,) = dec.speed_records(ens[0])
    assert sp.longitudinal_mps == pytest.approx(0.137)  # -(-137 mm/s), velocity 2 = forward
    assert sp.transverse_mps == pytest.approx(0.058)  # -(-58 mm/s), velocity 1 = starboard
    assert sp.kind == "sog" and sp.valid


def test_garbage_between_ensembles_is_one_framing_reject_per_run() -> None:
    """Garbage before and between ensembles is one framing reject per run and all three ensembles
    decode."""
    data = (DATA / "ooi_adcp_auv_3.pd0").read_bytes()
    dec = Pd0Decoder("dvl", errors="skip")
    out = dec.decode_all(b"\x01\x02garbage" + data[:432] + b"x" * 500 + data[432:])
    assert len(out) == 3
    assert dec.counters.rejects["framing"] == 2


def test_buffer_stays_bounded_under_garbage() -> None:
    """500 kB of garbage keeps at most a partial header buffered and is one framing reject, reported
    when the run ends at flush."""
    dec = Pd0Decoder("dvl", errors="skip")
    for _ in range(50):
        list(dec.feed(b"\x00" * 10_000))
    framer = dec._framer
    assert isinstance(framer, BinaryFramer)
    assert len(framer._buf) < 100  # only a possible partial header is kept
    assert dec.counters.rejects["framing"] == 0  # the run is reported when it ends
    list(dec.flush())
    assert dec.counters.rejects["framing"] == 1


@pytest.mark.parametrize("frame", ["ship", "earth", "instrument"])
def test_encoder_round_trip(frame: str) -> None:
    """encode_pd0 in ship, earth or instrument frame decodes to its ensemble number, RTC, attitude,
    ranges and bottom speed within mm rounding."""
    b = encode_pd0(
        ensemble_number=70000,
        timestamp=datetime(2025, 6, 12, 8, 1, 2, 340000, tzinfo=UTC),
        heading_deg=123.45,
        pitch_deg=-1.5,
        roll_deg=2.25,
        bottom_ship_mps=(1.5, -0.2),
        range_m=25.3,
        coord_frame=frame,  # type: ignore[arg-type]
    )
    dec = Pd0Decoder("dvl")
    (e,) = dec.decode_all(b)
    assert isinstance(e, Pd0Ensemble)
    assert e.ensemble_number == 70000
    assert e.rtc == (25, 6, 12, 8, 1, 2, 34)
    assert (e.heading_deg, e.pitch_deg, e.roll_deg) == (123.45, -1.5, 2.25)
    assert e.bt_range_cm == (2530,) * 4
    (sp,) = dec.speed_records(e)
    assert sp.longitudinal_mps == pytest.approx(1.5, abs=2e-3)
    assert sp.transverse_mps == pytest.approx(-0.2, abs=2e-3)


def test_encoder_without_bottom_lock() -> None:
    """An ensemble encoded without bottom track decodes with no velocities and no bottom lock."""
    b = encode_pd0(ensemble_number=1, timestamp=datetime(2025, 1, 1, tzinfo=UTC), heading_deg=0.0)
    dec = Pd0Decoder("dvl")
    (e,) = dec.decode_all(b)
    assert isinstance(e, Pd0Ensemble)
    assert e.bt_velocity_mms == (None, None, None, None) and not e.bottom_lock


@settings(max_examples=200, deadline=None)
@given(cuts=st.lists(st.integers(min_value=0, max_value=1296), max_size=20))
def test_any_chunking_gives_the_same_records(cuts: list[int]) -> None:
    """OOI's 3-ensemble file gives the same records however it is cut into chunks."""
    data = (DATA / "ooi_adcp_auv_3.pd0").read_bytes()
    whole = Pd0Decoder("dvl").decode_all(data)
    dec = Pd0Decoder("dvl")
    out = feed_in_chunks(dec, data, cuts)
    assert out == whole


def _flip_test(pos: int, xor: int) -> None:
    data = bytearray((DATA / "ooi_adcp_auv_3.pd0").read_bytes())
    original = Pd0Decoder("dvl").decode_all(bytes(data))
    data[pos % len(data)] ^= xor
    dec = Pd0Decoder("dvl", errors="skip")
    out = dec.decode_all(bytes(data))
    # every record that comes out is one of the originals (a corrupted one never does)
    assert all(r in original for r in out)
    assert len(out) >= 2


@pytest.mark.fuzz
@settings(max_examples=by_profile(300), deadline=None)
@given(pos=st.integers(min_value=0, max_value=10_000), xor=st.integers(min_value=1, max_value=255))
def test_a_flipped_byte_never_yields_a_corrupted_ensemble(pos: int, xor: int) -> None:
    """A flipped byte anywhere in the file yields only original ensembles, and at least two of the
    three."""
    _flip_test(pos, xor)


def test_a_corrupted_length_at_end_of_file_does_not_swallow_the_next_ensemble() -> None:
    """Found by the fuzz run: ensemble 2's length field +512 made the framer wait for
    bytes that never came, and the end of the file took ensemble 3 with it."""
    data = bytearray((DATA / "ooi_adcp_auv_3.pd0").read_bytes())
    data[435] ^= 2
    dec = Pd0Decoder("dvl", errors="yield")
    out = dec.decode_all(bytes(data))
    assert [e.ensemble_number for e in out if isinstance(e, Pd0Ensemble)] == [14, 16]
    assert dec.counters.rejected == 1


@pytest.mark.parametrize("bad", [*OUT_OF_RANGE_LEADER, {"salinity_ppt": 60}])
def test_an_out_of_range_leader_field_is_a_reject(bad: dict[str, float]) -> None:
    """A PD0 ensemble whose pitch, roll, temperature, salinity or sound speed is outside its
    physical range is an out_of_range reject, not a record; the same ensemble in range is read."""
    base = {"ensemble_number": 1, "timestamp": datetime(2025, 1, 1, tzinfo=UTC)}
    good = encode_pd0(heading_deg=10.0, **base)  # type: ignore[arg-type]
    assert isinstance(Pd0Decoder("d").decode_all(good)[0], Pd0Ensemble)
    dec = Pd0Decoder("d", errors="yield")
    (out,) = dec.decode_all(encode_pd0(heading_deg=10.0, **base, **bad))  # type: ignore[arg-type]
    assert isinstance(out, Rejected) and out.reason == "out_of_range"


def test_an_impossible_clock_is_a_reject() -> None:
    """A PD0 ensemble whose variable leader's real-time clock names month 13 is an out_of_range
    reject."""
    import struct

    from drivers.binframe import sum16

    good = encode_pd0(
        ensemble_number=1, timestamp=datetime(2025, 1, 1, tzinfo=UTC), heading_deg=10.0
    )
    body = bytearray(good[:-2])
    n_types = body[5]
    offsets = [struct.unpack_from("<H", body, 6 + 2 * i)[0] for i in range(n_types)]
    (vl,) = [o for o in offsets if struct.unpack_from("<H", body, o)[0] == 0x0080]
    assert body[vl + 5] == 1  # the month
    body[vl + 5] = 13
    bad = bytes(body) + (sum16(bytes(body)) & 0xFFFF).to_bytes(2, "little")
    dec = Pd0Decoder("d", errors="yield")
    (out,) = dec.decode_all(bad)
    assert isinstance(out, Rejected) and out.reason == "out_of_range" and "clock" in out.detail


MAX_SUMMED_PER_BYTE = 1
"""Times the framer may pass a received byte to the checksum's sum: a frame's checksum
comes from running sums, so no byte is summed again for each header claiming it."""


def test_headers_claiming_long_ensembles_with_wrong_checksums_cost_linear_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """100 KB of such headers, one every 6 bytes, all their checksums wrong, then a good
    ensemble: no byte summed more than MAX_SUMMED_PER_BYTE times, one checksum reject per
    claimed ensemble (the headers inside it are part of it), the good ensemble kept.
    Summing each claimed ensemble took 2 s (idle) to 10 s (loaded) for these 100 KB
    (16 000 bytes summed for each of 16 666 headers), a port of a DVL's speed held the
    daemon's thread."""
    good = encode_pd0(
        ensemble_number=7, timestamp=datetime(2025, 1, 1, tzinfo=UTC), heading_deg=0.0
    )
    dec = Pd0Decoder(errors="skip")
    hostile = HOSTILE_HEADER * (100_000 // len(HOSTILE_HEADER))
    data = hostile + b"\0" * 16_002 + good
    limit = MAX_SUMMED_PER_BYTE * len(data)
    summed = 0

    def counting_sum16(chunk: bytes | bytearray | memoryview) -> int:
        nonlocal summed
        summed += len(chunk)
        if summed > limit:  # fail at once, not after the minutes a sum per header takes
            raise AssertionError(f"more than {limit} bytes summed for {len(data)} received")
        return sum16(chunk)

    monkeypatch.setattr(binframe, "sum16", counting_sum16)
    out = feed_in_chunks(dec, data, range(4096, len(data), 4096))
    assert summed <= limit
    assert [o.ensemble_number for o in out if isinstance(o, Pd0Ensemble)] == [7]
    # the headers inside a claimed ensemble reported are part of its reject
    assert dec.counters.rejects["checksum"] == -(-len(hostile) // 16_002)
