"""Common records: SpeedRecord, units."""

from __future__ import annotations

import dataclasses
import math

import pytest

from drivers.errors import OutOfRangeError
from drivers.records import (
    KMH_MPS,
    KNOT_MPS,
    PHYSICAL_RANGES,
    SpeedRecord,
    check_ranges,
)


def _speed(lon: float | None, tr: float | None) -> SpeedRecord:
    return SpeedRecord(
        port="p",
        kind="stw",
        role="speed",
        longitudinal_mps=lon,
        transverse_mps=tr,
        valid=True,
        source="VBW",
    )


class TestSpeedRecord:
    """The common speed record."""

    def test_built_by_keyword_only(self) -> None:
        """A speed record (nine fields) is built by keyword: positional arguments are refused,
        and the transverse speed and both headings default to None."""
        with pytest.raises(TypeError):
            SpeedRecord("p", "stw", "speed", 1.0, None, True, None, None, "VHW")  # type: ignore[call-arg]
        rec = SpeedRecord(
            port="p", kind="stw", role="speed", longitudinal_mps=1.0, valid=True, source="VHW"
        )
        assert (rec.transverse_mps, rec.heading_true_deg, rec.heading_mag_deg) == (None,) * 3

    def test_magnitude_uses_both_axes(self) -> None:
        """speed_mps is the horizontal magnitude when the transverse axis is known."""
        assert _speed(3.0, -4.0).speed_mps == pytest.approx(5.0)

    def test_magnitude_of_single_axis(self) -> None:
        """Without a transverse value the magnitude is |longitudinal|."""
        assert _speed(-1.5, None).speed_mps == 1.5
        assert _speed(None, None).speed_mps is None

    def test_frozen(self) -> None:
        """Records cannot be modified after creation."""
        with pytest.raises(dataclasses.FrozenInstanceError):
            _speed(1.0, None).valid = False  # type: ignore[misc]

    def test_compared_by_value(self) -> None:
        """Two records with the same fields are equal (not identity equality)."""
        assert _speed(1.0, 0.5) == _speed(1.0, 0.5)
        assert _speed(1.0, None) != _speed(1.0, 0.5)


class TestUnits:
    """Unit constants."""

    def test_knot_and_kmh(self) -> None:
        """1 kn = 1852/3600 m/s and 1 km/h = 1/3.6 m/s exactly."""
        assert pytest.approx(0.514444, abs=1e-6) == KNOT_MPS
        assert pytest.approx(KNOT_MPS) == 1.852 * KMH_MPS


class TestCheckRanges:
    """The one physical-range check every RDI decoder applies."""

    @pytest.mark.parametrize("name", sorted(PHYSICAL_RANGES))
    def test_bounds_are_closed_and_nan_is_outside(self, name: str) -> None:
        """Each bound is within its field's range; a step past either, or NaN, is refused
        with the field's name in the message."""
        lo, hi = PHYSICAL_RANGES[name]
        check_ranges("X", b"raw", **{name: lo})
        check_ranges("X", b"raw", **{name: hi})
        for bad in (lo - 0.01, hi + 0.01, math.nan):
            with pytest.raises(OutOfRangeError, match=name.replace("_", " ")) as err:
                check_ranges("X", b"raw", **{name: bad})
            assert err.value.raw == b"raw"

    def test_names_every_field_outside(self) -> None:
        """Two fields outside and one within: both outside are named, the good one is not."""
        with pytest.raises(OutOfRangeError) as err:
            check_ranges(":TS", b"", salinity=60.0, depth=10.0, sound_speed=900.0)
        text = str(err.value)
        assert "salinity 60.0" in text and "sound speed 900.0" in text and "depth" not in text
