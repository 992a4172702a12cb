"""Teledyne-RDI PD0 binary ensembles (Rowe SeaPILOT emulates them).

Layout (docs/PROTOCOLS.md §5.3, little-endian): header ``7F 7F``, byte count (without
the checksum), a spare byte, the number of data types and their offsets; then the
data types, found through the offset table (unknown IDs are skipped, no fixed
layout is assumed): fixed leader ``0x0000`` (coordinate frame in the EX byte, bits
4–3), variable leader ``0x0080`` (ensemble number with its MSB, RTC, heading /
pitch / roll in 0.01°), bottom track ``0x0600`` (ranges in cm, 0 = no bottom;
velocities in mm/s, −32768 = bad). The 16-bit sum of every byte before the
checksum must match; after a corrupted ensemble the decoder resynchronises on the
next header (:mod:`drivers.binframe`).

**Sign convention.** PD0 bottom-track velocity is the velocity of the *bottom
relative to the instrument*; the vessel's motion is its negation. In ship
coordinates the components are (starboard, forward, mast, error), so the speed
record is ``longitudinal = −v2``, ``transverse = −v1`` (PD6 ``:BS`` is already the
vessel's motion: the two formats differ in sign). Earth coordinates (East, North)
are rotated into the ship frame with the ensemble's heading; instrument
coordinates are taken as aligned with the ship (X starboard, Y forward: beam 3
forward, heading alignment ignored); beam coordinates give an invalid record.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from datetime import datetime
from typing import ClassVar, TypeAlias

from drivers import rdi
from drivers.base import FramedDecoder, Framer, Use
from drivers.binframe import BinaryFramer, sum16
from drivers.errors import FieldError, OutOfRangeError
from drivers.records import SpeedRecord, check_ranges

HEADER = b"\x7f\x7f"
MAX_ENSEMBLE = 16384
"""Largest plausible ensemble in bytes (header sanity check while resynchronising)."""

FIXED_LEADER = 0x0000
VARIABLE_LEADER = 0x0080
BOTTOM_TRACK = 0x0600
FREQUENCIES_KHZ = (75, 150, 300, 600, 1200, 2400, 38, 0)


@dataclass(frozen=True, slots=True)
class Pd0Ensemble:
    """The fields emlogd uses from one PD0 ensemble.

    Attributes:
        ensemble_number: ensemble number (MSB included).
        rtc: real-time clock (year % 100, month, day, hour, minute, second, hundredths).
        coord_frame: coordinate frame of the velocities (EX bits 4–3).
        n_beams: number of beams.
        n_cells: number of depth cells.
        frequency_khz: system frequency from the configuration word.
        serial_number: instrument serial number (None on a short fixed leader).
        heading_deg, pitch_deg, roll_deg: attitude, degrees.
        temperature_c: water temperature, °C.
        salinity_ppt: salinity.
        sound_speed_mps: speed of sound.
        depth_m: transducer depth, m.
        bt_velocity_mms: bottom-track velocities 1–4 in mm/s as sent (None = −32768),
            None without a bottom-track block.
        bt_range_cm: bottom ranges of beams 1–4 in cm (0 = no bottom).
        data_types: the data-type IDs in the ensemble, in order.
    """

    ensemble_number: int
    rtc: tuple[int, int, int, int, int, int, int]
    coord_frame: rdi.CoordFrame
    n_beams: int
    n_cells: int
    frequency_khz: int
    serial_number: int | None
    heading_deg: float
    pitch_deg: float
    roll_deg: float
    temperature_c: float
    salinity_ppt: float
    sound_speed_mps: float
    depth_m: float
    bt_velocity_mms: tuple[int | None, int | None, int | None, int | None] | None
    bt_range_cm: tuple[int, int, int, int] | None
    data_types: tuple[int, ...]

    @property
    def bottom_lock(self) -> bool:
        """Bottom track present with valid velocities 1–3 and some bottom range."""
        v, r = self.bt_velocity_mms, self.bt_range_cm
        return v is not None and r is not None and None not in v[:3] and any(x > 0 for x in r)


Pd0Record: TypeAlias = Pd0Ensemble
"""Every record :class:`Pd0Decoder` yields (besides :class:`~drivers.records.Rejected`):
one type, named like the other protocols' unions."""

