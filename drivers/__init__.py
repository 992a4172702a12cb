"""Sensor protocols and I/O for emlogd.

Protocol modules (pure: bytes in, frozen records out; no serial/os/time/threading):
``nmea0183`` (VHW, VBW, VLW, MTW, HDT/HDG/HDM, Rowe $PRTI01/02), ``rdi_ascii``
(PD6/PD13), ``rdi_pd0`` (PD0 binary), ``rdi_pd45`` (PD4/PD5 binary).
I/O modules: ``capture`` (capture v1 files), ``port`` (serial source through
``serial.serial_for_url``), ``vpty`` (virtual serial port), ``fake`` (fake device).

The registry is explicit and lazy: :data:`PROTOCOLS` maps a
fixed name to ``(module, class)``; :func:`get_decoder` imports on demand.
Third-party decoders may be added through the ``emlogd.drivers`` entry-point group.
A built-in name given as a literal types the decoder precisely (``make_decoder("pd0")``
is a :class:`~drivers.rdi_pd0.Pd0Decoder`, a ``Decoder[Pd0Record]``); any other name
gives a ``Decoder[Any]``, whose records a consumer narrows with ``isinstance``.

Must not import: calib, emlogd.
"""

from __future__ import annotations

import importlib
from functools import cache
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, Literal, overload

from drivers.base import Decoder, DecoderOptions, ErrorPolicy, Use
from drivers.errors import (
    CaptureFormatError,
    ChecksumError,
    ConfigError,
    DeviceError,
    EmlogdError,
    FieldError,
    FrameError,
    MissingChecksumError,
    OutOfRangeError,
    TooLongError,
    UnknownProtocolError,
    UnknownSentenceError,
)
from drivers.records import Rejected, SpeedRecord, SpeedRole

if TYPE_CHECKING:
    from drivers.nmea0183 import NmeaDecoder
    from drivers.rdi_ascii import PdAsciiDecoder
    from drivers.rdi_pd0 import Pd0Decoder
    from drivers.rdi_pd45 import Pd5Decoder, Pd45Decoder

PROTOCOLS: dict[str, tuple[str, str]] = {
    "nmea0183": ("drivers.nmea0183", "NmeaDecoder"),
    "pd6": ("drivers.rdi_ascii", "PdAsciiDecoder"),
    "pd13": ("drivers.rdi_ascii", "PdAsciiDecoder"),
    "pd0": ("drivers.rdi_pd0", "Pd0Decoder"),
    "pd4": ("drivers.rdi_pd45", "Pd45Decoder"),
    "pd5": ("drivers.rdi_pd45", "Pd5Decoder"),
}
"""Protocol name -> (module, class). Names are fixed strings, never class names."""

ENTRY_POINT_GROUP = "emlogd.drivers"


@cache
def _entry_point_protocols() -> tuple[tuple[str, str, str], ...]:
    """The ``(name, module, class)`` of every entry point in :data:`ENTRY_POINT_GROUP`.

    Read once per process: scanning the installed distributions' metadata costs
    milliseconds, and a config load asks for the protocols dozens of times (a package
    installed while the process runs is seen by the next process).
    """
    found = []
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        module, _, cls = ep.value.partition(":")
        found.append((ep.name, module, cls))
    return tuple(found)


def _all_protocols() -> dict[str, tuple[str, str]]:
    found = dict(PROTOCOLS)
    for name, module, cls in _entry_point_protocols():
        found.setdefault(name, (module, cls))
    return found


def protocol_names() -> list[str]:
    """Sorted names of every known protocol (built-in and entry points)."""
    return sorted(_all_protocols())


def protocols_for(use: Use) -> list[str]:
    """Names of the protocols whose decoder can serve ``use`` (:attr:`Decoder.uses`), the
    built-in ones first in :data:`PROTOCOLS`' order."""
    return [name for name in _all_protocols() if use in get_decoder(name).uses]


@overload
def get_decoder(name: Literal["nmea0183"]) -> type[NmeaDecoder]: ...
@overload
def get_decoder(name: Literal["pd6", "pd13"]) -> type[PdAsciiDecoder]: ...
@overload
def get_decoder(name: Literal["pd0"]) -> type[Pd0Decoder]: ...
@overload
def get_decoder(name: Literal["pd4"]) -> type[Pd45Decoder]: ...
@overload
def get_decoder(name: Literal["pd5"]) -> type[Pd5Decoder]: ...
@overload
def get_decoder(name: str) -> type[Decoder[Any]]: ...


def get_decoder(name: str) -> type[Decoder[Any]]:
    """Return the decoder class registered under ``name``.

    Raises:
        UnknownProtocolError: ``name`` is not registered; the message lists the valid names.
    """
    table = _all_protocols()
    try:
        module_name, class_name = table[name]
    except KeyError:
        raise UnknownProtocolError(
            f"unknown protocol {name!r}; valid: {', '.join(sorted(table))}"
        ) from None
    cls = getattr(importlib.import_module(module_name), class_name)
    if not (isinstance(cls, type) and issubclass(cls, Decoder)):
        raise UnknownProtocolError(f"{module_name}.{class_name} is not a drivers.base.Decoder")
    return cls


@overload
def make_decoder(
    name: Literal["nmea0183"],
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> NmeaDecoder: ...
@overload
def make_decoder(
    name: Literal["pd6", "pd13"],
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> PdAsciiDecoder: ...
@overload
def make_decoder(
    name: Literal["pd0"],
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> Pd0Decoder: ...
@overload
def make_decoder(
    name: Literal["pd4"],
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> Pd45Decoder: ...
@overload
def make_decoder(
    name: Literal["pd5"],
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> Pd5Decoder: ...
@overload
def make_decoder(
    name: str,
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> Decoder[Any]: ...


def make_decoder(
    name: str,
    port: str = "",
    *,
    errors: ErrorPolicy = "raise",
    options: DecoderOptions | None = None,
) -> Decoder[Any]:
    """Instantiate the decoder for protocol ``name`` (see :class:`Decoder`)."""
    return get_decoder(name)(port, errors=errors, options=options)


def is_binary(name: str) -> bool:
    """True if protocol ``name`` is binary (stored as ``hex:`` chunks in a capture)."""
    return get_decoder(name).binary


def record_types() -> tuple[type, ...]:
    """Every record dataclass: the common ones plus each protocol module's ``RECORDS``
    (the members of its record union) and ``RECORD_PARTS`` (dataclasses nested in them)."""
    types: list[type] = [SpeedRecord, Rejected]
    seen: set[str] = set()
    for module_name, _ in PROTOCOLS.values():
        if module_name in seen:
            continue
        seen.add(module_name)
        module = importlib.import_module(module_name)
        types.extend(getattr(module, "RECORDS", ()))
        types.extend(getattr(module, "RECORD_PARTS", ()))
    return tuple(types)


__all__ = [
    "PROTOCOLS",
    "CaptureFormatError",
    "ChecksumError",
    "ConfigError",
    "Decoder",
    "DecoderOptions",
    "DeviceError",
    "EmlogdError",
    "ErrorPolicy",
    "FieldError",
    "FrameError",
    "MissingChecksumError",
    "OutOfRangeError",
    "Rejected",
    "SpeedRecord",
    "SpeedRole",
    "TooLongError",
    "UnknownProtocolError",
    "UnknownSentenceError",
    "Use",
    "get_decoder",
    "is_binary",
    "make_decoder",
    "protocol_names",
    "protocols_for",
    "record_types",
]
