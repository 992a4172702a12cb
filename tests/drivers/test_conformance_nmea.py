"""Real NMEA from other projects, and the values their own tests expect (SOURCES.md)."""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import pynmea2
import pytest

from drivers.base import DecoderOptions
from drivers.errors import ChecksumError, FieldError
from drivers.nmea0183 import Heading, Mtw, NmeaDecoder, NmeaRecord, Prti, Vbw, Vhw, Vlw
from drivers.records import KNOT_MPS, Rejected

DATA = Path(__file__).resolve().parents[1] / "data" / "nmea"
SHARED = Path(__file__).resolve().parents[2] / ".." / "shared" / "conformance" / "nmea"
NM_M = 1852.0


def _decode(name: str, path: Path = DATA) -> tuple[list[NmeaRecord | Rejected], NmeaDecoder]:
    dec = NmeaDecoder("x", errors="yield")
    return dec.decode_all((path / name).read_bytes()), dec


def _one(sentence: str) -> NmeaRecord:
    return NmeaDecoder("x", options=DecoderOptions(checksum="optional")).parse_frame(
        sentence.encode()
    )


VECTORS = [json.loads(line) for line in (DATA / "test_vectors.jsonl").read_text().splitlines()]


def _vector(sentence_prefix: str) -> dict[str, object]:
    return next(v for v in VECTORS if v["sentence"].startswith(sentence_prefix))


def test_signalk_vhw_expectations() -> None:
    """VHW vectors decode to Signal K's expected STW and headings, empty headings to None, and an
    all-empty VHW gives an invalid speed record."""
    r = _one("$IIVHW,,T,,M,06.12,N,11.33,K*50")
    assert isinstance(r, Vhw)
    exp = _vector("$IIVHW,,T,,M,06.12")["expected_by_source"]
    assert isinstance(exp, dict)
    stw = exp["navigation.speedThroughWater"]
    assert r.stw_mps == pytest.approx(stw["value_m_s"], abs=stw["tol"])
    assert r.heading_true_deg is None and r.heading_mag_deg is None
    r = _one("$SDVHW,182.5,T,181.8,M,0.0,N,0.0,K*4C")
    assert isinstance(r, Vhw)
    assert r.stw_mps == 0.0
    assert math.radians(r.heading_mag_deg or 0) == pytest.approx(3.1730085801256913, abs=5e-5)
    assert math.radians(r.heading_true_deg or 0) == pytest.approx(3.1852258848896517, abs=5e-5)
    empty = _one("$IIVHW,,T,,M,,N,,K*55")
    assert isinstance(empty, Vhw) and empty.stw_mps is None
    (sp,) = NmeaDecoder("x").speed_records(empty)
    assert not sp.valid  # no output value from an all-empty VHW


