"""A GNSS receiver repeating its last fix with new times (emlogd/pipeline/stalefix.py)."""

from __future__ import annotations

from datetime import UTC, datetime

from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.pipeline.core import Output, Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.stalefix import STALE_DISTANCE_M, RepeatedFixes
from tests.emlogd.pipeline.test_core import _Rec
from tests.nmea_encoders import encode_hdt

FIX = (43.1, 5.9, 2.0, 45.0)


class TestRepeatedFixes:
    def test_a_fix_repeated_past_the_distance_its_speed_makes_is_stale_until_it_moves(
        self,
    ) -> None:
        """At 2 m/s kept for 5 s (:data:`STALE_DISTANCE_M`, 10 m); then stale (None once,
        at the start: the event) until any of position, speed and course changes."""
        r = RepeatedFixes()
        got = [r.stale(float(k), "gnss", FIX) for k in range(8)]
        assert STALE_DISTANCE_M / FIX[2] == 5.0
        assert got == [False] * 5 + [None, True, True]
        moved = (FIX[0] + 1e-5, *FIX[1:])
        assert r.stale(8.0, "gnss", moved) is False
        assert r.stale(9.0, "gnss", moved) is False
        assert r.stale(10.0, "other", FIX) is False
        slower = (*FIX[:2], 1.9, FIX[3])
        assert r.stale(11.0, "gnss", slower) is False

    def test_slow_fixes_wait_longer_and_a_sentence_without_a_position_is_not_judged(
        self,
    ) -> None:
        """At rest a position stays put for ever; at 0.1 m/s for 100 s. A VTG (no
        position) between the RMCs leaves the run as it is."""
        r = RepeatedFixes()
        rest = (*FIX[:2], 0.0, FIX[3])
        assert not any(r.stale(float(k), "gnss", rest) for k in range(600))
        drift = (*FIX[:2], 0.1, FIX[3])
        got = [r.stale(600.0 + k, "gnss", drift) for k in range(101)]
        assert got[:100] == [False] * 100 and got[100] is None
        for k in range(5):
            assert r.stale(float(k), "log", FIX) is False
            assert r.stale(k + 0.5, "log", None) is False
        assert r.stale(5.0, "log", FIX) is None


def test_a_receiver_sending_its_last_fix_again_is_no_reference() -> None:
    """RMC repeating one fix (position, 2 m/s, course) with new times for 40 s, then
    moving again: its first 5 s are references (10 m at 2 m/s), the rest not (one
    ``gnss_repeated`` event); the moving fixes after are references again."""
    p = Pipeline(
        [PortSettings("nmea", "nmea0183")],
        [UutSettings(port="nmea", reference_port="nmea", reference_field="gnss")],
    )
    rec = _Rec()
    p.uuts["nmea"].cal.recorder = rec
    out = Output()
    t0 = 1_750_000_000.0
    for k in range(60):
        t = t0 + k
        lat = 43.1 + (0.0 if 10 <= k < 50 else k * 1e-5)
        fix = datetime.fromtimestamp(t, UTC)
        for dt, s in (
            (0.0, encode_hdt(45.0)),
            (0.1, encode_rmc(fix, 2.0, 45.0, lat_deg=lat, lon_deg=5.9)),
            (0.2, encode_vhw(2.0, heading_true_deg=45.0)),
        ):
            out.add(p.feed(t + dt, "nmea", (s + "\r\n").encode()))
    out.add(p.tick(t0 + 70.0))
    valid = {round(t - t0 - 0.1) for t, _v, ok, _h in rec.refs if ok}
    assert valid >= set(range(3, 15)) | set(range(50, 60))
    assert not valid & set(range(15, 50))
    events = [e for e in out.events if e.kind == "gnss_repeated"]
    assert [(e.port, round(e.t - t0, 1)) for e in events] == [("nmea", 15.1)]


def test_one_fix_sent_again_with_its_own_time_is_no_repeat() -> None:
    """One RMC at 4.5 m/s, its own time too, received once a second for 8 s (a receiver
    or a logger sending the fix it has again, as Psaros's log holds for three seconds at
    8.7 kn): its clock says no time passed, so it is not judged stale; by receipt times
    it would have been after 10 m (3 s)."""
    p = Pipeline(
        [PortSettings("nmea", "nmea0183")],
        [UutSettings(port="nmea", reference_port="nmea", reference_field="gnss")],
    )
    out = Output()
    t0 = 1_750_000_000.0
    rmc = encode_rmc(datetime.fromtimestamp(t0, UTC), 4.5, 45.0, lat_deg=43.1, lon_deg=5.9)
    for k in range(8):
        out.add(p.feed(t0 + k, "nmea", (rmc + "\r\n").encode()))
    assert not [e for e in out.events if e.kind == "gnss_repeated"]
    r = RepeatedFixes()
    fast = (*FIX[:2], 4.5, FIX[3])
    assert [r.stale(t0 + k, "gnss", fast) for k in range(5)][-2:] == [None, True]
