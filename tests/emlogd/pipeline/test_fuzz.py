"""Whole-pipeline fuzz: random and mutated sentences of every protocol through the Pipeline.

Every port of a config like the example's (two EMlogs, a PD6 DVL as reference, a PD0 and
a PD5 DVL, a GNSS receiver as a third log's reference, a compass) receives valid
sentences, the same with a field replaced by a hostile value (checksum recomputed, so only
the field checks stand between it and the filter), flipped or cut bytes, and random
bytes, in time order with ticks between, as ``replay`` drives it. Nothing may raise out of
the pipeline, and every sentence it emits must decode as a valid record with finite
values. A small profile runs in the default suite; the long one is marked ``fuzz``.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.binframe import sum16
from drivers.framing import with_checksum
from drivers.nmea0183 import NmeaDecoder, Vhw, encode_rmc, encode_vbw, encode_vhw
from drivers.rdi_ascii import encode_pd6
from drivers.rdi_pd0 import encode_pd0
from drivers.rdi_pd45 import encode_pd45
from drivers.records import Rejected
from emlogd.config import parse_config
from emlogd.pipeline.core import Pipeline
from emlogd.settings import fusion_from_config, pipeline_from_config
from tests import nmea_encoders as enc
from tests.profiles import by_profile

CONFIG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog3, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
  - {name: dvl0, url: /dev/null, protocol: pd0, role: reference}
  - {name: dvl5, url: /dev/null, protocol: pd5, role: aux}
  - {name: gps, url: /dev/null, protocol: nmea0183, role: reference}
  - {name: compass, url: /dev/null, protocol: nmea0183, role: aux}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.5, current: auto, validation_s: 5, recheck_s: 10}
  - {uut: emlog2, reference: dvl0, uut_source: VBW, lag: auto, lag_window_s: 20, talker: VM}
  - {uut: emlog3, reference: gps, reference_field: gnss, heading: compass, lag: 0.2,
     talker: VD}
outputs: {speed: both}
"""

T0 = datetime(2026, 1, 1, tzinfo=UTC)

HOSTILE = (
    "1e308", "-1e308", "nan", "inf", "-inf", "-0", "360", "360.0001", "-0.0001", "180.5",
    "-180.5", "99999999", "0", "", "1e-320", "-", ".", "+", "1_0", " 1", "0x10", "٣",
    "4294967296", "-32768", "32767", "9" * 40,
)  # fmt: skip
"""Field values that are hard to read or physically impossible."""


def _nmea(port: str, k: int) -> bytes:
    t = T0.timestamp() + k
    v = 2.0 + math.sin(k / 7.0)
    h = (k * 13.0) % 360.0
    when = datetime.fromtimestamp(t, UTC)
    by_port = {
        "emlog1": [encode_vhw(v, heading_mag_deg=h)],
        "emlog2": [encode_vbw(v, 0.1), encode_vhw(v)],
        "emlog3": [encode_vhw(v * 1.05)],
        "gps": [
            encode_rmc(when, v, h, lat_deg=43.1, lon_deg=5.9, variation_deg=1.5),
            enc.encode_vtg(v, h),
            enc.encode_gga(when, 43.1, 5.9),
            enc.encode_zda(when),
            with_checksum("GPVDR,10.0,T,8.5,M,0.50,N"),
        ],
        "compass": [
            enc.encode_hdg(h, 1.0, 2.0),
            enc.encode_hdg(h, -1.0, -2.0),
            enc.encode_hdt(h),
            enc.encode_hdm(h),
        ],
    }
    lines = by_port[port]
    return (lines[k % len(lines)] + "\r\n").encode()


def _binary(port: str, k: int) -> bytes:
    v = 2.0 + math.sin(k / 7.0)
    h = (k * 13.0) % 360.0
    when = datetime.fromtimestamp(T0.timestamp() + k, UTC)
    if port == "dvl":
        lines = encode_pd6(
            timestamp=when, heading_deg=h, bottom_ship_mps=(0.1, v, 0.0), range_m=30.0,
            water_ship_mps=(0.0, v - 0.3, 0.0),
        )  # fmt: skip
        return "".join(x + "\r\n" for x in lines).encode()
    if port == "dvl0":
        return encode_pd0(
            ensemble_number=k + 1, timestamp=when, heading_deg=h, bottom_ship_mps=(v, 0.1),
            range_m=30.0,
        )  # fmt: skip
    return encode_pd45(pd5=True, bottom_ship_mps=(v, 0.1), range_m=30.0, heading_deg=h)


PORTS = ("emlog1", "emlog2", "emlog3", "dvl", "dvl0", "dvl5", "gps", "compass")
TEXT_PORTS = frozenset({"emlog1", "emlog2", "emlog3", "gps", "compass"})


def _valid(port: str, k: int) -> bytes:
    return _nmea(port, k) if port in TEXT_PORTS else _binary(port, k)