def test_signalk_vlw_mtw_heading_expectations() -> None:
    """VLW, MTW, HDG, HDT and HDM vectors decode to Signal K's expected distances, temperatures,
    headings, deviation and variation (west negative), and empty fields to None."""
    r = _one("$IIVLW,10.1,N,3.2,N*7C")
    assert isinstance(r, Vlw) and (r.total_nm or 0) * NM_M == pytest.approx(18705.2, abs=1e-3)
    r = _one("$IIVLW,115.2,N,12.3,N*7A")
    assert isinstance(r, Vlw) and (r.trip_nm or 0) * NM_M == pytest.approx(22779.6, abs=1e-3)
    r = _one("$YXMTW,15.2,C*14")
    assert isinstance(r, Mtw) and (r.temperature_c or 0) + 273.15 == pytest.approx(
        288.35, abs=0.005
    )
    r = _one("$RAMTW,,C*1E")
    assert isinstance(r, Mtw) and r.temperature_c is None
    r = _one("$SDHDG,181.9,,,0.6,E*32")
    assert isinstance(r, Heading)
    assert math.radians(r.heading_deg or 0) == pytest.approx(3.1747539093776855, abs=0.005)
    assert math.radians(r.variation_deg or 0) == pytest.approx(0.010471975511965976, abs=0.005)
    r = _one("$INHDG,180,5,E,10,W*7F")
    assert isinstance(r, Heading) and math.radians(r.deviation_deg or 0) == pytest.approx(
        0.0872664626, abs=1e-5
    )
    r = _one("$INHDG,180,5,W,10,W*6D")
    assert isinstance(r, Heading)
    assert (r.heading_deg, r.deviation_deg, r.variation_deg) == (180.0, -5.0, -10.0)
    assert (r.heading_deg or 0) + (r.deviation_deg or 0) == 175.0  # magnetic = sensor + deviation
    r = _one("$GPHDT,123.456,T*32")
    assert (
        isinstance(r, Heading)
        and r.true
        and math.radians(r.heading_deg or 0) == pytest.approx(2.155, abs=0.005)
    )
    r = _one("$04HDM,186.5,M*2C")
    assert (
        isinstance(r, Heading)
        and not r.true
        and math.radians(r.heading_deg or 0) == pytest.approx(3.26, abs=0.005)
    )
    for empty in ("$SDHDG,,,,,*70", "$SKHDT,,*40", "$SKHDM,,*59"):
        r = _one(empty)
        assert isinstance(r, Heading) and r.heading_deg is None
    r = _one("$INMTW,17.9,C*1B")
    assert isinstance(r, Mtw) and r.temperature_c == 17.9
    r = _one("$GPHDT,274.07,T*03")
    assert isinstance(r, Heading) and r.heading_deg == 274.07


def test_bad_checksum_vector_is_rejected() -> None:
    """Signal K's bad-checksum vector raises ChecksumError."""
    with pytest.raises(ChecksumError):
        _one("$GPROT,35.6,A*FF")


def test_go_nmea_vbw_and_vhw() -> None:
    """go-nmea's VBW vector gives a valid water pair on its own A status while the ground pair is V,
    and its VHW vector gives all four fields."""
    r = _one("$VMVBW,-7.1,0.1,A,,,V,,V,,V*65")
    assert isinstance(r, Vbw)
    assert r.water_long_mps == pytest.approx(-7.1 * KNOT_MPS)
    assert r.water_trans_mps == pytest.approx(0.1 * KNOT_MPS)
    assert r.water_valid and not r.ground_valid  # the water pair stands on its own status
    assert r.ground_long_mps is None and r.stern_water_mps is None
    r = _one("$VWVHW,45.0,T,43.0,M,3.5,N,6.4,K*56")
    assert isinstance(r, Vhw)
    assert (r.heading_true_deg, r.heading_mag_deg, r.stw_knots, r.stw_kmh) == (45.0, 43.0, 3.5, 6.4)


@pytest.mark.parametrize(
    "sentence",
    [v["sentence"] for v in VECTORS if isinstance(v["expected_by_source"], dict)
     and "error" in v["expected_by_source"] and v["sentence"].startswith(("$VMVBW", "$VWVHW"))],
)  # fmt: skip
def test_go_nmea_malformed_fields_are_bad_field(sentence: str) -> None:
    """Each of go-nmea's malformed VBW/VHW vectors is rejected as bad_field."""
    dec = NmeaDecoder("x", errors="yield")
    (r,) = dec.decode_all((sentence + "\r\n").encode())
    assert isinstance(r, Rejected) and r.reason == "bad_field", r


