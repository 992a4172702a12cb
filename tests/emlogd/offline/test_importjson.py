"""JSON-lines logs (Signal K deltas, canboat analyzer JSON) read by ``emlogd import
--format json``. Synthetic lines written from the documented layouts."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vhw
from drivers.records import KNOT_MPS
from emlogd.offline.importbase import ImportFormatError
from emlogd.offline.importjson import REORDER_S, import_json

T0 = datetime(2025, 6, 27, 10, 40, tzinfo=UTC).timestamp()
SELF = "vessels.urn:mrn:imo:mmsi:230000001"


def _decoded(cap: Path) -> list[object]:
    dec = make_decoder("nmea0183", "nmea")
    return [x for r in CaptureReader(cap) for x in dec.feed(r.data)]


def _times(cap: Path) -> list[float]:
    return [r.t for r in CaptureReader(cap)]


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _delta(t: float, values: dict[str, Any], context: str | None = SELF) -> str:
    doc: dict[str, Any] = {
        "updates": [
            {
                "source": {"label": "can0", "type": "NMEA2000"},
                "timestamp": _iso(t),
                "values": [{"path": p, "value": v} for p, v in values.items()],
            }
        ]
    }
    if context is not None:
        doc["context"] = context
    return json.dumps(doc)


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(ln + "\n" for ln in lines))
    return path


class TestSignalK:
    def test_si_units_and_the_own_boat(self, tmp_path: Path) -> None:
        """Radians become degrees and m/s stay m/s; an AIS target's deltas (another
        context) are not the boat's; the position and variation go into RMC."""
        lines = [
            _delta(T0, {"navigation.magneticVariation": math.radians(-2.5)}),
            _delta(T0, {"navigation.headingTrue": math.radians(90.0)}),
            _delta(T0 + 0.1, {"navigation.speedThroughWater": 2.5}),
            _delta(
                T0 + 0.5,
                {
                    "navigation.position": {"latitude": 43.5, "longitude": -5.25},
                    "navigation.speedOverGround": 2.6,
                    "navigation.courseOverGroundTrue": math.radians(95.0),
                },
            ),
            _delta(
                T0 + 0.6,
                {"navigation.speedOverGround": 9.0, "navigation.speedThroughWater": 9.0},
                "vessels.urn:mrn:imo:mmsi:211111111",
            ),
            _delta(T0 + 1.1, {"navigation.speedThroughWater": 2.7}, None),  # no context: own
        ]
        rep = import_json([_write(tmp_path / "sk.json", lines)], tmp_path / "o.cap")
        assert rep.sentences == {"VHW": 2, "RMC": 1}
        assert rep.skipped == {"other_vessel": 1}
        assert rep.heading_ref == "true" and rep.notes["signalk_contexts"] == 2
        recs = _decoded(tmp_path / "o.cap")
        vhw = [x for x in recs if isinstance(x, Vhw)]
        assert [v.stw_knots for v in vhw] == [
            pytest.approx(2.5 / KNOT_MPS, abs=0.01),
            pytest.approx(2.7 / KNOT_MPS, abs=0.01),
        ]
        assert vhw[0].heading_true_deg == pytest.approx(90.0)
        (rmc,) = [x for x in recs if isinstance(x, Rmc)]
        assert rmc.sog_mps == pytest.approx(2.6, abs=0.01)
        assert rmc.cog_true_deg == pytest.approx(95.0)
        assert rmc.lat_deg == pytest.approx(43.5) and rmc.lon_deg == pytest.approx(-5.25)
        assert rmc.variation_deg == pytest.approx(-2.5)
        assert _times(tmp_path / "o.cap") == pytest.approx([T0 + 0.1, T0 + 0.5, T0 + 1.1])

    def test_magnetic_heading_and_bad_lines(self, tmp_path: Path) -> None:
        """A magnetic heading alone goes into VHW's magnetic field; unreadable lines,
        times and values are counted by reason."""
        lines = [
            "not json at all",
            "1751020800000;I;" + _delta(T0, {"navigation.headingMagnetic": math.radians(10.0)}),
            json.dumps({"updates": [{"values": [{"path": "navigation.speedThroughWater"}]}]}),
            _delta(T0 + 0.2, {"navigation.speedThroughWater": 2.0}),
            _delta(T0 + 0.3, {"navigation.speedThroughWater": 99.0}),
            _delta(T0 + 0.4, {"environment.depth.belowTransducer": 12.0}),
            json.dumps({"updates": [{"timestamp": "yesterday", "values": []}]}),
        ]
        rep = import_json([_write(tmp_path / "sk.json", lines)], tmp_path / "o.cap")
        assert rep.sentences == {"VHW": 1}
        assert rep.skipped == {"not_a_message": 1, "no_time": 1, "no_value": 2, "bad_time": 1}
        assert rep.cells == {"stw: out_of_range": 1}
        assert rep.heading_ref == "magnetic" and rep.variation == "none"
        (vhw,) = [x for x in _decoded(tmp_path / "o.cap") if isinstance(x, Vhw)]
        assert vhw.heading_mag_deg == pytest.approx(10.0) and vhw.heading_true_deg is None

    def test_out_of_order_within_the_window(self, tmp_path: Path) -> None:
        """Messages a second out of order are written in order; one later than
        REORDER_S behind what was written is counted."""
        stw = "navigation.speedThroughWater"
        lines = [
            _delta(T0 + 1.0, {stw: 2.0}),
            _delta(T0 + 0.5, {stw: 2.1}),
            _delta(T0 + 2.0 + REORDER_S, {stw: 2.2}),
            _delta(T0 + 0.2, {stw: 2.3}),
        ]
        rep = import_json([_write(tmp_path / "sk.json", lines)], tmp_path / "o.cap")
        assert _times(tmp_path / "o.cap") == pytest.approx([T0 + 0.5, T0 + 1.0, T0 + 2 + REORDER_S])
        assert rep.skipped == {"time_going_back": 1}


