"""Teledyne-RDI PD4 and PD5 binary output (docs/PROTOCOLS.md §5.4).

Layout (little-endian, 1-based TRDI byte numbers): ``0x7D``; structure ID (0 = PD4,
1 = PD5); byte count without the checksum (45 for PD4, 86 for PD5); the system
configuration (bits 7–6 coordinate frame: 00 beam, 01 instrument, 10 ship, 11
earth); bottom velocity X/Y/Z/E in mm/s (−32768 = bad); bottom range per beam in
cm; bottom status; reference-layer (water-mass) velocity X/Y/Z/E, its start and
end (dm) and status; time of first ping; BIT; speed of sound; temperature (0.01
°C). PD5 adds salinity, depth (dm), pitch/roll/heading (0.01°) and the bottom and
reference-layer distances made good (int32). The 16-bit sum of every preceding
byte follows. No real PD4/PD5 capture exists in the public corpus
(conformance/SOURCES.md): these decoders are tested against the layout and the
encoders here.

**Sign convention.** Unlike PD0, PD4/PD5 give the **vessel's** motion relative to
the bottom. In ship coordinates X is transverse (+ starboard) and Y longitudinal
(+ forward), so the speed record is ``longitudinal = Y``, ``transverse = X``;
earth coordinates need a heading (PD5 only) and are rotated into the ship frame.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar, TypeAlias

from drivers import rdi
from drivers.base import FramedDecoder, Framer, Use
from drivers.binframe import BinaryFramer, sum16
from drivers.errors import FieldError, OutOfRangeError
from drivers.records import SpeedRecord, check_ranges

HEADER = b"\x7d"
LENGTHS = {0: 45, 1: 86}
"""Structure ID -> byte count without the checksum."""

_PD4 = struct.Struct("<BBHB4h4HB4hHHB4BHHh")
_PD5_EXTRA = struct.Struct("<BHhhH4i4i")


@dataclass(frozen=True, slots=True)
class Pd45Ensemble:
    """One PD4 or PD5 ensemble (velocities None when −32768).

    Attributes:
        format: ``"PD4"`` or ``"PD5"``.
        coord_frame: coordinate frame of the velocities.
        bottom_mms: bottom velocity X/Y/Z/error, mm/s (vessel-motion sign).
        bottom_range_cm: range to bottom per beam, cm (0 = no bottom).
        bottom_status: per-beam status flags (0 = good).
        water_mms: reference-layer velocity X/Y/Z/error, mm/s.
        water_layer_dm: reference layer (start, end), dm.
        water_status: reference-layer status flags.
        first_ping: time of first ping (h, m, s, hundredths).
        bit: built-in-test result.
        sound_speed_mps: speed of sound.
        temperature_c: temperature, °C.
        salinity_ppt, depth_m, pitch_deg, roll_deg, heading_deg: PD5 only, else None.
        bottom_dmg_dm, water_dmg_dm: PD5 distances made good E/N/U/error, else None.
    """

    format: str
    coord_frame: rdi.CoordFrame
    bottom_mms: tuple[int | None, int | None, int | None, int | None]
    bottom_range_cm: tuple[int, int, int, int]
    bottom_status: int
    water_mms: tuple[int | None, int | None, int | None, int | None]
    water_layer_dm: tuple[int, int]
    water_status: int
    first_ping: tuple[int, int, int, int]
    bit: int
    sound_speed_mps: float
    temperature_c: float
    salinity_ppt: float | None = None
    depth_m: float | None = None
    pitch_deg: float | None = None
    roll_deg: float | None = None
    heading_deg: float | None = None
    bottom_dmg_dm: tuple[int, int, int, int] | None = None
    water_dmg_dm: tuple[int, int, int, int] | None = None

    @property
    def bottom_lock(self) -> bool:
        """Velocities X and Y valid and some bottom range."""
        v = self.bottom_mms
        return v[0] is not None and v[1] is not None and any(r > 0 for r in self.bottom_range_cm)


Pd45Record: TypeAlias = Pd45Ensemble
"""Every record :class:`Pd45Decoder` yields (besides :class:`~drivers.records.Rejected`):
one type, named like the other protocols' unions."""

RECORDS: tuple[type[Pd45Record], ...] = (Pd45Ensemble,)
"""The members of :data:`Pd45Record`."""


def _length_of(buf: bytearray) -> int | None:
    n = LENGTHS.get(buf[1])
    if n is None or (buf[2] | buf[3] << 8) != n:
        return None
    return n


