"""The corrected VBW's ground pair: the reference's speed over ground on the hull, read by
pynmea2 — sent with A while the reference's latest one is valid and fresh, else empty
with V."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pynmea2
import pytest

from drivers.nmea0183 import encode_rmc
from drivers.nmea0183 import encode_vbw as raw_vbw
from drivers.rdi_ascii import encode_pd6
from drivers.rdi_pd0 import encode_pd0
from drivers.records import KNOT_MPS
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from tests.nmea_encoders import encode_hdt

T0 = 1_750_000_000.0
STAMP = datetime(2025, 6, 15, 12, 0, tzinfo=UTC)
LOG = PortSettings("log", "nmea0183")


def _pipeline(ref: PortSettings, **kw: object) -> Pipeline:
    """A log sending VBW against ``ref``, its first VBW sent (the ground pair is kept from
    then on)."""
    s = UutSettings(port="log", reference_port=ref.name, uut_source="VBW", **kw)  # type: ignore[arg-type]
    p = Pipeline([LOG, ref], [s])
    assert _empty(_vbw(p, T0 - 10.0))
    return p


def _pd6(ship: tuple[float, float] | None, heading: float = 30.0) -> bytes:
    """One PD6 ensemble; ``ship`` the vessel's bottom track (forward, starboard) m/s, None
    without a bottom lock."""
    bs = None if ship is None else (ship[1], ship[0], 0.0)
    lines = encode_pd6(timestamp=STAMP, heading_deg=heading, bottom_ship_mps=bs, range_m=20.0)
    return ("\r\n".join(lines) + "\r\n").encode()


def _vbw(p: Pipeline, t: float) -> pynmea2.NMEASentence:
    """The corrected VBW the pipeline emits for a raw VBW at ``t``, parsed by pynmea2."""
    out = p.feed(t, "log", (raw_vbw(2.4, 0.1, talker="VM") + "\r\n").encode())
    (line,) = [e.sentence for e in out.emits if "VBW" in e.sentence]
    msg = pynmea2.parse(line, check=True)
    assert msg.sentence_type == "VBW" and msg.data_validity_water_spd == "A"
    return msg


def _ground(msg: pynmea2.NMEASentence) -> tuple[float, float]:
    assert msg.data_validity_grnd_spd == "A"
    return float(msg.lon_grnd_spd) * KNOT_MPS, float(msg.trans_grnd_spd) * KNOT_MPS


def _empty(msg: pynmea2.NMEASentence) -> bool:
    """The ground pair empty (pynmea2 reads an empty field as None) and flagged V."""
    return (
        msg.lon_grnd_spd is None
        and msg.trans_grnd_spd is None
        and msg.data_validity_grnd_spd == "V"
    )


@pytest.mark.parametrize("field", ["bottom", "water"])
def test_dvl_bottom_track_is_the_ground_pair(field: str) -> None:
    """A PD6 ``:BS`` bottom track (2.5 m/s ahead, 0.2 to starboard) goes out as the
    corrected VBW's ground pair with A, whichever DVL field the UUT calibrates against."""
    p = _pipeline(PortSettings("dvl", "pd6"), reference_field=field)
    p.feed(T0, "dvl", _pd6((2.5, 0.2)))
    assert _ground(_vbw(p, T0 + 0.5)) == pytest.approx((2.5, 0.2), abs=0.006)


def test_pd0_earth_frame_bottom_track_is_turned_onto_the_hull() -> None:
    """A PD0 bottom track in earth coordinates is sent along and across the hull."""
    p = _pipeline(PortSettings("dvl", "pd0"))
    ens = encode_pd0(
        ensemble_number=1,
        timestamp=STAMP,
        heading_deg=120.0,
        bottom_ship_mps=(3.0, -0.4),
        range_m=30.0,
        coord_frame="earth",
    )
    p.feed(T0, "dvl", ens)
    assert _ground(_vbw(p, T0 + 0.2)) == pytest.approx((3.0, -0.4), abs=0.006)


def test_lost_bottom_lock_withdraws_the_ground_pair() -> None:
    """After a valid bottom track, an ensemble without bottom lock leaves the ground pair
    empty with V at once; a valid one brings it back."""
    p = _pipeline(PortSettings("dvl", "pd6"))
    p.feed(T0, "dvl", _pd6((2.5, 0.2)))
    assert _ground(_vbw(p, T0 + 0.5)) == pytest.approx((2.5, 0.2), abs=0.006)
    p.feed(T0 + 1.0, "dvl", _pd6(None))
    assert _empty(_vbw(p, T0 + 1.5))
    p.feed(T0 + 2.0, "dvl", _pd6((2.6, 0.1)))
    assert _ground(_vbw(p, T0 + 2.5)) == pytest.approx((2.6, 0.1), abs=0.006)


