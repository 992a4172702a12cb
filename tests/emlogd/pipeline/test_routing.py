"""Routing's parts: navigation items, the headings by port, the GNSS projection."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import pytest

from drivers import make_decoder
from drivers.framing import with_checksum
from drivers.nmea0183 import encode_vhw
from drivers.rdi_ascii import encode_pd6
from drivers.records import SpeedRecord
from emlogd.pipeline.routing import Headings, NavHeading, UutRoute, nav_items
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.uut import UutCalibration


class TestNavigationItems:
    """Decoded records become routing items by type and by the speed record's typed role."""

    def test_roles_route_speeds_and_headings_travel_with_them(self) -> None:
        """A speed goes to the reference field of its role (a VBW ground pair to none), and a
        heading sent with a speed precedes it, true and magnetic apart."""

        nmea = make_decoder("nmea0183", "n")
        vhw = encode_vhw(2.0, heading_true_deg=10.0, heading_mag_deg=12.0)
        vbw = with_checksum("VMVBW,2.0,0.1,A,2.1,0.2,A")
        recs = nmea.decode_all(f"{vhw}\r\n{vbw}\r\n".encode())
        items = [it for r in recs for it in nav_items(nmea, r)]
        assert [type(it).__name__ for it in items] == ["NavHeading", "SpeedRecord", "SpeedRecord"]
        assert items[0] == NavHeading(10.0, 12.0, None, "VHW")
        assert isinstance(items[1], SpeedRecord) and isinstance(items[2], SpeedRecord)
        assert (items[1].role, items[1].source, items[1].heading_mag_deg) == (
            "speed",
            "VHW",
            12.0,
        )
        assert (items[2].role, items[2].source) == ("speed", "VBW")
        pd6 = make_decoder("pd6", "d")
        lines = encode_pd6(
            timestamp=datetime(2026, 1, 1, tzinfo=UTC),
            heading_deg=30.0,
            bottom_ship_mps=(0.1, 2.0, 0.0),
            range_m=9.0,
            water_ship_mps=(0.0, 1.5, 0.0),
        )
        (ens,) = pd6.decode_all("".join(x + "\r\n" for x in lines).encode())
        got = [
            (type(it).__name__, it.role if isinstance(it, SpeedRecord) else None)
            for it in nav_items(pd6, ens)
        ]
        assert got == [
            ("NavHeading", None),
            ("SpeedRecord", "bottom"),
            ("NavHeading", None),
            ("SpeedRecord", "water"),
        ]


def _uut(**kw: object) -> UutSettings:
    return UutSettings(port="log", reference_port="dvl", **kw)  # type: ignore[arg-type]


class TestHeadings:
    """Each port's headings, the order a UUT looks for one in, and the variation."""

    def test_auto_prefers_the_reference_then_the_uut_then_any_port(self) -> None:
        """auto: the reference's port first, then the UUT's own, then the others in
        config order; the port the heading came from is returned with it."""
        h = Headings(["log", "dvl", "hdg"], [_uut()])
        assert h.order(_uut()) == ["dvl", "log", "hdg"]
        assert h.order(_uut(heading="hdg")) == ["hdg"]
        h.add(10.0, "hdg", NavHeading(90.0, None, None))
        h.add(11.0, "hdg", NavHeading(91.0, None, None))
        assert h.at(h.order(_uut()), 10.5) == pytest.approx((90.5, "hdg"))
        h.add(10.0, "log", NavHeading(80.0, None, None))
        h.add(11.0, "log", NavHeading(80.0, None, None))
        assert h.at(h.order(_uut()), 10.5) == pytest.approx((80.0, "log"))

    def test_a_heading_beyond_the_gap_is_not_used(self) -> None:
        """A heading arriving every second bridges HEADING_MAX_GAP_S (its cadence's gap is
        shorter): a time further than that from a bracketing sample is not interpolated,
        and has no heading unless a sample is within HEADING_NEAREST_S."""
        h = Headings(["hdg"], [_uut(heading="hdg")])
        for k in range(11):
            h.add(float(k), "hdg", NavHeading(90.0, None, None))
        h.add(15.0, "hdg", NavHeading(95.0, None, None))
        assert h.at(["hdg"], 10.5) == pytest.approx((90.0, "hdg"))
        assert h.at(["hdg"], 12.7) is None  # 2.7 s from 10 s: beyond 2.5 intervals of 1 s
        h.add(16.0, "hdg", NavHeading(96.0, None, None))
        assert h.at(["hdg"], 15.5) == pytest.approx((95.5, "hdg"))

    def test_a_magnetic_heading_needs_a_variation(self) -> None:
        """Without any variation a magnetic heading is refused and counted; with the
        config's variation it becomes true; a port's own variation wins over the config's."""
        h = Headings(["hdg"], [_uut()])
        h.add(10.0, "hdg", NavHeading(None, 100.0, None))
        assert h.rings["hdg"].refused_magnetic == 1 and h.variation_of("hdg") is None
        h = Headings(["hdg"], [_uut(magnetic_variation_deg=-3.0)])
        h.add(10.0, "hdg", NavHeading(None, 100.0, None))
        assert h.at(["hdg"], 10.0) == pytest.approx((97.0, "hdg"))
        h.variation["hdg"] = 2.0
        assert h.variation_of("hdg") == 2.0 and h.variation_of("other") == 2.0


