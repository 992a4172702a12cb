"""NMEA 0183 speed-log sentences: framing, checksum, typed records, encoders.

Framing is ours (:class:`~drivers.framing.LineFramer`: ``$``/``!`` start, any mix of
CR/LF, the 82-character limit with a per-port leniency) and so is the checksum
check (:func:`~drivers.framing.split_nmea`: a wrong checksum is always rejected, a
missing one unless the port is configured ``checksum: optional``). Then:

every sentence (VHW, VBW, VLW, MTW, HDT, HDG, HDM, THS, RMC, VTG, GGA, ZDA, VDR, Rowe
``$PRTI01``/``$PRTI02`` in their 12- and 14-field forms, and ``$PASHR``'s true heading
in its attitude and Ashtech ``ATT`` forms) is split and converted by
:mod:`drivers.nmea0183.parsing` under one set of field rules: a number has ``float``
syntax with no blank or underscore and is finite, an integer is digits, a flag field
holds its letter or is empty. The tests check the decoded fields against pynmea2's
field mapping on every VHW, VLW, MTW, HDT, HDM and HDG of the real captures.

Units out: m/s, degrees, nautical miles, °C. Every field is range-checked before it
goes into a record (docs/PROTOCOLS.md lists each range): a value outside is an
``out_of_range`` reject, never a record. Directions come out in [0, 360) (a sent 360
reads as 0), deviations and variations within ±180°. VHW speed is taken from knots,
else from km/h; a knots/km/h pair that differs by more than the fields' rounding
allows is refused (``out_of_range``: the sender contradicts itself). VBW: the water pair is valid when *its own* status is
``A`` whatever the ground pair says (pynmea2's ``VBW.is_valid`` wants both).

PRTI velocities are taken as the vessel's motion (Rowe's native sign, see
docs/PROTOCOLS.md §4; not verified for PRTI against GPS). PRTI01 is the instrument frame:
X is mapped to starboard and Y to forward, assuming the DVL is mounted with beam 3
forward (Rowe's default); PRTI02 is the earth frame (East, North) and gives no
ship-frame speed record.

GLL (position and time of day) is parsed (:func:`parse_gll`) for the import's timing
of a log whose GNSS sends nothing else with a time; the decoder does not yield it.

Must not import: serial, os, time, threading (pure module).
"""

from drivers.nmea0183.decoder import NmeaDecoder
from drivers.nmea0183.encoders import (
    encode_rmc,
    encode_vbw,
    encode_vhw,
)
from drivers.nmea0183.parsing import (
    MAX_FIX_QUALITY,
    MAX_HDOP,
    MAX_OFFSET_DEG,
    MAX_SATELLITES,
    MAX_SPEED_MPS,
    PRTI_INVALID,
    UNITS_RELATIVE,
    UNITS_ROUNDING,
    ZDA_YEARS,
    parse_gga,
    parse_gll,
    parse_heading,
    parse_mtw,
    parse_pashr,
    parse_prti,
    parse_rmc,
    parse_vbw,
    parse_vdr,
    parse_vhw,
    parse_vlw,
    parse_vtg,
    parse_zda,
)
from drivers.nmea0183.records import (
    GNSS_INVALID_MODES,
    RECORDS,
    Gga,
    Gll,
    Heading,
    Mtw,
    NmeaRecord,
    Prti,
    Rmc,
    Vbw,
    Vdr,
    Vhw,
    Vlw,
    Vtg,
    Zda,
)

__all__ = [
    "GNSS_INVALID_MODES",
    "MAX_FIX_QUALITY",
    "MAX_HDOP",
    "MAX_OFFSET_DEG",
    "MAX_SATELLITES",
    "MAX_SPEED_MPS",
    "PRTI_INVALID",
    "RECORDS",
    "UNITS_RELATIVE",
    "UNITS_ROUNDING",
    "ZDA_YEARS",
    "Gga",
    "Gll",
    "Heading",
    "Mtw",
    "NmeaDecoder",
    "NmeaRecord",
    "Prti",
    "Rmc",
    "Vbw",
    "Vdr",
    "Vhw",
    "Vlw",
    "Vtg",
    "Zda",
    "encode_rmc",
    "encode_vbw",
    "encode_vhw",
    "parse_gga",
    "parse_gll",
    "parse_heading",
    "parse_mtw",
    "parse_pashr",
    "parse_prti",
    "parse_rmc",
    "parse_vbw",
    "parse_vdr",
    "parse_vhw",
    "parse_vlw",
    "parse_vtg",
    "parse_zda",
]
