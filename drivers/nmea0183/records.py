"""NMEA 0183 records: one frozen, slotted dataclass per decoded sentence.

Units: m/s, degrees, nautical miles, °C (see the package's docstring).

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import TypeAlias, get_args


@dataclass(frozen=True, slots=True, kw_only=True)
class Vhw:
    """VHW — water speed and heading.

    Attributes:
        talker: the two-character talker ID (metadata only).
        heading_true_deg: true heading, deg, or None.
        heading_mag_deg: magnetic heading, deg, or None.
        stw_knots: speed through water as sent in knots, or None.
        stw_kmh: speed through water as sent in km/h, or None.
        stw_mps: speed through water in m/s (from knots, else km/h), or None when
            both are empty (the record then gives an invalid speed record).
    """

    talker: str
    heading_true_deg: float | None
    heading_mag_deg: float | None
    stw_knots: float | None
    stw_kmh: float | None
    stw_mps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Vbw:
    """VBW — dual ground/water speed (6- or 10-field form), m/s, + ahead / + starboard."""

    talker: str
    water_long_mps: float | None
    water_trans_mps: float | None
    water_valid: bool
    ground_long_mps: float | None
    ground_trans_mps: float | None
    ground_valid: bool
    stern_water_mps: float | None = None
    stern_water_valid: bool = False
    stern_ground_mps: float | None = None
    stern_ground_valid: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class Vlw:
    """VLW — distances in nautical miles (ground pair: NMEA 3 8-field form)."""

    talker: str
    total_nm: float | None
    trip_nm: float | None
    ground_total_nm: float | None = None
    ground_trip_nm: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Mtw:
    """MTW — water temperature in °C (None when the field is empty)."""

    talker: str
    temperature_c: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Heading:
    """HDT, HDG, HDM or THS.

    Attributes:
        talker: talker ID.
        sentence: ``"HDT"``, ``"HDG"``, ``"HDM"`` or ``"THS"``.
        heading_deg: the heading as sent (HDG: magnetic *sensor* heading), or None.
        true: the heading is true (HDT, THS).
        deviation_deg: HDG deviation, + east, or None.
        variation_deg: HDG variation, + east, or None.
    """

    talker: str
    sentence: str
    heading_deg: float | None
    true: bool
    deviation_deg: float | None = None
    variation_deg: float | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class Prti:
    """Rowe $PRTI01 (instrument frame) or $PRTI02 (earth frame).

    Attributes:
        sentence: ``"PRTI01"`` or ``"PRTI02"``.
        start_time_s: sample start time since power-up, s.
        sample: ensemble number.
        temperature_c: water temperature, °C.
        bottom_mps: bottom-track (X, Y, Z) or (E, N, U), m/s; None when invalid.
        bottom_depth_m: range to bottom, m (0 = no bottom).
        water_mps: water-mass (X, Y, Z) or (E, N, U), m/s; None when invalid or empty.
        water_depth_m: water-mass layer depth, m, or None.
        status: status word (bit 0x0004 BT hold, 0x0008 BT searching).
        subsystem: subsystem code (14-field form), or None.
        cepo_index: CEPO index (14-field form), or None.
    """

    sentence: str
    start_time_s: float
    sample: int
    temperature_c: float
    bottom_mps: tuple[float, float, float] | None
    bottom_depth_m: float
    water_mps: tuple[float, float, float] | None
    water_depth_m: float | None
    status: int
    subsystem: str | None = None
    cepo_index: int | None = None

    @property
    def bottom_valid(self) -> bool:
        """Bottom track usable: velocities valid, a bottom found, not hold/searching."""
        return self.bottom_mps is not None and self.bottom_depth_m > 0 and not self.status & 0x000C


GNSS_INVALID_MODES = frozenset("NEMS")
"""NMEA 2.3+ mode indicators that are not a measured fix: not valid, estimated (dead
reckoning), manual input, simulator."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Rmc:
    """RMC — recommended minimum GNSS data.

    Attributes:
        talker: talker ID (``GP``, ``GN``, ``GL``...).
        time_utc: date and time of the fix (aware UTC), or None when either is empty.
        time_of_day_s: seconds since midnight UTC, or None.
        status_active: status ``A`` (else ``V``, void).
        lat_deg: latitude, degrees, + north, or None.
        lon_deg: longitude, degrees, + east, or None.
        sog_mps: speed over ground, m/s, or None.
        cog_true_deg: course over ground, degrees true, or None.
        variation_deg: magnetic variation, degrees, + east, or None.
        mode: the NMEA 2.3+ mode indicator (``A`` autonomous, ``D`` differential, ``E``
            estimated, ``N`` not valid...), or None on older receivers.
    """

    talker: str
    time_utc: datetime | None
    time_of_day_s: float | None
    status_active: bool
    lat_deg: float | None
    lon_deg: float | None
    sog_mps: float | None
    cog_true_deg: float | None
    variation_deg: float | None
    mode: str | None

    @property
    def valid(self) -> bool:
        """An active fix from a measured mode, with a speed."""
        return (
            self.status_active
            and self.sog_mps is not None
            and (self.mode is None or self.mode not in GNSS_INVALID_MODES)
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Vtg:
    """VTG — course and speed over ground (m/s, degrees)."""

    talker: str
    cog_true_deg: float | None
    cog_mag_deg: float | None
    sog_mps: float | None
    mode: str | None

    @property
    def valid(self) -> bool:
        """A speed from a measured mode."""
        return self.sog_mps is not None and (
            self.mode is None or self.mode not in GNSS_INVALID_MODES
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Gga:
    """GGA — fix data: time of day, position and fix quality (0 = no fix)."""

    talker: str
    time_of_day_s: float | None
    lat_deg: float | None
    lon_deg: float | None
    quality: int
    satellites: int | None
    hdop: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Gll:
    """GLL — position and time of day (NMEA 2.0+; 1.5's four fields carry no time).

    Parsed for the import's timing of a log whose GNSS sends GLL alone
    (:mod:`emlogd.offline.importnmea`); the decoder does not yield it, so it is no member
    of :data:`NmeaRecord` (the live pipeline takes positions from RMC and GGA).

    Attributes:
        talker: talker ID.
        lat_deg: latitude, degrees, + north, or None.
        lon_deg: longitude, degrees, + east, or None.
        time_of_day_s: seconds since midnight UTC, or None.
        status_active: status ``A`` (an empty status counts as active: NMEA 1.5).
        mode: the NMEA 2.3+ mode indicator, or None.
    """

    talker: str
    lat_deg: float | None
    lon_deg: float | None
    time_of_day_s: float | None
    status_active: bool
    mode: str | None

    @property
    def valid(self) -> bool:
        """An active fix from a measured mode."""
        return self.status_active and (self.mode is None or self.mode not in GNSS_INVALID_MODES)


@dataclass(frozen=True, slots=True, kw_only=True)
class Zda:
    """ZDA — UTC date and time (aware), or None when a field is empty."""

    talker: str
    time_utc: datetime | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Vdr:
    """VDR — set and drift of the current (set: the direction it flows towards)."""

    talker: str
    set_true_deg: float | None
    set_mag_deg: float | None
    drift_mps: float | None


NmeaRecord: TypeAlias = Vhw | Vbw | Vlw | Mtw | Heading | Prti | Rmc | Vtg | Gga | Zda | Vdr
"""Every record :class:`NmeaDecoder` yields (besides :class:`~drivers.records.Rejected`)."""

RECORDS: tuple[type[NmeaRecord], ...] = get_args(NmeaRecord)
"""The members of :data:`NmeaRecord`, in its order."""
