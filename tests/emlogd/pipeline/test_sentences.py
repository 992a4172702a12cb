"""Output sentences: status sentence fields, checksum and length; corrected VHW/VBW."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from drivers.framing import split_nmea
from emlogd.pipeline.sentences import (
    StatusFields,
    encode_status,
    encode_vbw,
    encode_vdr,
    encode_vhw,
    encode_vhw_void,
)
from tests.profiles import by_profile


def _fields(sentence: str) -> list[str]:
    body = split_nmea(sentence.encode("ascii"), required=True)
    return body.decode("ascii").split(",")


def test_status_sentence_fields() -> None:
    """A learning status sentence carries the port, L, the model, m and b to 4 and 3 decimals, their
    σ in exponent form, the NIS mean and V, with the a fields empty."""
    s = encode_status(
        StatusFields(
            port="emlog1",
            state="learning",
            model="EM3",
            params={"m": 0.1712, "b": 0.12},
            std={"m": 0.0021, "b": 0.0034},
            nis_mean=1.02,
            ref_state="valid",
        )
    )
    assert s.startswith("$PEMLS,")
    assert _fields(s) == [
        "PEMLS", "emlog1", "L", "EM3", "", "+0.1712", "+0.120", "", "2.1e-03", "3.4e-03", "1.02", "V",
    ]  # fmt: skip


def test_uncalibrated_status_has_empty_parameters() -> None:
    """An uncalibrated status sentence has every parameter, σ and NIS field empty and reference
    state N."""
    s = encode_status(StatusFields(port="emlog2", state="uncalibrated", model="EM4"))
    assert _fields(s) == ["PEMLS", "emlog2", "U", "EM4", "", "", "", "", "", "", "", "N"]


def test_bad_maker_code_rejected() -> None:
    """A maker code that is not three uppercase letters is a ValueError."""
    with pytest.raises(ValueError, match="maker"):
        encode_status(StatusFields(port="x", state="frozen", model="EM3", maker="em"))


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@given(
    port=st.text(min_size=0, max_size=40),
    params=st.fixed_dictionaries({"a": finite, "m": finite, "b": finite}),
    std=st.fixed_dictionaries({"a": finite, "m": finite, "b": finite}),
    nis=st.one_of(st.none(), st.floats(min_value=0, max_value=1e9)),
    state=st.sampled_from(["learning", "frozen", "uncalibrated"]),
    ref=st.sampled_from(["valid", "lost", "stale", "slow", "none"]),
)
@example(  # b = 10 was clamped to 9.9999, which "+.3f" rounds up to "+10.000": 83 bytes
    port="00000000",
    params={"a": 0.0, "m": 0.0, "b": 10.0},
    std={"a": 0.0, "m": 0.0, "b": 0.0},
    nis=100.0,
    state="learning",
    ref="valid",
)
def test_status_always_fits_and_checksums(
    port: str,
    params: dict[str, float],
    std: dict[str, float],
    nis: float | None,
    state: str,
    ref: str,
) -> None:
    """Any port name, parameters, σ, NIS, state and reference state give a printable, checksummed,
    12-field status sentence within 82 characters."""
    std = {k: abs(v) for k, v in std.items()}
    s = encode_status(StatusFields(port, state, "EM4", params, std, nis, ref))
    assert len(s) + 2 <= 82
    assert all(32 <= ord(c) < 127 for c in s)
    assert len(_fields(s)) == 12


def test_corrected_vhw_fills_knots_and_kmh() -> None:
    """A corrected VHW carries both headings with their T and M flags and the speed in knots and
    km/h."""
    s = encode_vhw(2.0, 45.0, 43.0, "VW")
    f = _fields(s)
    assert f[0] == "VWVHW"
    assert float(f[1]) == pytest.approx(45.0) and f[2] == "T"
    assert float(f[3]) == pytest.approx(43.0) and f[4] == "M"
    knots, kmh = float(f[5]), float(f[7])
    assert knots == pytest.approx(2.0 / (1852 / 3600), abs=0.01)
    assert kmh == pytest.approx(7.2, abs=0.01)
    assert f[6] == "N" and f[8] == "K"


def test_corrected_vbw_has_a_valid_water_pair() -> None:
    """A corrected VBW carries the longitudinal and transverse speeds in knots with water status
    A."""
    f = _fields(encode_vbw(1.5, -0.1, "VW"))
    assert f[0] == "VWVBW"
    assert float(f[1]) == pytest.approx(1.5 / (1852 / 3600), abs=0.01)
    assert float(f[2]) == pytest.approx(-0.1 / (1852 / 3600), abs=0.01)
    assert f[3] == "A"


def _status_round_trip(m: float, b: float, sm: float, nis: float | None) -> None:
    s = encode_status(
        StatusFields(
            "emlog1", "learning", "EM3", {"m": m, "b": b}, {"m": sm, "b": sm}, nis, "valid"
        )
    )
    f = _fields(s)
    assert len(s) + 2 <= 82
    assert float(f[5]) == pytest.approx(max(min(m, 9.9999), -9.9999), abs=5e-5)
    assert float(f[6]) == pytest.approx(max(min(b, 9.999), -9.999), abs=5e-4)


@pytest.mark.fuzz
@settings(max_examples=by_profile(100))
@given(
    m=st.floats(-20, 20),
    b=st.floats(-20, 20),
    sm=st.floats(0, 1),
    nis=st.one_of(st.none(), st.floats(0, 1e6)),
)
def test_status_round_trip(m: float, b: float, sm: float, nis: float | None) -> None:
    """m and b read back from the status sentence as sent, clamped to ±9.9999 and ±9.999, within 82
    characters."""
    _status_round_trip(m, b, sm, nis)


def test_directions_fit_their_field() -> None:
    """The void VHW's headings and the VDR's set are written in 0–359.9° with one decimal
    (a heading of −10° as 350.0, 359.96° as 359.9), an unknown or non-finite one empty;
    the VDR's drift is clamped to 0–99.99 kn."""
    vhw = _fields(encode_vhw_void(-10.0, 359.96))
    assert vhw[1:5] == ["350.0", "T", "359.9", "M"] and vhw[5] == vhw[7] == ""
    assert _fields(encode_vhw_void(None, float("nan")))[1:5] == ["", "T", "", "M"]
    vdr = _fields(encode_vdr(720.04, None, 120.0))
    assert vdr[1:7] == ["0.0", "T", "", "M", "99.99", "N"]
