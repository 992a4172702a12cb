"""What the RDI formats share (drivers.rdi): the bottom track's mapping and the bad-value marker."""

from __future__ import annotations

from typing import Literal

import pytest

from drivers import rdi


class TestBottomTrack:
    """The one mapping of an RDI binary bottom track (PD0, PD4/PD5) to a speed record."""

    def test_ship_and_earth_frames(self) -> None:
        """Ship coordinates are (starboard, forward); earth coordinates (east, north) are
        rotated by the heading (heading 90: east is forward, north is to port)."""
        ship = rdi.bottom_track("d", "ship", True, (300, 2000), 10.0, "PD0:BT")
        assert (ship.longitudinal_mps, ship.transverse_mps, ship.valid) == (2.0, 0.3, True)
        earth = rdi.bottom_track("d", "earth", True, (2000, 300), 90.0, "PD0:BT")
        assert earth.longitudinal_mps == pytest.approx(2.0)
        assert earth.transverse_mps == pytest.approx(-0.3)
        assert (earth.heading_true_deg, earth.role, earth.kind) == (90.0, "bottom", "sog")

    @pytest.mark.parametrize(
        ("frame", "lock", "vessel", "heading"),
        [
            ("beam", True, (300, 2000), 10.0),
            ("ship", False, (300, 2000), 10.0),
            ("ship", True, (None, 2000), 10.0),
            ("earth", True, (300, 2000), None),
        ],
    )
    def test_no_track_is_an_invalid_record(
        self,
        frame: Literal["beam", "ship", "earth"],
        lock: bool,
        vessel: tuple[int | None, int | None],
        heading: float | None,
    ) -> None:
        """Beam coordinates, no bottom lock, a bad component, or earth coordinates without
        a heading: an invalid record with no speed (the pipeline sees the loss)."""
        rec = rdi.bottom_track("d", frame, lock, vessel, heading, "PD5:BT")
        assert (rec.valid, rec.longitudinal_mps, rec.transverse_mps) == (False, None, None)

    @pytest.mark.parametrize("frame", ["ship", "instrument", "earth"])
    def test_the_encoders_mapping_is_its_inverse(
        self, frame: Literal["ship", "instrument", "earth"]
    ) -> None:
        """What rdi.vessel_mms writes, rdi.bottom_track reads back as the same
        (forward, starboard) motion, to the millimetre, at any heading."""
        for heading in (0.0, 37.0, 200.0):
            a, b = rdi.vessel_mms((2.5, -0.4), frame, heading)
            rec = rdi.bottom_track("d", frame, True, (a, b), heading, "PD0:BT")
            assert rec.longitudinal_mps == pytest.approx(2.5, abs=1e-3)
            assert rec.transverse_mps == pytest.approx(-0.4, abs=1e-3)

    def test_invalid_marker_reads_as_none(self) -> None:
        """-32768 is None; every other value, the extremes included, is kept."""
        assert rdi.velocities((rdi.INVALID, -32767, 0, 32767)) == (None, -32767, 0, 32767)
