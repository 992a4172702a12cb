"""NMEA 2000 in canboat's plain text: lines written from the PGNs' layouts, decoded
into the analyzer's fields and imported by ``emlogd import --format n2k``."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw
from emlogd.offline.importjson import import_json
from emlogd.offline.importn2k import plain_message

STAMP = "2016-04-09T16:41:39.628Z"


def _line(pgn: int, data: bytes, stamp: str = STAMP, prefix: str = "") -> str:
    hexes = ",".join(f"{b:02x}" for b in data)
    return f"{prefix}{stamp},2,{pgn},7,255,{len(data)},{hexes}"


def _heading(rad: float, var_rad: float | None, ref: int) -> bytes:
    var = 0x7FFF if var_rad is None else round(var_rad * 1e4)
    return struct.pack("<BHhhB", 0, round(rad * 1e4), 0x7FFF, var, 0xFC | ref)


def _speed(mps: float) -> bytes:
    return struct.pack("<BHHBBB", 0, round(mps * 100), 0xFFFF, 0, 0xFF, 0xFF)


def _cog_sog(cog_rad: float, sog_mps: float, ref: int = 0) -> bytes:
    return struct.pack("<BBHHH", 0, 0xFC | ref, round(cog_rad * 1e4), round(sog_mps * 100), 0xFFFF)


def _position(lat: float, lon: float) -> bytes:
    return struct.pack("<ii", round(lat * 1e7), round(lon * 1e7))


def test_the_pgns_layouts_are_decoded() -> None:
    """Heading, speed, COG/SOG, position and variation in the analyzer's units; a field
    of all ones is no value; a line of another PGN has no fields; text is no line."""
    msg = plain_message(_line(127250, _heading(math.radians(200.0), math.radians(-1.5), 1)))
    assert msg is not None and msg["pgn"] == 127250 and msg["timestamp"] == STAMP
    assert msg["fields"] == {
        "Heading": pytest.approx(200.0, abs=0.01),
        "Variation": pytest.approx(-1.5, abs=0.01),
        "Reference": "Magnetic",
    }
    msg = plain_message(_line(128259, _speed(3.21), prefix="1460220099628;A;"))
    assert msg is not None and msg["fields"] == {"Speed Water Referenced": pytest.approx(3.21)}
    msg = plain_message(_line(129026, _cog_sog(math.radians(350.0), 4.5)))
    assert msg is not None and msg["fields"] == {
        "COG Reference": "True",
        "COG": pytest.approx(350.0, abs=0.01),
        "SOG": pytest.approx(4.5),
    }
    msg = plain_message(_line(129025, _position(-33.5, 151.25)))
    assert msg is not None
    assert msg["fields"] == {"Latitude": pytest.approx(-33.5), "Longitude": pytest.approx(151.25)}
    data = struct.pack("<BBHhH", 0, 0, 0xFFFF, round(math.radians(2.0) * 1e4), 0xFFFF)
    msg = plain_message(_line(127258, data))
    assert msg is not None and msg["fields"] == {"Variation": pytest.approx(2.0, abs=0.01)}
    msg = plain_message(_line(130306, bytes(8)))
    assert msg is not None and msg["fields"] == {}
    assert plain_message("$IIVHW,,,263,M,01.0,N,,*62") is None


def test_a_plain_log_imports(tmp_path: Path) -> None:
    """A log of the four PGNs becomes VHW with the magnetic heading and RMC with the
    position; PGNs not read are counted."""
    lines = [
        _line(
            127250, _heading(math.radians(10.0), math.radians(2.0), 1), "2016-04-09-16:41:39.000"
        ),
        _line(128259, _speed(2.5), "2016-04-09T16:41:39.100Z"),
        _line(129025, _position(59.5, 10.5), "2016-04-09T16:41:39.200Z"),
        _line(129026, _cog_sog(math.radians(15.0), 2.6), "2016-04-09T16:41:39.300Z"),
        _line(130306, bytes(8), "2016-04-09T16:41:39.400Z"),
    ]
    src = tmp_path / "n2k.log"
    src.write_text("\n".join(lines) + "\n")
    rep = import_json([src], tmp_path / "o.cap")
    assert rep.sentences == {"VHW": 1, "RMC": 1} and rep.skipped == {"pgn_not_read": 1}
    assert rep.heading_ref == "magnetic" and rep.variation == "column"
    dec = make_decoder("nmea0183", "nmea")
    recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
    (vhw,) = [x for x in recs if isinstance(x, Vhw)]
    assert vhw.heading_mag_deg == pytest.approx(10.0) and vhw.stw_mps == pytest.approx(
        2.5, abs=0.01
    )
    (rmc,) = [x for x in recs if isinstance(x, Rmc)]
    assert rmc.lat_deg == pytest.approx(59.5) and rmc.cog_true_deg == pytest.approx(15.0)
    assert rmc.variation_deg == pytest.approx(2.0)