RECORDS: tuple[type[Pd0Record], ...] = (Pd0Ensemble,)
"""The members of :data:`Pd0Record`."""


def _length_of(buf: bytearray) -> int | None:
    n = buf[2] | buf[3] << 8
    ndt = buf[5]
    if not 1 <= ndt <= 32 or not 6 + 2 * ndt <= n <= MAX_ENSEMBLE:
        return None
    return n


class Pd0Decoder(FramedDecoder[Pd0Record]):
    """PD0 decoder (see the module docstring)."""

    protocol: ClassVar[str] = "pd0"
    binary: ClassVar[bool] = True
    uses: ClassVar[frozenset[Use]] = frozenset({"bottom"})
    heading: ClassVar[bool] = True
    """The variable leader's heading."""

    def _make_framer(self) -> Framer:
        return BinaryFramer(HEADER, _length_of, 6, "PD0")

    def parse_frame(self, frame: bytes) -> Pd0Record:
        """Decode one checksum-verified ensemble (without its checksum).

        Raises:
            FieldError: missing leaders, offsets out of the ensemble, short blocks.
        """
        n = len(frame)
        ndt = frame[5]
        offsets = struct.unpack_from(f"<{ndt}H", frame, 6)
        blocks: dict[int, int] = {}
        ids = []
        for off in offsets:
            if not 6 + 2 * ndt <= off <= n - 2:
                raise FieldError(f"data-type offset {off} outside the ensemble ({n} bytes)", frame)
            dtid = struct.unpack_from("<H", frame, off)[0]
            ids.append(dtid)
            blocks.setdefault(dtid, off)
        ends: list[int] = sorted([*(int(o) for o in offsets), n])

        def size(off: int) -> int:
            return int(next(e for e in ends if e > off)) - off

        fl = blocks.get(FIXED_LEADER)
        vl = blocks.get(VARIABLE_LEADER)
        if fl is None or vl is None:
            raise FieldError("PD0 ensemble without fixed or variable leader", frame)
        if size(fl) < 42 or size(vl) < 28:
            raise FieldError("PD0 leader too short", frame)
        config = struct.unpack_from("<H", frame, fl + 4)[0]
        n_beams, n_cells = frame[fl + 8], frame[fl + 9]
        ex = frame[fl + 25]
        serial = struct.unpack_from("<I", frame, fl + 54)[0] if size(fl) >= 58 else None
        ens = struct.unpack_from("<H", frame, vl + 2)[0] | frame[vl + 11] << 16
        rtc = struct.unpack_from("<7B", frame, vl + 4)
        c, depth_dm, heading, pitch, roll, sal, temp = struct.unpack_from(
            "<HHHhhHh", frame, vl + 14
        )
        check_ranges(
            "variable leader",
            frame,
            heading=heading / 100.0,
            pitch=pitch / 100.0,
            roll=roll / 100.0,
            temperature=temp / 100.0,
            salinity=sal,
            sound_speed=c,
            depth=depth_dm / 10.0,
        )
        _, mo, d, h, mi, sec, hs = rtc
        if not (1 <= mo <= 12 and 1 <= d <= 31 and h < 24 and mi < 60 and sec < 60 and hs < 100):
            raise OutOfRangeError(f"real-time clock {rtc} is no date and time", frame)
        bt_v = bt_r = None
        bt = blocks.get(BOTTOM_TRACK)
        if bt is not None:
            if size(bt) < 32:
                raise FieldError("PD0 bottom-track block too short", frame)
            r = struct.unpack_from("<4H", frame, bt + 16)
            if size(bt) >= 81:
                msb = frame[bt + 77 : bt + 81]
                r = tuple(lo + (hi << 16) for lo, hi in zip(r, msb, strict=True))
            v = struct.unpack_from("<4h", frame, bt + 24)
            bt_v = rdi.velocities(v)
            bt_r = (r[0], r[1], r[2], r[3])
        return Pd0Ensemble(
            ensemble_number=ens,
            rtc=(rtc[0], rtc[1], rtc[2], rtc[3], rtc[4], rtc[5], rtc[6]),
            coord_frame=rdi.COORD_FRAMES[(ex >> 3) & 3],
            n_beams=n_beams,
            n_cells=n_cells,
            frequency_khz=FREQUENCIES_KHZ[config & 7],
            serial_number=serial,
            heading_deg=0.0 if heading == 36000 else heading / 100.0,
            pitch_deg=pitch / 100.0,
            roll_deg=roll / 100.0,
            temperature_c=temp / 100.0,
            salinity_ppt=float(sal),
            sound_speed_mps=float(c),
            depth_m=depth_dm / 10.0,
            bt_velocity_mms=bt_v,
            bt_range_cm=bt_r,
            data_types=tuple(ids),
        )

    def speed_records(self, record: Pd0Record) -> tuple[SpeedRecord, ...]:
        """Bottom track → vessel speed over ground in the ship frame (role ``bottom``,
        source ``PD0:BT``), with the ensemble's heading taken as true."""
        if record.bt_velocity_mms is None:
            return ()
        v1, v2 = record.bt_velocity_mms[0], record.bt_velocity_mms[1]
        # vessel motion: the opposite of the bottom's
        vessel = (None if v1 is None else -v1, None if v2 is None else -v2)
        return (
            rdi.bottom_track(
                self.port,
                record.coord_frame,
                record.bottom_lock,
                vessel,
                record.heading_deg,
                "PD0:BT",
            ),
        )