def test_bottom_track_glitch_is_not_sent() -> None:
    """A bottom track jumping 4 m/s athwart in 0.1 s (a glitch no hull makes) is not sent:
    the ground pair is empty with V until the next plausible one."""
    p = _pipeline(PortSettings("dvl", "pd6"))
    p.feed(T0, "dvl", _pd6((2.5, 0.2)))
    p.feed(T0 + 0.1, "dvl", _pd6((2.5, 4.2)))
    assert _empty(_vbw(p, T0 + 0.15))
    p.feed(T0 + 0.2, "dvl", _pd6((2.5, 0.25)))
    assert _ground(_vbw(p, T0 + 0.25)) == pytest.approx((2.5, 0.25), abs=0.006)


def test_stale_reference_gives_no_ground_pair() -> None:
    """A bottom track older than the reference's staleness bound (``ref_stale_s``) is not
    sent; within it, it is."""
    p = _pipeline(PortSettings("dvl", "pd6"), ref_stale_s=3.0)
    p.feed(T0, "dvl", _pd6((2.5, 0.2)))
    assert _ground(_vbw(p, T0 + 2.9)) == pytest.approx((2.5, 0.2), abs=0.006)
    assert _empty(_vbw(p, T0 + 3.1))


def test_no_reference_gives_no_ground_pair() -> None:
    """Without a reference sample the ground pair is empty with V."""
    assert _empty(_vbw(_pipeline(PortSettings("dvl", "pd6")), T0))


def _fresh(ref_stale_s: float = 5.0) -> Pipeline:
    """A log sending VBW against a PD6 DVL, no VBW sent yet."""
    s = UutSettings(port="log", reference_port="dvl", uut_source="VBW", ref_stale_s=ref_stale_s)
    return Pipeline([LOG, PortSettings("dvl", "pd6")], [s])


def test_the_first_vbw_carries_the_bottom_track_heard_before_it() -> None:
    """Before its first VBW a log keeps only the reference's latest sample, unchecked (a
    VHW-only log pays one tuple per reference sample); the first VBW's look-up checks it,
    so that VBW already carries the pair with A."""
    p = _fresh()
    p.feed(T0 - 5.0, "dvl", _pd6((1.0, 0.5)))
    p.feed(T0, "dvl", _pd6((2.5, 0.2)))
    assert p.uuts["log"].ground.latest is None
    assert _ground(_vbw(p, T0 + 0.1)) == pytest.approx((2.5, 0.2), abs=0.006)
    p.feed(T0 + 0.2, "dvl", _pd6((2.5, 0.3)))
    assert _ground(_vbw(p, T0 + 0.3)) == pytest.approx((2.5, 0.3), abs=0.006)


@pytest.mark.parametrize(
    ("ship", "at"), [(None, 0.1), ((2.5, 0.2), 3.1)], ids=["no-bottom-lock", "stale"]
)
def test_the_first_vbw_is_v_when_the_sample_before_it_is_invalid_or_stale(
    ship: tuple[float, float] | None, at: float
) -> None:
    """The sample kept before the first VBW goes through the same checks: without bottom
    lock, or older than ``ref_stale_s``, the first VBW's ground pair is empty with V."""
    p = _fresh(ref_stale_s=3.0)
    p.feed(T0, "dvl", _pd6(ship))
    assert _empty(_vbw(p, T0 + at))


def test_gnss_velocity_turned_into_the_hull_frame() -> None:
    """A GNSS reference's SOG and COG with the heading at the fix's time go out as
    SOG·cos(COG − ψ) along and SOG·sin(COG − ψ) across the hull; a fix without status A
    withdraws the pair."""
    p = _pipeline(PortSettings("gps", "nmea0183"), reference_field="gnss", heading="gps")
    sog, cog, psi = 3.0, 70.0, 60.0
    for k in range(3):
        gps = encode_rmc(None, sog, cog) + "\r\n" + encode_hdt(psi) + "\r\n"
        p.feed(T0 + k, "gps", gps.encode())
    want = (sog * math.cos(math.radians(cog - psi)), sog * math.sin(math.radians(cog - psi)))
    assert _ground(_vbw(p, T0 + 2.5)) == pytest.approx(want, abs=0.006)
    gps = encode_rmc(None, sog, cog, active=False) + "\r\n" + encode_hdt(psi) + "\r\n"
    p.feed(T0 + 3.0, "gps", gps.encode())
    p.feed(T0 + 4.0, "gps", (encode_hdt(psi) + "\r\n").encode())
    assert _empty(_vbw(p, T0 + 4.5))