class TestGnssProjection:
    """A GNSS fix becomes a reference along the hull once the heading at its time is known."""

    def _route(self, **kw: object) -> tuple[UutRoute, list[tuple[float, float | None, bool]]]:
        s = _uut(reference_field="gnss", lag_s=0.0, **kw)
        got: list[tuple[float, float | None, bool]] = []

        class Recording(UutCalibration):
            def add_reference(self, t: float, v_mps: float | None, valid: bool) -> None:
                got.append((t, v_mps, valid))

        cal = Recording(s, None, lambda t: None, lambda t, k, d: None)
        return UutRoute(s, cal, ["gnss"]), got

    def test_sog_is_projected_with_the_heading_at_the_fix(self) -> None:
        """SOG·cos(COG − ψ) with ψ at the fix's time; below min_sog_mps the fix is invalid."""
        u, got = self._route(min_sog_mps=0.5)
        u.gnss.append((10.0, 3.0, 40.0, True))
        u.gnss.append((11.0, 0.2, 40.0, True))
        u.project(None, lambda t: 10.0, 11.0)
        assert got[0][0] == 10.0 and got[0][2] is True
        assert got[0][1] == pytest.approx(3.0 * math.cos(math.radians(30.0)))
        assert got[1] == (11.0, None, False)

    def test_a_fix_waits_for_its_heading_but_not_forever(self) -> None:
        """A fix whose heading has not arrived waits while younger than GNSS_HEADING_WAIT_S,
        then goes as invalid when no heading comes."""
        from emlogd.pipeline.align import SampleRing

        ring = SampleRing(16, 2.0, angular=True)
        ring.add(9.0, 10.0)
        u, got = self._route()
        u.gnss.append((10.0, 3.0, 40.0, True))
        u.project(ring, lambda t: None, 11.0)
        assert got == [] and len(u.gnss) == 1
        u.project(ring, lambda t: None, 12.5)
        assert got == [(10.0, None, False)] and not u.gnss


class TestOverRange:
    """A reading above the log's configured range goes out raw, up to twice the range."""

    def test_above_the_range_up_to_twice_it_goes_out_raw_and_is_counted(self) -> None:
        """Range 8 m/s: 8 is in range, 8.01 to 16 above it (passed raw), 16.01 refused.
        Each passed reading counted; the replay's hook hears the learnt sentence's alone;
        a log with a fault stays silent above its range as below it."""
        s = _uut(lag_s=0.0)
        cal = UutCalibration(s, None, lambda t: None, lambda t, k, d: None)
        u = UutRoute(s, cal, ["dvl"])
        assert [u.over_range(v) for v in (8.0, 8.01, 16.0, 16.01)] == [False, True, True, False]
        heard: list[tuple[float, float]] = []
        u.passed = lambda t, v: heard.append((t, v))
        assert u.passed_raw(1.0, 9.5, True) == 9.5 and u.passed_raw(1.5, 9.6, False) == 9.6
        assert heard == [(1.0, 9.5)] and cal.counters.over_range == 2
        cal.sup.health.fault = "uut_stuck"
        assert u.passed_raw(2.0, 9.5, True) is None