def _hostile_field(data: bytes, index: int, value: str, also: int | None = None) -> bytes:
    """The comma-separated field ``index`` of a text sentence (and field ``also``, if
    given) replaced by ``value``, the NMEA checksum recomputed (PD6 has none); binary data
    gets the value's bytes written in at those offsets and its 16-bit checksum recomputed."""
    if data[:1] in (b"$", b":"):
        out = []
        for line in data.split(b"\r\n"):
            if not line:
                continue
            body = line.decode("utf-8").split("*")[0]
            fields = body.split(",")
            for where in (index,) if also is None else (index, also):
                i = 1 + where % max(len(fields) - 1, 1)
                if i < len(fields):
                    fields[i] = value
            text = ",".join(fields).encode("utf-8")
            if text.startswith(b"$"):
                cs = 0
                for c in text[1:]:
                    cs ^= c
                text += b"*%02X" % cs
            out.append(text)
        return b"".join(x + b"\r\n" for x in out)
    raw = bytearray(data[:-2])
    blob = value.encode("utf-8") or b"\xff"
    for where in (index,) if also is None else (index, also):
        at = 4 + where % max(len(raw) - 4, 1)
        raw[at : at + len(blob)] = blob[: max(len(raw) - at, 0)]
    return bytes(raw) + (sum16(bytes(raw)) & 0xFFFF).to_bytes(2, "little")


op = st.tuples(
    st.sampled_from(PORTS),
    st.sampled_from(("valid", "field", "fields", "flip", "cut", "random")),
    st.integers(0, 400),
    st.sampled_from(HOSTILE),
    st.binary(min_size=1, max_size=60),
    st.floats(0.0, 0.7),
)


def _spoilt(data: bytes, how: str, index: int, value: str, noise: bytes) -> bytes:
    """A valid record spoilt as ``how`` says: a hostile value in one field or two (the
    second chosen by the noise), a bit flipped, cut short, or replaced by the noise."""
    if how == "field":
        return _hostile_field(data, index, value)
    if how == "fields":
        return _hostile_field(data, index, value, noise[0])
    if how == "flip":
        i = index % len(data)
        return data[:i] + bytes([data[i] ^ (1 + noise[0] % 255)]) + data[i + 1 :]
    if how == "cut":
        return data[: index % len(data)]
    if how == "random":
        return noise
    return data


def _check_sentence(check: NmeaDecoder, s: str) -> None:
    """An emitted sentence decodes without a reject, its speed finite."""
    recs = check.decode_all((s + "\r\n").encode("ascii"))
    assert recs and not any(isinstance(r, Rejected) for r in recs), s
    for r in recs:
        if isinstance(r, Vhw) and r.stw_mps is not None:
            assert math.isfinite(r.stw_mps), s


def _run(ops: list[tuple[str, str, int, str, bytes, float]]) -> None:
    cfg = parse_config(CONFIG)
    pipeline = Pipeline(*pipeline_from_config(cfg), fusion=fusion_from_config(cfg))
    check = NmeaDecoder("check", errors="yield")
    t = T0.timestamp()
    t_tick = -math.inf
    emitted: list[str] = []
    for k, (port, how, index, value, noise, dt) in enumerate(ops):
        data = _spoilt(_valid(port, k), how, index, value, noise)
        t += dt
        emitted.extend(e.sentence for e in pipeline.feed(t, port, data).emits)
        if t - t_tick >= 0.5:
            t_tick = t
            emitted.extend(e.sentence for e in pipeline.tick(t).emits)
    emitted.extend(e.sentence for e in pipeline.flush().emits)
    pipeline.status()
    for s in emitted:
        if not s.startswith("$PEML"):  # the status and fused sentences are proprietary
            _check_sentence(check, s)
    for name in PORTS:
        assert pipeline.decoders[name].counters.rejects["internal"] == 0, name


def _warm() -> list[tuple[str, str, int, str, bytes, float]]:
    """300 valid records across every port: the UUTs have data to learn from."""
    return [(PORTS[k % len(PORTS)], "valid", 0, "", b"\0", 0.05) for k in range(300)]


@pytest.mark.fuzz
@settings(
    max_examples=by_profile(25, 3000),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(ops=st.lists(op, min_size=1, max_size=by_profile(120, 600)))
def test_hostile_input_never_escapes_the_pipeline(
    ops: list[tuple[str, str, int, str, bytes, float]],
) -> None:
    """Random and mutated sentences of every protocol, after a valid warm-up, go through the
    whole pipeline without an exception, and whatever it emits decodes as valid NMEA (25
    examples of up to 120 records; 3000 of up to 600 in the long profile)."""
    _run(_warm() + ops)


@pytest.mark.parametrize("port", PORTS)
def test_every_hostile_value_in_every_field_of_every_port(port: str) -> None:
    """Each hostile value in each field position and in each pair of the first eight of a port's
    sentences (the fields of the text protocols, a spread of byte offsets of the binary ones:
    an HDG with both deviation and variation 1e308 among them), after a valid warm-up, goes
    through the pipeline without an exception."""
    ops = _warm()
    step = 1 if port in TEXT_PORTS else 7
    for value in HOSTILE:
        for index in range(40):
            ops.append((port, "field", index * step, value, b"\0", 0.05))
        for i in range(8):
            for j in range(i + 1, 8):
                ops.append((port, "fields", i * step, value, bytes([j * step]), 0.05))
    _run(ops)