def test_marnav_style_vbw_pairs_and_the_minus_zero() -> None:
    """marnav-style VBWs decode a water pair alone, a ground pair alone and -0 as 0.0 with the stern
    ground pair valid, and a VHW with a heading but no speed has no STW."""
    r = _one("$IIVBW,1.0,-1.5,A,,,*2A")
    assert (
        isinstance(r, Vbw) and r.water_valid and r.water_trans_mps == pytest.approx(-1.5 * KNOT_MPS)
    )
    r = _one("$IIVBW,,,,1.0,0.5,A*06")
    assert isinstance(r, Vbw) and r.ground_valid and not r.water_valid
    r = _one("$IIVBW,,,V,-0,-0.01,A,,V,0,A*5C")
    assert isinstance(r, Vbw) and r.ground_long_mps == 0.0 and r.stern_ground_valid
    r = _one("$IIVHW,327,T,308.4,M,,N,,K*42")
    assert isinstance(r, Vhw) and r.heading_true_deg == 327.0 and r.stw_mps is None


def test_rowe_prti_vectors() -> None:
    """Rowe's PRTI01/PRTI02 vectors (12 and 14 fields) decode time, sample, temperature, status,
    subsystem and CEPO index with -99999 velocities as None, and a PRTI01 without bottom gives an
    invalid speed record."""
    r = _one("$PRTI01,379550,1,1468,-99999,-99999,-99999,0,,,,,0004*09")
    assert isinstance(r, Prti)
    assert (r.start_time_s, r.sample, r.temperature_c) == (3795.5, 1, 14.68)
    assert r.bottom_mps is None and r.bottom_depth_m == 0.0 and r.water_mps is None
    assert r.status == 0x0004 and not r.bottom_valid
    r = _one("$PRTI01,379550,1,1468,-99999,-99999,-99999,0,,,,,0004,3,0*0A")
    assert isinstance(r, Prti) and r.subsystem == "3" and r.cepo_index == 0
    r = _one("$PRTI02,379550,1,1468,-99999,-99999,-99999,0,,,,,0004,3,0*09")
    assert isinstance(r, Prti) and r.sentence == "PRTI02"
    (sp,) = NmeaDecoder("dvl").speed_records(
        _one("$PRTI01,379550,1,1468,-99999,-99999,-99999,0,,,,,0004*09")
    )
    assert not sp.valid and sp.source == "PRTI01"


def test_gpsd_bundg_zeus_capture() -> None:
    """gpsd's Bundg Zeus capture decodes to its known VHW, VLW, MTW and HDG counts with no checksum
    reject and framing rejects only for its '#' comment lines."""
    out, dec = _decode("gpsd_bundg_zeus_9.log")
    kinds = Counter(type(r).__name__ for r in out)
    assert kinds["Vhw"] == 150 and kinds["Vlw"] == 150 and kinds["Mtw"] == 149
    hdg = [r for r in out if isinstance(r, Heading) and r.sentence == "HDG"]
    assert len(hdg) == 1457
    assert dec.counters.rejects["checksum"] == 0  # all checksums are correct in this file
    # the only framing rejects are the '#' comment lines of the file's header
    assert dec.counters.rejects["framing"] == sum(
        1
        for ln in (DATA / "gpsd_bundg_zeus_9.log").read_bytes().splitlines()
        if ln.startswith(b"#")
    )
    first = next(r for r in out if isinstance(r, Vhw))
    assert first.stw_knots is not None and 6.0 < first.stw_knots < 7.5


def test_signalk_gofree_capture_with_garbage_inside() -> None:
    """Signal K's GoFree capture gives its MTW, heading and VHW counts, rejects its garbled VLW and
    92-character XDR lines, and a larger max_length admits some too-long lines."""
    out, dec = _decode("signalk_gofree-merrimac.log")
    kinds = Counter(type(r).__name__ for r in out)
    assert kinds["Mtw"] == 142
    assert kinds["Heading"] == 1375
    # 142 VHW lines; one of them is spliced into a garbled line and rejected as framing
    raw_lines = (DATA / "signalk_gofree-merrimac.log").read_bytes().splitlines()
    assert sum(1 for ln in raw_lines if b"VHW" in ln) == 142
    assert kinds["Vhw"] >= 141
    rejected = [r for r in out if isinstance(r, Rejected)]
    garbled_vlw = [r for r in rejected if r.raw.startswith(b"$SDVLW")]
    assert garbled_vlw and all(r.reason in ("framing", "checksum", "too_long") for r in garbled_vlw)
    xdr = [r for r in rejected if r.raw.startswith(b"$IIXDR")]
    assert xdr  # 92-character XDR: too long for NMEA (a lenient port may accept it)
    lenient = NmeaDecoder("x", errors="skip", options=DecoderOptions(max_length=200))
    lenient.decode_all((DATA / "signalk_gofree-merrimac.log").read_bytes())
    assert lenient.counters.rejects["too_long"] < dec.counters.rejects["too_long"]


