"""Magnetic variation from the IGRF model, its routing to magnetic headings, and the
heading-against-course check."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any

import pytest

from drivers.framing import with_checksum
from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.pipeline import routing
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.routing import MODEL_VARIATION_S
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.variation import (
    MAX_HEADING_OFFSET_DEG,
    CourseOffsetCheck,
    decimal_year,
    model_variation,
)
from tests.nmea_encoders import encode_gga, encode_hdt

T0 = datetime(2014, 6, 27, 13, 0, tzinfo=UTC).timestamp()


def _epoch(year: float) -> float:
    y = int(year)
    start = datetime(y, 1, 1, tzinfo=UTC).timestamp()
    return start + (year - y) * (datetime(y + 1, 1, 1, tzinfo=UTC).timestamp() - start)


# The declination test values published with the World Magnetic Model (the NOAA NCEI /
# BGS technical reports "The US/UK World Magnetic Model for 2010-2015" and "for
# 2015-2020", their tables of test values: date, height 0 km, latitude, longitude 240°
# written here as -120°). IGRF and WMM are separate fits of the same field: they agree
# within a few tenths of a degree at these points.
PUBLISHED: list[tuple[float, float, float, float]] = [
    (2010.0, 80.0, 0.0, -6.13),
    (2010.0, 0.0, 120.0, 0.97),
    (2010.0, -80.0, 240.0 - 360.0, 70.21),
    (2015.0, 80.0, 0.0, -3.85),
    (2015.0, 0.0, 120.0, 0.57),
    (2015.0, -80.0, 240.0 - 360.0, 69.81),
]


class TestModel:
    """IGRF-14 declination against published values."""

    @pytest.mark.parametrize(("year", "lat", "lon", "decl"), PUBLISHED)
    def test_published_declinations(self, year: float, lat: float, lon: float, decl: float) -> None:
        """The model's variation is the published declination within 0.3°."""
        v = model_variation(lat, lon, _epoch(year))
        assert v is not None
        assert v == pytest.approx(decl, abs=0.3)

    def test_the_2000s_are_covered(self) -> None:
        """A 2005 log (Valencia) gets its own epoch's variation, west of north, not
        today's: the declination in western Europe has drifted east by about 0.15° a
        year and crossed zero there in the 2010s."""
        v = model_variation(39.40, -0.30, _epoch(2005.45))
        assert v is not None and -2.0 < v < -0.5
        now = model_variation(39.40, -0.30, _epoch(2025.0))
        assert now is not None and now > 0.5

    def test_outside_the_model_or_the_globe_gives_nothing(self) -> None:
        """No model value before 1900 or after 2030, nor for an impossible position."""
        assert model_variation(46.0, 6.0, _epoch(1850.0)) is None
        assert model_variation(46.0, 6.0, _epoch(2031.0)) is None
        assert model_variation(91.0, 6.0, T0) is None
        assert model_variation(46.0, math.nan, T0) is None

    def test_decimal_year(self) -> None:
        """Mid-year is half a year."""
        assert decimal_year(datetime(2021, 7, 2, 12, tzinfo=UTC).timestamp()) == pytest.approx(
            2021.5, abs=1e-3
        )


def _pipeline(**kw: Any) -> Pipeline:
    return Pipeline(
        [PortSettings("nmea", "nmea0183")],
        [UutSettings(port="nmea", reference_port="nmea", reference_field="gnss", lag_s=0.0, **kw)],
    )


def _feed(p: Pipeline, t: float, sentence: str) -> None:
    p.feed(t, "nmea", (sentence + "\r\n").encode())


