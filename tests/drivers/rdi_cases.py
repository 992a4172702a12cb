"""Test inputs the RDI PD0 and PD4/PD5 decoders' tests (and the daemon's) share."""

from __future__ import annotations

OUT_OF_RANGE_LEADER: tuple[dict[str, float], ...] = (
    {"pitch_deg": 95.0},
    {"roll_deg": -181.0},
    {"temperature_c": 80.0},
    {"sound_speed_mps": 1000},
)
"""Encoder keywords, each outside its physical range, that PD0 and PD5 both carry."""

HOSTILE_HEADER = bytes([0x7F, 0x7F, 0x80, 0x3E, 0x00, 0x01])
"""A PD0 header claiming a 16 000-byte ensemble of one data type: plausible to the
framer, which checks the checksum once 16 000 bytes follow it."""