# ------------------------------------------------------------------ encoder


def encode_pd0(
    *,
    ensemble_number: int,
    timestamp: datetime,
    heading_deg: float,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    bottom_ship_mps: tuple[float, float] | None = None,
    range_m: float | None = None,
    coord_frame: rdi.CoordFrame = "ship",
    temperature_c: float = 15.0,
    salinity_ppt: int = 35,
    sound_speed_mps: int = 1500,
    serial_number: int = 1,
) -> bytes:
    """A minimal valid PD0 ensemble: fixed leader, variable leader, bottom track.

    Args:
        bottom_ship_mps: the **vessel's** motion (forward, starboard) in m/s, or None
            for no bottom lock (−32768 and range 0). It is negated into PD0's
            bottom-relative sign, and rotated into East/North for ``coord_frame="earth"``.
        range_m: range to bottom, m (all four beams).

    Raises:
        ValueError: non-finite values.
    """
    if bottom_ship_mps is None:
        v = (rdi.INVALID, rdi.INVALID, rdi.INVALID, rdi.INVALID)
        rng = 0
    else:
        a, b = rdi.vessel_mms(bottom_ship_mps, coord_frame, heading_deg)
        v = (-a, -b, 0, 0)  # the bottom's motion: the opposite of the vessel's
        rng = max(round((range_m or 0.0) * 100.0), 1)
    ex = rdi.COORD_FRAMES.index(coord_frame) << 3
    fixed = bytearray(59)
    struct.pack_into("<HBBH", fixed, 0, FIXED_LEADER, 51, 1, 0b0100_1011)  # 600 kHz
    fixed[8], fixed[9] = 4, 1
    fixed[25] = ex
    struct.pack_into("<I", fixed, 54, serial_number)
    fixed[58] = 30
    var = bytearray(65)
    struct.pack_into(
        "<HH7BB",
        var,
        0,
        VARIABLE_LEADER,
        ensemble_number & 0xFFFF,
        timestamp.year % 100,
        timestamp.month,
        timestamp.day,
        timestamp.hour,
        timestamp.minute,
        timestamp.second,
        timestamp.microsecond // 10000,
        (ensemble_number >> 16) & 0xFF,
    )
    struct.pack_into(
        "<HHHhhHh",
        var,
        14,
        sound_speed_mps,
        0,
        round((heading_deg % 360.0) * 100.0) % 36000,
        round(pitch_deg * 100.0),
        round(roll_deg * 100.0),
        salinity_ppt,
        round(temperature_c * 100.0),
    )
    bt = bytearray(85)
    struct.pack_into("<H", bt, 0, BOTTOM_TRACK)
    struct.pack_into("<4H", bt, 16, *([rng & 0xFFFF] * 4))
    struct.pack_into("<4h", bt, 24, *v)
    bt[77:81] = bytes([(rng >> 16) & 0xFF] * 4)
    header_len = 6 + 2 * 3
    offs = (header_len, header_len + len(fixed), header_len + len(fixed) + len(var))
    body = bytearray(HEADER)
    body += struct.pack("<HBB3H", 0, 0, 3, *offs)
    body += fixed + var + bt
    struct.pack_into("<H", body, 2, len(body))
    return bytes(body) + struct.pack("<H", sum16(body))