def test_signalk_plaka_capture() -> None:
    """Signal K's Plaka capture gives 938 speed-only VHW between 5.5 and 6.5 kn and 1875 HDT without
    a checksum or field reject."""
    out, dec = _decode("signalk_plaka_first15000lines.log")
    vhw = [r for r in out if isinstance(r, Vhw)]
    assert len(vhw) == 938
    assert all(r.heading_true_deg is None and r.stw_knots is not None for r in vhw)
    assert all(5.5 <= (r.stw_knots or 0) <= 6.5 for r in vhw)
    hdt = [r for r in out if isinstance(r, Heading) and r.sentence == "HDT"]
    assert len(hdt) == 1875
    assert dec.counters.rejects["checksum"] == 0 and dec.counters.rejects["bad_field"] == 0


def test_humminbird_mtw() -> None:
    """gpsd's Humminbird capture gives 16 MTW near 18 °C, the first being gpsd's documented 17.9
    °C."""
    out, _ = _decode("gpsd_humminbird-M37.log")
    mtw = [r for r in out if isinstance(r, Mtw)]
    assert len(mtw) == 16 and all(17.9 <= (r.temperature_c or 0) <= 18.1 for r in mtw)
    assert mtw[0].temperature_c == 17.9  # the gpsd doc example, $INMTW,17.9,C*1B


def _both_parse(names: Iterable[str], kinds: tuple[str, ...]) -> Iterator[tuple[str, Any, Any]]:
    """Each line of the captures ``names`` (under DATA) with a sentence of ``kinds`` that we
    decode into a record: the line, our record and pynmea2's parse of it."""
    for name in names:
        for line in (DATA / name).read_text(errors="replace").splitlines():
            line = line.strip()
            if not line.startswith("$") or line[3:6] not in kinds:
                continue
            try:
                ours = _one(line)
            except Exception:
                continue
            yield line, ours, pynmea2.parse(line, check=True)


def test_our_decoder_agrees_with_pynmea2_on_every_real_vhw() -> None:
    """Every VHW we decode from the three real captures (over 1000; they hold no VBW) has the
    headings and speeds pynmea2 gives."""
    n = 0
    names = (
        "gpsd_bundg_zeus_9.log",
        "signalk_gofree-merrimac.log",
        "signalk_plaka_first15000lines.log",
    )
    for _, ours, theirs in _both_parse(names, ("VHW", "VBW")):
        n += 1
        if isinstance(ours, Vhw):
            for a, b in (
                (ours.heading_true_deg, theirs.heading_true),
                (ours.heading_mag_deg, theirs.heading_magnetic),
                (ours.stw_knots, theirs.water_speed_knots),
                (ours.stw_kmh, theirs.water_speed_km),
            ):
                assert (a is None and b is None) or a == pytest.approx(float(b))
    assert n > 1000


def _signed(value: object, direction: str) -> float | None:
    if value is None:
        return None
    return -float(value) if direction == "W" else float(value)  # type: ignore[arg-type]


