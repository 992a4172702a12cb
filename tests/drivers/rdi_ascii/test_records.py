"""PD6/PD13 records: the line order an ensemble is assembled in, the record members, the
bottom range read from :BD."""

from __future__ import annotations

import dataclasses

from drivers.rdi_ascii.records import (
    ORDER,
    RECORD_PARTS,
    RECORDS,
    DistanceMadeGood,
    Pd6Ensemble,
    PdHealth,
    Velocity,
)


def _ensemble(bottom_dmg: DistanceMadeGood | None) -> Pd6Ensemble:
    return Pd6Ensemble(
        pitch_deg=0.0,
        roll_deg=0.0,
        heading_deg=90.0,
        timestamp="25061208000123",
        salinity_ppt=35.0,
        temperature_c=15.0,
        depth_m=0.0,
        sound_speed_mps=1500.0,
        bit=0,
        pressure_kpa=None,
        beam_ranges_m=None,
        water_instrument=None,
        water_ship=None,
        water_earth=None,
        water_dmg=None,
        bottom_instrument=None,
        bottom_ship=Velocity(0.1, 1.5, 0.0),
        bottom_earth=None,
        bottom_dmg=bottom_dmg,
    )


def test_an_ensemble_starts_at_sa_and_ends_at_bd() -> None:
    """The line order opens with :SA and :TS and closes with the bottom-track lines, :BD last,
    each line type once."""
    assert ORDER[:2] == ("SA", "TS") and ORDER[-4:] == ("BI", "BS", "BE", "BD")
    assert len(set(ORDER)) == len(ORDER)


def test_the_records_are_the_ensemble_and_the_health_line() -> None:
    """The yielded records are the ensemble and the :HM health line; the velocity and the
    distance made good are parts of an ensemble only."""
    assert (Pd6Ensemble, PdHealth) == RECORDS
    assert (Velocity, DistanceMadeGood) == RECORD_PARTS
    assert all(dataclasses.is_dataclass(cls) for cls in RECORDS + RECORD_PARTS)


def test_the_bottom_range_is_the_range_of_bd() -> None:
    """An ensemble's bottom range is its :BD range, and None when :BD was not sent."""
    dmg = DistanceMadeGood(east_m=1.0, north_m=2.0, up_m=0.0, range_m=7.13, time_since_good_s=0.0)
    assert _ensemble(dmg).bottom_range_m == 7.13
    assert _ensemble(None).bottom_range_m is None
