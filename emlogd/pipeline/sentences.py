"""The sentences the daemon emits: corrected VHW/VBW and the status sentence.

Corrected speeds are encoded by :mod:`drivers.nmea0183` (knots and km/h both
filled and consistent — ArduPilot reads km/h, Signal K reads knots). The status
sentence is proprietary (``$P`` + a three-letter maker code + ``S``)::

    $PEMLS,emlog1,L,EM3,,+0.1712,+0.120,,2.1e-03,3.4e-03,1.02,V*hh

fields: UUT port (at most 8 characters), state (``L`` learning, ``F`` frozen,
``U`` uncalibrated), model, the parameters a (s/m), m, b (m/s) of the good
calibration (empty when the model lacks one or there is none), their standard
deviations (a and m clamped to ±9.9999, b to ±9.999, σ to two-digit exponents), the running
NIS mean (empty before learning), and the reference state
(``V`` valid, ``L`` lost, ``S`` stale, ``W`` too slow, ``N`` none yet). Every
sentence is checksummed and at most 82 characters with CR LF.

The fused speed's status (``$P`` + maker + ``F``)::

    $PEMLF,4.21,0.04,1,emlog2,A,emlog1:break*hh

fields: the fused speed and its σ in knots (empty when invalid), the number of logs
used and their names (heaviest weight first), the status (``A`` valid, ``V`` invalid:
logs disagree and nothing tells which is right, or the one log left is still and
nothing vouches for it), and the logs left out with their
reasons (``name:reason`` joined by ``;``; see :mod:`emlogd.pipeline.fusion`). Names are
cut to fit 82 characters, the used ones first.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from drivers import nmea0183
from drivers.base import NMEA_MAX_LENGTH
from drivers.framing import with_checksum
from drivers.records import KNOT_MPS
from emlogd.pipeline.fusion import Fused

STATE_CODES = {"learning": "L", "frozen": "F", "uncalibrated": "U"}
REF_CODES = {"valid": "V", "lost": "L", "stale": "S", "slow": "W", "none": "N"}


@dataclass(frozen=True, slots=True)
class StatusFields:
    """The content of one status sentence."""

    port: str
    state: str
    model: str
    params: Mapping[str, float] = field(default_factory=dict)
    std: Mapping[str, float] = field(default_factory=dict)
    nis_mean: float | None = None
    ref_state: str = "none"
    maker: str = "EML"


def _clamp(x: float | None, limit: float) -> float | None:
    """A parameter clamped to ±limit, the widest its format holds without rounding up
    a digit (9.9999 for 4 decimals, 9.999 for 3; a calibration beyond is nonsense)."""
    return None if x is None else max(min(x, limit), -limit)


def _std(x: float | None) -> float | None:
    """σ clamped to a two-digit exponent (below 1e-9 is sent as 0)."""
    if x is None or not math.isfinite(x):
        return None
    return 0.0 if abs(x) < 1e-9 else min(abs(x), 9.9e9)


def _num(x: float | None, spec: str) -> str:
    if x is None or not math.isfinite(x):
        return ""
    return format(x, spec)


def _deg(x: float | None) -> str:
    """A direction in its 0–359.9° field with one decimal, empty for None or non-finite."""
    if x is None or not math.isfinite(x):
        return ""
    return f"{min(max(x % 360.0, 0.0), 359.9):.1f}"


def encode_status(f: StatusFields) -> str:
    """The status sentence (without CR LF).

    Raises:
        ValueError: a maker code that is not three uppercase letters.
    """
    if not (len(f.maker) == 3 and f.maker.isalpha() and f.maker.isupper()):
        raise ValueError(f"maker code must be three uppercase letters, not {f.maker!r}")
    nis = None if f.nis_mean is None else min(f.nis_mean, 999.99)
    fields = [
        f"P{f.maker}S",
        "".join(c for c in f.port if c.isascii() and (c.isalnum() or c in "_-"))[:8],
        STATE_CODES.get(f.state, "U"),
        f.model,
        _num(_clamp(f.params.get("a"), 9.9999), "+.4f"),
        _num(_clamp(f.params.get("m"), 9.9999), "+.4f"),
        _num(_clamp(f.params.get("b"), 9.999), "+.3f"),
        _num(_std(f.std.get("a")), ".1e"),
        _num(_std(f.std.get("m")), ".1e"),
        _num(_std(f.std.get("b")), ".1e"),
        _num(nis, ".2f"),
        REF_CODES.get(f.ref_state, "N"),
    ]
    sentence = with_checksum(",".join(fields))
    if len(sentence) + 2 > NMEA_MAX_LENGTH:  # cannot happen with the widths above
        raise ValueError(f"status sentence too long: {sentence}")
    return sentence


def encode_fused_status(fused: Fused, maker: str) -> str:
    """The fused speed's status sentence (without CR LF).

    Raises:
        ValueError: a maker code that is not three uppercase letters.
    """
    if not (len(maker) == 3 and maker.isalpha() and maker.isupper()):
        raise ValueError(f"maker code must be three uppercase letters, not {maker!r}")
    kn = KNOT_MPS
    head = [
        f"P{maker}F",
        _num(min(fused.speed_mps / kn, 999.99), ".2f"),
        _num(min(fused.std_mps / kn, 99.99), ".2f"),
        str(len(fused.sources)),
    ]
    status = "A" if fused.valid else "V"

    def fits(names: str, excluded: str) -> bool:
        return len(with_checksum(",".join([*head, names, status, excluded]))) + 2 <= NMEA_MAX_LENGTH

    names = ""
    for name in fused.sources:
        trial = f"{names};{_clean(name)}" if names else _clean(name)
        if not fits(trial, ""):
            break
        names = trial
    excluded = ""
    for name, why in fused.excluded:
        item = f"{_clean(name)}:{_clean(why)}"
        trial = f"{excluded};{item}" if excluded else item
        if not fits(names, trial):
            break
        excluded = trial
    return with_checksum(",".join([*head, names, status, excluded]))


def _clean(name: str) -> str:
    return "".join(c for c in name if c.isascii() and (c.isalnum() or c in "_-"))


def encode_vhw_void(
    heading_true_deg: float | None = None,
    heading_mag_deg: float | None = None,
    talker: str = "II",
) -> str:
    """A VHW without a speed (VHW has no status field: an empty speed is invalid),
    headings passed through."""
    return with_checksum(f"{talker}VHW,{_deg(heading_true_deg)},T,{_deg(heading_mag_deg)},M,,N,,K")


def encode_vhw(
    stw_mps: float,
    heading_true_deg: float | None = None,
    heading_mag_deg: float | None = None,
    talker: str = "VW",
) -> str:
    """A corrected VHW: STW in knots and km/h, headings passed through."""
    return nmea0183.encode_vhw(
        stw_mps, heading_true_deg=heading_true_deg, heading_mag_deg=heading_mag_deg, talker=talker
    )


def encode_vdr(
    set_true_deg: float, set_mag_deg: float | None, drift_kn: float, talker: str = "VW"
) -> str:
    """The current as ``$--VDR,<set true>,T,<set magnetic>,M,<drift kn>,N``.

    The set is the direction the current flows towards. Fields are clamped to their
    widths (set 0–359.9°, drift 0–99.99 kn); a missing magnetic set is left empty.
    """
    drift = f"{min(max(drift_kn, 0.0), 99.99):.2f}" if math.isfinite(drift_kn) else ""
    body = f"{talker}VDR,{_deg(set_true_deg)},T,{_deg(set_mag_deg)},M,{drift},N"
    return with_checksum(body)


def encode_vbw(
    long_mps: float,
    trans_mps: float | None,
    talker: str = "VW",
    ground: tuple[float, float] | None = None,
) -> str:
    """A corrected VBW: the water pair with status A (a missing transverse speed is sent
    as 0), the ground pair (along, across the hull, m/s) with status A when known
    (:mod:`emlogd.pipeline.groundpair`), else empty with V; no stern fields."""
    gl, gt = (None, None) if ground is None else ground
    return nmea0183.encode_vbw(
        long_mps,
        0.0 if trans_mps is None else trans_mps,
        ground_long_mps=gl,
        ground_trans_mps=gt,
        ground_valid=ground is not None,
        talker=talker,
    )