def test_our_decoder_agrees_with_pynmea2_on_every_real_vlw_mtw_and_heading() -> None:
    """Every VLW, MTW, HDT, HDM and HDG we decode from the real captures has the distances,
    temperatures, headings and signed deviation and variation pynmea2 gives."""
    seen: Counter[str] = Counter()
    names = sorted(p.name for p in DATA.glob("*.log"))
    for line, ours, theirs in _both_parse(names, ("VLW", "MTW", "HDT", "HDM", "HDG")):
        seen[line[3:6]] += 1
        if isinstance(ours, Vlw):
            pairs = [
                (ours.total_nm, theirs.trip_distance),
                (ours.trip_nm, theirs.trip_distance_reset),
            ]
        elif isinstance(ours, Mtw):
            pairs = [(ours.temperature_c, theirs.temperature)]
        else:
            assert isinstance(ours, Heading)
            pairs = [(ours.heading_deg, theirs.heading)]
            if line[3:6] == "HDG":
                pairs += [
                    (ours.deviation_deg, _signed(theirs.deviation, theirs.dev_dir)),
                    (ours.variation_deg, _signed(theirs.variation, theirs.var_dir)),
                ]
        for a, b in pairs:
            assert (a is None and b is None) or a == pytest.approx(float(b)), line
    assert set(seen) == {"VLW", "MTW", "HDT", "HDM", "HDG"} and sum(seen.values()) > 1000, seen


def test_gpl_capture_in_place() -> None:
    """The Hakefjord capture in ../shared gives 1883 each of VHW, VLW and MTW, magnetic heading
    only, with no checksum reject (skipped when absent)."""
    path = SHARED / "vdrplayer_Hakefjord.txt"
    if not path.exists():
        pytest.skip("../shared/conformance is not present (GPL file, not copied)")
    out, dec = _decode(path.name, SHARED)
    kinds = Counter(type(r).__name__ for r in out)
    assert kinds["Vhw"] == 1883 and kinds["Vlw"] == 1883 and kinds["Mtw"] == 1883
    vhw = [r for r in out if isinstance(r, Vhw)]
    assert all(r.heading_true_deg is None and r.heading_mag_deg is not None for r in vhw)
    assert dec.counters.rejects["checksum"] == 0


def test_lgpl_and_unchecked_vectors_in_place() -> None:
    """The LGPL vectors in ../shared decode (a checksum-less 10-field VBW with all four pairs valid,
    a full VHW), a VHW with an empty T flag decodes, and one with shifted fields raises
    FieldError."""
    path = SHARED / "test_vectors_from_projects.jsonl"
    if not path.exists():
        pytest.skip("../shared/conformance is not present")
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    lgpl = [r for r in rows if r["license"].startswith("LGPL")]
    vbw = _one(lgpl[0]["sentence"])  # no checksum: accepted only with checksum optional
    assert isinstance(vbw, Vbw)
    assert vbw.water_long_mps == pytest.approx(11.0 * KNOT_MPS) and vbw.water_valid
    assert vbw.ground_long_mps == pytest.approx(7.5 * KNOT_MPS) and vbw.ground_valid
    assert vbw.stern_water_mps == pytest.approx(6.65 * KNOT_MPS) and vbw.stern_water_valid
    assert vbw.stern_ground_mps == pytest.approx(12.3 * KNOT_MPS) and vbw.stern_ground_valid
    vhw = _one(lgpl[1]["sentence"])
    assert isinstance(vhw, Vhw)
    assert (vhw.heading_true_deg, vhw.heading_mag_deg, vhw.stw_knots, vhw.stw_kmh) == (
        0.0,
        1.5,
        1.0,
        1.85,
    )
    r = _one("$IIVHW,,,211.0,M,0.00,N,0.00,K*2D")  # marnav: even the T flag is empty
    assert isinstance(r, Vhw) and r.heading_mag_deg == 211.0
    with pytest.raises(FieldError):
        NmeaDecoder("x").parse_frame(b"$VWVHW,T,45.0,43.0,M,3.5,N,6.4,K*56")
