"""``emlogd import --format nmea``: an RMC without a course over ground given the course
from the positions before it, when the speed and their spacing allow it. Synthetic
logs only."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.framing import split_nmea, with_checksum
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, encode_rmc, encode_vhw
from drivers.records import KNOT_MPS
from emlogd.offline.importnmea import import_nmea

T0 = datetime(2026, 6, 1, 12, 0, 0, tzinfo=UTC)
LAT0, LON0 = 46.2, 6.2


def _track(n: int, speed_kn: float, course_deg: float) -> list[tuple[datetime, float, float]]:
    """(time, lat, lon) of a boat at a constant speed and course, one fix a second."""
    v = speed_kn * KNOT_MPS
    north, east = v * math.cos(math.radians(course_deg)), v * math.sin(math.radians(course_deg))
    out = []
    for k in range(n):
        lat = LAT0 + math.degrees(north * k / 6_371_000.0)
        lon = LON0 + math.degrees(east * k / (6_371_000.0 * math.cos(math.radians(LAT0))))
        out.append((T0 + timedelta(seconds=k), lat, lon))
    return out


def _no_course(line: str, decimals: int | None = None) -> str:
    """The RMC with its course field emptied (and its minutes cut to ``decimals``)."""
    f = split_nmea(line.encode("ascii")).decode("ascii").split(",")
    f[8] = ""
    if decimals is not None:
        for i in (3, 5):
            whole, _, frac = f[i].partition(".")
            f[i] = f"{whole}.{frac[:decimals]}"
    return with_checksum(",".join(f))


def _import(lines: list[str], tmp_path: Path) -> tuple[dict[str, int], list[Rmc]]:
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    dec = make_decoder("nmea0183", "nmea")
    recs = [x for r in CaptureReader(tmp_path / "o.cap") for x in dec.feed(r.data)]
    return dict(rep.notes), [x for x in recs if isinstance(x, Rmc)]


def _log(
    track: list[tuple[datetime, float, float]], speed_kn: float, decimals: int | None = None
) -> list[str]:
    lines = []
    for t, lat, lon in track:
        rmc = encode_rmc(t, speed_kn * KNOT_MPS, 0.0, lat_deg=lat, lon_deg=lon)
        lines += [_no_course(rmc, decimals), encode_vhw(speed_kn * KNOT_MPS)]
    return lines


def test_a_course_from_the_positions_before(tmp_path: Path) -> None:
    """At 5 kn on 060°, one fix a second, positions to 0.0001' (2.6 m a second, 14
    resolutions): every RMC but the first (nothing before it) is given a course within
    3° of the track's (their rounding), 0.5° on average, and counted."""
    notes, rmc = _import(_log(_track(20, 5.0, 60.0), 5.0), tmp_path)
    assert notes == {"course_from_positions": 19, "course_empty": 1}
    assert rmc[0].cog_true_deg is None
    got = [r.cog_true_deg or math.nan for r in rmc[1:]]
    assert got == pytest.approx([60.0] * 19, abs=3.0)
    assert sum(got) / len(got) == pytest.approx(60.0, abs=0.5)


def test_coarse_positions_reach_further_back(tmp_path: Path) -> None:
    """Positions to 0.001' (1.85 m): the course comes from the fix at least 8
    resolutions (15 m) back, within 5 s — at 7 kn (3.6 m a second), 4 or 5 fixes back,
    as the rounding falls — and is the track's within 5°; the first fixes have none."""
    notes, rmc = _import(_log(_track(20, 7.0, 200.0), 7.0, decimals=3), tmp_path)
    assert notes["course_empty"] in (4, 5)
    assert notes["course_from_positions"] == 20 - notes["course_empty"]
    assert all(r.cog_true_deg is None for r in rmc[:4])
    got = [r.cog_true_deg for r in rmc if r.cog_true_deg is not None]
    assert got == pytest.approx([200.0] * len(got), abs=5.0)


@pytest.mark.parametrize(
    ("speed_kn", "decimals"),
    [(0.7, None), (5.0, 2)],
)
def test_no_course_when_speed_or_spacing_do_not_allow(
    tmp_path: Path, speed_kn: float, decimals: int | None
) -> None:
    """At 0.7 kn (1.8 m in 5 s, under the 2 m asked), or with positions to 0.01' (18.5 m:
    148 m asked), no RMC is given a course: each is counted ``course_empty``."""
    notes, rmc = _import(_log(_track(12, speed_kn, 60.0), speed_kn, decimals=decimals), tmp_path)
    assert notes == {"course_empty": 12}
    assert all(r.cog_true_deg is None for r in rmc)


def test_a_position_jump_gives_no_course(tmp_path: Path) -> None:
    """A fix 60 m off the track (a position jump): its distance over the second does not
    agree with the speed over ground, so it gets no course (nor the fix after it, which
    would take its bearing from the jump)."""
    track = _track(10, 5.0, 60.0)
    t, lat, lon = track[5]
    track[5] = (t, lat + math.degrees(60.0 / 6_371_000.0), lon)
    notes, rmc = _import(_log(track, 5.0), tmp_path)
    assert rmc[5].cog_true_deg is None and rmc[6].cog_true_deg is None
    assert notes == {"course_from_positions": 7, "course_empty": 3}


def test_an_rmc_with_its_course_is_kept_as_written(tmp_path: Path) -> None:
    """An RMC that has a course is written byte for byte; nothing is noted."""
    lines = [encode_rmc(t, 2.5, 61.0, lat_deg=a, lon_deg=o) for t, a, o in _track(5, 5.0, 60.0)]
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    assert not rep.notes
    assert [r.data.decode().strip() for r in CaptureReader(tmp_path / "o.cap")] == lines
