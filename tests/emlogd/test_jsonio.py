"""JSON views of records."""

from __future__ import annotations

import json
from datetime import UTC, datetime

from drivers.records import SpeedRecord
from emlogd.jsonio import to_jsonable


class TestToJsonable:
    """to_jsonable gives plain JSON types."""

    def test_record_has_type_and_fields(self) -> None:
        """A dataclass becomes a dict with its class name under 'type'."""
        rec = SpeedRecord(
            port="emlog1",
            kind="stw",
            role="speed",
            longitudinal_mps=1.5,
            valid=True,
            heading_true_deg=10.0,
            source="VHW",
        )
        d = to_jsonable(rec)
        assert d["type"] == "SpeedRecord"
        assert d["longitudinal_mps"] == 1.5
        assert d["transverse_mps"] is None
        json.dumps(d)

    def test_nested_and_special_values(self) -> None:
        """Datetimes, bytes, tuples and non-finite floats are converted."""
        t = datetime(2025, 6, 1, 6, 0, tzinfo=UTC)
        d = to_jsonable({"record": {"when": t, "raw": b"\x01\xff", "v": (1, float("nan"))}})
        assert d["record"] == {"when": t.isoformat(), "raw": "01ff", "v": [1, None]}