class Pd45Decoder(FramedDecoder[Pd45Record]):
    """PD4/PD5 decoder (registry name ``pd4``; both formats are accepted). PD4 carries no
    heading: :class:`Pd5Decoder` is the port configured ``pd5``."""

    protocol: ClassVar[str] = "pd4"
    binary: ClassVar[bool] = True
    uses: ClassVar[frozenset[Use]] = frozenset({"bottom"})
    heading: ClassVar[bool] = False

    def _make_framer(self) -> Framer:
        return BinaryFramer(HEADER, _length_of, 4, "PD4/PD5")

    def parse_frame(self, frame: bytes) -> Pd45Record:
        """Decode one checksum-verified PD4/PD5 frame (without the checksum).

        Raises:
            FieldError: a length that does not match the structure ID.
        """
        sid = frame[1]
        if LENGTHS.get(sid) != len(frame):
            raise FieldError(f"structure {sid} with {len(frame)} bytes", frame)
        f = _PD4.unpack_from(frame, 0)
        config = f[3]
        h, m, sec, hundredths = f[20:24]
        c, temp = float(f[25]), f[26] / 100.0
        if not (h < 24 and m < 60 and sec < 60 and hundredths < 100):
            raise OutOfRangeError(f"first ping {h}:{m}:{sec}.{hundredths} out of range", frame)
        check_ranges("PD4", frame, sound_speed=c, temperature=temp)
        common = {
            "format": "PD5" if sid == 1 else "PD4",
            "coord_frame": rdi.COORD_FRAMES[(config >> 6) & 3],
            "bottom_mms": rdi.velocities(f[4:8]),
            "bottom_range_cm": (f[8], f[9], f[10], f[11]),
            "bottom_status": f[12],
            "water_mms": rdi.velocities(f[13:17]),
            "water_layer_dm": (f[17], f[18]),
            "water_status": f[19],
            "first_ping": (f[20], f[21], f[22], f[23]),
            "bit": f[24],
            "sound_speed_mps": c,
            "temperature_c": temp,
        }
        if sid == 0:
            return Pd45Ensemble(**common)
        g = _PD5_EXTRA.unpack_from(frame, _PD4.size)
        sal, depth, pitch, roll, hdg = float(g[0]), g[1] / 10.0, g[2] / 100.0, g[3] / 100.0, g[4]
        check_ranges(
            "PD5", frame, salinity=sal, depth=depth, pitch=pitch, roll=roll, heading=hdg / 100
        )
        return Pd45Ensemble(
            **common,
            salinity_ppt=sal,
            depth_m=depth,
            pitch_deg=pitch,
            roll_deg=roll,
            heading_deg=0.0 if hdg == 36000 else hdg / 100.0,
            bottom_dmg_dm=(g[5], g[6], g[7], g[8]),
            water_dmg_dm=(g[9], g[10], g[11], g[12]),
        )

    def speed_records(self, record: Pd45Record) -> tuple[SpeedRecord, ...]:
        """Bottom velocity → vessel speed over ground, ship frame (role ``bottom``, source
        ``PD4:BT``/``PD5:BT``), with the PD5 heading taken as true."""
        return (
            rdi.bottom_track(
                self.port,
                record.coord_frame,
                record.bottom_lock,
                (record.bottom_mms[0], record.bottom_mms[1]),
                record.heading_deg,
                f"{record.format}:BT",
            ),
        )


class Pd5Decoder(Pd45Decoder):
    """The decoder of a port configured ``pd5``: the same frames, with the heading."""

    protocol: ClassVar[str] = "pd5"
    heading: ClassVar[bool] = True


def encode_pd45(
    *,
    pd5: bool = False,
    bottom_ship_mps: tuple[float, float] | None = None,
    range_m: float | None = None,
    coord_frame: rdi.CoordFrame = "ship",
    heading_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    temperature_c: float = 15.0,
    sound_speed_mps: int = 1500,
    first_ping: tuple[int, int, int, int] = (0, 0, 0, 0),
) -> bytes:
    """One PD4 (or PD5) frame with checksum.

    Args:
        bottom_ship_mps: the vessel's (forward, starboard) motion, m/s, or None for no
            bottom lock. Rotated into East/North for ``coord_frame="earth"``.

    Raises:
        ValueError: non-finite values.
    """
    if bottom_ship_mps is None:
        vx = vy = rdi.INVALID
        rng = 0
    else:
        vx, vy = rdi.vessel_mms(bottom_ship_mps, coord_frame, heading_deg)
        rng = max(min(round((range_m or 0.0) * 100.0), 65535), 1)
    sid = 1 if pd5 else 0
    body = bytearray(
        _PD4.pack(
            0x7D,
            sid,
            LENGTHS[sid],
            rdi.COORD_FRAMES.index(coord_frame) << 6,
            vx,
            vy,
            0 if vx != rdi.INVALID else rdi.INVALID,
            0 if vx != rdi.INVALID else rdi.INVALID,
            rng,
            rng,
            rng,
            rng,
            0,
            rdi.INVALID,
            rdi.INVALID,
            rdi.INVALID,
            rdi.INVALID,
            0,
            0,
            0,
            *first_ping,
            0,
            sound_speed_mps,
            round(temperature_c * 100.0),
        )
    )
    if pd5:
        body += _PD5_EXTRA.pack(
            35,
            0,
            round(pitch_deg * 100.0),
            round(roll_deg * 100.0),
            round((heading_deg % 360.0) * 100.0) % 36000,
            *(0,) * 8,
        )
    return bytes(body) + struct.pack("<H", sum16(body))