class TestRouting:
    """A magnetic heading with no variation in the log takes the model's."""

    def test_magnetic_heading_and_gnss_position_use_the_model(self) -> None:
        """HDG with an empty variation + RMC with a position and none: the heading is
        magnetic + the IGRF variation there, and the status says so."""
        p = _pipeline()
        lat, lon = 46.22, 6.17  # Lake Geneva
        fix = encode_rmc(datetime.fromtimestamp(T0, UTC), 3.0, 100.0, lat_deg=lat, lon_deg=lon)
        _feed(p, T0, with_checksum("IIHDG,100.0,,,,"))  # before any position: refused
        _feed(p, T0 + 0.5, fix)
        _feed(p, T0 + 1.0, with_checksum("IIHDG,100.0,,,,"))
        var = model_variation(lat, lon, T0)
        assert var is not None and 1.0 < var < 2.0
        assert p._heading_at("nmea", T0 + 1.0) == pytest.approx(100.0 + var, abs=0.01)
        h = p.status()["uuts"]["nmea"]["heading"]  # type: ignore[index]
        assert h["variation_source"] == "model"
        assert h["variation_deg"] == pytest.approx(var, abs=0.01)
        assert h["refused_magnetic"] == 1

    def test_a_gga_position_serves_too(self) -> None:
        """GGA (a position with a fix, no date: the receive time's date) gives the model
        its position when the RMC has none."""
        p = _pipeline()
        t = datetime.fromtimestamp(T0, UTC)
        _feed(p, T0, encode_gga(t, 46.2, 6.2))
        _feed(p, T0 + 0.5, encode_rmc(t, 3.0, 100.0))
        _feed(p, T0 + 1.0, with_checksum("IIHDG,100.0,,,,"))
        assert p.variation_source("nmea")[1] == "model"
        var = model_variation(46.2, 6.2, T0)
        assert var is not None
        assert p._heading_at("nmea", T0 + 1.0) == pytest.approx(100.0 + var, abs=0.01)

    def test_the_log_and_the_configuration_come_before_the_model(self) -> None:
        """A configured variation beats the model; a variation in the log beats both."""
        p = _pipeline(magnetic_variation_deg=-5.0)
        fix = encode_rmc(datetime.fromtimestamp(T0, UTC), 3.0, 100.0, lat_deg=46.2, lon_deg=6.2)
        _feed(p, T0, fix)
        _feed(p, T0 + 1.0, with_checksum("IIHDG,100.0,,,,"))
        assert p._heading_at("nmea", T0 + 1.0) == pytest.approx(95.0)
        assert p.variation_source("nmea") == (-5.0, "config")
        _feed(p, T0 + 2.0, with_checksum("IIHDG,100.0,,,3.0,E"))
        assert p.variation_source("nmea") == (3.0, "log")

    def test_fixes_whose_date_changes_at_every_sentence_cost_one_model_a_second(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """RMC at 100 Hz for 2 s, each a day after the one before (a hostile or broken
        receiver: dates across years): the model is computed at most once per
        MODEL_VARIATION_S of receive time, not per sentence (0.5 ms each, a day and a
        cell per sentence cost the daemon's thread half its time at 1000 sentences/s); the
        variation still follows the fixes."""
        calls: list[float] = []

        def counted(lat: float, lon: float, t: float) -> float | None:
            calls.append(t)
            return model_variation(lat, lon, t)

        monkeypatch.setattr(routing, "model_variation", counted)
        p = _pipeline()
        for k in range(200):
            day = datetime.fromtimestamp(T0 + k * 86400.0, UTC)
            _feed(p, T0 + k * 0.01, encode_rmc(day, 3.0, 100.0, lat_deg=46.2, lon_deg=6.2))
        assert len(calls) <= 2 / MODEL_VARIATION_S + 1, len(calls)
        assert calls[0] == T0  # the fix's own date
        assert p.variation_source("nmea")[1] == "model"


class TestStatusReason:
    """The daemon's status names the heading when it is why the GNSS reference is not valid."""

    def _run(self, heading: str, position: bool) -> str:
        p = _pipeline()
        for k in range(30):
            t = T0 + k
            if heading:
                _feed(p, t, with_checksum(heading))
            pos = {"lat_deg": 46.2, "lon_deg": 6.2} if position else {}
            _feed(p, t + 0.1, encode_rmc(datetime.fromtimestamp(t, UTC), 3.0, 90.0, **pos))  # type: ignore[arg-type]
            _feed(p, t + 0.2, encode_vhw(2.9, talker="II"))
        p.tick(T0 + 31.0)
        reason = p.status()["uuts"]["nmea"]["reason"]  # type: ignore[index]
        assert isinstance(reason, str)
        return reason

    def test_magnetic_without_variation_is_named(self) -> None:
        """GNSS every second, HDG magnetic, no variation anywhere: the reason says so
        (not "reference silent") and how to give one."""
        reason = self._run("IIHDG,90.0,,,,", position=False)
        assert reason.startswith("heading magnetic without a variation (30 refused)")
        assert "magnetic_variation_deg" in reason

    def test_no_heading_is_named(self) -> None:
        """GNSS every second and no heading at all: the reason names the heading."""
        assert self._run("", position=False) == "no heading for the GNSS reference"

    def test_with_a_position_the_model_serves(self) -> None:
        """The same with positions in the RMC: the heading is used, no heading reason."""
        assert "heading" not in self._run("IIHDG,90.0,,,,", position=True)


def _sail(
    heading_error_deg: float, n: int = 600, current: tuple[float, float] = (0.3, -0.2)
) -> list[tuple[float, float, float, float]]:
    """Legs of 60 s on eight headings in a current, with ±4° leeway by tack: the
    (time, heading as sent, SOG, COG) of each fix at 1 Hz."""
    out: list[tuple[float, float, float, float]] = []
    for k in range(n):
        leg = k // 60
        psi = (leg * 135.0) % 360.0
        leeway = 4.0 if leg % 2 else -4.0
        u = 3.0
        course_water = math.radians(psi + leeway)
        vn = u * math.cos(course_water) + current[0]
        ve = u * math.sin(course_water) + current[1]
        sog = math.hypot(vn, ve)
        cog = math.degrees(math.atan2(ve, vn)) % 360.0
        out.append((T0 + k, (psi - heading_error_deg) % 360.0, sog, cog))
    return out


class TestCourseOffsetCheck:
    """The heading's offset from the course through the water, current taken out."""

    def test_a_good_heading_in_a_current_is_not_flagged(self) -> None:
        """True heading, 0.36 m/s current, ±4° leeway: offset near 0, not flagged."""
        c = CourseOffsetCheck()
        for t, h, sog, cog in _sail(0.0):
            c.add(t, h, sog, cog)
        d = c.offset_deg()
        assert d is not None and abs(d) < 2.0
        assert not c.flagged()

    @pytest.mark.parametrize("error", [20.0, -15.0])
    def test_a_wrong_heading_is_flagged_with_its_offset(self, error: float) -> None:
        """A heading 20° (a magnetic heading taken as true, a bad compass) off the water's
        course is flagged, and the offset is measured."""
        c = CourseOffsetCheck()
        for t, h, sog, cog in _sail(error):
            c.add(t, h, sog, cog)
        d = c.offset_deg()
        assert d is not None and d == pytest.approx(error, abs=2.0)
        assert abs(d) > MAX_HEADING_OFFSET_DEG and c.flagged()

    def test_one_leg_decides_nothing(self) -> None:
        """On one heading current and offset are one unknown: undecided."""
        c = CourseOffsetCheck()
        for t, h, sog, cog in _sail(20.0, n=60):
            for j in range(5):
                c.add(t + j * 60.0, h, sog, cog)
        assert c.offset_deg() is None and not c.flagged()


class _Refs:
    """Collects the references a UUT is given (the offline commands' recorder)."""

    def __init__(self) -> None:
        self.refs: list[tuple[float, bool]] = []

    def reference(
        self, t: float, v_mps: float | None, valid: bool, heading_deg: float | None
    ) -> None:
        self.refs.append((t, valid and v_mps is not None))

    def reading(self, t: float, raw_mps: float) -> None:
        pass


def test_a_flagged_heading_projects_no_reference() -> None:
    """Through the pipeline: a heading 20° off the course is flagged in the status and the
    GNSS projections stop (counted), while a good heading keeps them."""
    counts: dict[float, tuple[object, object, int]] = {}
    for error in (0.0, 20.0):
        p = _pipeline()
        rec = _Refs()
        p.uuts["nmea"].cal.recorder = rec
        for t, h, sog, cog in _sail(error):
            _feed(p, t, encode_hdt(h))
            _feed(p, t + 0.1, encode_rmc(datetime.fromtimestamp(t, UTC), sog, cog))
            _feed(p, t + 0.2, encode_vhw(3.0, heading_true_deg=h))
        p.tick(T0 + 700.0)
        h_status = p.status()["uuts"]["nmea"]["heading"]  # type: ignore[index]
        late = sum(1 for t, ok in rec.refs if ok and t > T0 + 400.0)
        counts[error] = (h_status["check"]["flagged"], h_status["refused_by_check"], late)
    assert counts[0.0][:2] == (False, 0) and counts[0.0][2] > 150
    flagged, refused, late = counts[20.0]
    assert flagged is True and isinstance(refused, int) and refused > 100
    assert late == 0