def _n2k(stamp: str, pgn: int, fields: dict[str, Any]) -> str:
    return json.dumps(
        {"timestamp": stamp, "prio": 2, "src": 35, "dst": 255, "pgn": pgn, "fields": fields}
    )


class TestCanboat:
    def test_pgns_in_the_analyzers_units(self, tmp_path: Path) -> None:
        """Speeds in m/s and angles in degrees, values as strings or numbers, both time
        stamps; the heading's Reference says true or magnetic; a magnetic COG is not
        used; PGNs not read are counted."""
        lines = [
            _n2k("2025-06-27-10:40:00.000", 127250, {"Heading": "200.0", "Reference": "Magnetic"}),
            _n2k("2025-06-27T10:40:00.100Z", 128259, {"Speed Water Referenced": "3.00"}),
            _n2k("2025-06-27T10:40:00.200Z", 129025, {"Latitude": 50.1, "Longitude": -1.2}),
            _n2k(
                "2025-06-27T10:40:00.300Z",
                129026,
                {"COG Reference": "True", "COG": 210.0, "SOG": 3.1},
            ),
            _n2k("2025-06-27T10:40:00.400Z", 130306, {"Wind Speed": 5.0, "Wind Angle": 40.0}),
            _n2k(
                "2025-06-27T10:40:00.500Z",
                129026,
                {"COG Reference": "Magnetic", "COG": 212.0, "SOG": 3.2},
            ),
            _n2k(
                "2025-06-27T10:40:01.000Z", 127250, {"Heading": 20.0, "Reference": {"name": "True"}}
            ),
            _n2k("2025-06-27T10:40:01.100Z", 128259, {"Speed Water Referenced": 3.05}),
        ]
        rep = import_json([_write(tmp_path / "n2k.json", lines)], tmp_path / "o.cap")
        assert rep.sentences == {"VHW": 2, "RMC": 2}
        assert rep.skipped == {"pgn_not_read": 1}
        assert rep.cells == {"cog: cog_not_true": 1}
        recs = _decoded(tmp_path / "o.cap")
        vhw = [x for x in recs if isinstance(x, Vhw)]
        assert vhw[0].heading_mag_deg == pytest.approx(200.0) and vhw[0].heading_true_deg is None
        assert vhw[1].heading_true_deg == pytest.approx(20.0)
        assert vhw[0].stw_knots == pytest.approx(3.0 / KNOT_MPS, abs=0.01)
        rmc = [x for x in recs if isinstance(x, Rmc)]
        assert rmc[0].cog_true_deg == pytest.approx(210.0) and rmc[0].lat_deg == pytest.approx(50.1)
        assert rmc[1].cog_true_deg == pytest.approx(210.0)  # the magnetic COG left out
        assert rmc[1].sog_mps == pytest.approx(3.2, abs=0.01)

    def test_no_water_speed_is_a_clear_error(self, tmp_path: Path) -> None:
        """A log without a speed through the water names what it needs."""
        lines = [
            _n2k("2025-06-27T10:40:00Z", 129026, {"COG Reference": "True", "COG": 1, "SOG": 2})
        ]
        src = _write(tmp_path / "n2k.json", lines)
        with pytest.raises(ImportFormatError, match="Speed Water Referenced") as err:
            import_json([src], tmp_path / "o.cap")
        assert "speedThroughWater" in str(err.value) and str(src) in str(err.value)
        assert not (tmp_path / "o.cap").exists()


def test_an_nmea_log_given_as_json_is_named(tmp_path: Path) -> None:
    """An NMEA 0183 log imported with --format json: the error says what it looks like."""
    src = _write(tmp_path / "log.nmea", ["$IIVHW,,,263,M,01.0,N,,*62"] * 3)
    with pytest.raises(ImportFormatError, match="looks like an NMEA 0183 log"):
        import_json([src], tmp_path / "o.cap")
