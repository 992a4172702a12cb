"""The NMEA 0183 decoder: a sentence's address to its parser, records to speed records.

Must not import: serial, os, time, threading (pure module).
"""

from __future__ import annotations

from typing import ClassVar

from drivers.base import FramedDecoder, Framer, Use
from drivers.errors import FieldError, UnknownSentenceError
from drivers.framing import LineFramer, split_nmea
from drivers.nmea0183.parsing import (
    GNSS_PARSERS,
    HEADING_FIELDS,
    parse_heading,
    parse_mtw,
    parse_pashr,
    parse_prti,
    parse_vbw,
    parse_vhw,
    parse_vlw,
)
from drivers.nmea0183.records import NmeaRecord, Prti, Vbw, Vhw
from drivers.records import SpeedRecord


class NmeaDecoder(FramedDecoder[NmeaRecord]):
    """NMEA 0183 decoder (see the docstring of :mod:`drivers.nmea0183`)."""

    protocol: ClassVar[str] = "nmea0183"
    binary: ClassVar[bool] = False
    uses: ClassVar[frozenset[Use]] = frozenset({"uut", "speed", "gnss", "bottom"})
    """VHW/VBW: a UUT or an EMlog reference; RMC/VTG: GNSS; Rowe $PRTI01: bottom track."""
    heading: ClassVar[bool] = False

    def _make_framer(self) -> Framer:
        return LineFramer(b"$!", self.options.max_length)

    def parse_frame(self, frame: bytes) -> NmeaRecord:
        """Decode one sentence (without CR LF) into a record.

        Raises:
            FrameError: a subclass naming the reject reason.
        """
        body = split_nmea(frame, required=self.options.checksum == "required")
        if frame[:1] != b"$":
            raise UnknownSentenceError("encapsulated (!) sentences are not decoded", frame)
        try:
            text = body.decode("ascii")
        except UnicodeDecodeError:
            raise FieldError("non-ASCII bytes in the sentence", frame) from None
        if not text.isprintable():
            raise FieldError("control characters in the sentence", frame)
        address, sep, rest = text.partition(",")
        if not sep:
            raise FieldError(f"no field after the address {address[:16]!r}", frame)
        fields = rest.split(",")
        if address.startswith("P"):
            if address in ("PRTI01", "PRTI02"):
                return parse_prti(address, fields, frame)
            if address == "PASHR":
                return parse_pashr(fields, frame)
            raise UnknownSentenceError(f"proprietary sentence {address} not decoded", frame)
        if len(address) != 5 or not address.isalnum():
            raise FieldError(f"bad address field {address[:16]!r}", frame)
        return _parse_kind(address[:2], address[2:], fields, frame)

    def speed_records(self, record: NmeaRecord) -> tuple[SpeedRecord, ...]:
        """VHW → stw (both headings); VBW → stw (water pair) and sog (ground pair, if
        sent); PRTI01 → sog (bottom track)."""
        port = self.port
        if isinstance(record, Vhw):
            return (
                SpeedRecord(
                    port=port,
                    kind="stw",
                    role="speed",
                    longitudinal_mps=record.stw_mps,
                    valid=record.stw_mps is not None,
                    heading_true_deg=record.heading_true_deg,
                    heading_mag_deg=record.heading_mag_deg,
                    source="VHW",
                ),
            )
        if isinstance(record, Vbw):
            water = SpeedRecord(
                port=port,
                kind="stw",
                role="speed",
                longitudinal_mps=record.water_long_mps,
                transverse_mps=record.water_trans_mps,
                valid=record.water_valid,
                source="VBW",
            )
            if record.ground_long_mps is None and not record.ground_valid:
                return (water,)
            ground = SpeedRecord(
                port=port,
                kind="sog",
                role="ground",
                longitudinal_mps=record.ground_long_mps,
                transverse_mps=record.ground_trans_mps,
                valid=record.ground_valid,
                source="VBW:G",
            )
            return (water, ground)
        if isinstance(record, Prti) and record.sentence == "PRTI01":
            bt = record.bottom_mps
            return (
                SpeedRecord(
                    port=port,
                    kind="sog",
                    role="bottom",
                    longitudinal_mps=None if bt is None else bt[1],
                    transverse_mps=None if bt is None else bt[0],
                    valid=record.bottom_valid,
                    source="PRTI01",
                ),
            )
        return ()


def _parse_kind(talker: str, kind: str, fields: list[str], frame: bytes) -> NmeaRecord:
    """A standard sentence's fields by its type (the speeds' first, the common case).

    Raises:
        FrameError: a subclass naming the reject reason (a type not decoded too).
    """
    if kind == "VHW":
        return parse_vhw(talker, fields, frame)
    if kind == "VBW":
        return parse_vbw(talker, fields, frame)
    gnss = GNSS_PARSERS.get(kind)
    if gnss is not None:
        return gnss(talker, fields, frame)
    if kind == "VLW":
        return parse_vlw(talker, fields, frame)
    if kind == "MTW":
        return parse_mtw(talker, fields, frame)
    if kind in HEADING_FIELDS:
        return parse_heading(kind, talker, fields, frame)
    raise UnknownSentenceError(f"sentence {kind} not decoded", frame)
