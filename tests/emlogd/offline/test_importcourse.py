"""``emlogd import --format nmea``: an RMC without a course over ground given the course
from the positions around it, when the speed and their spacing allow it. Synthetic
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


def test_a_course_from_the_positions_around(tmp_path: Path) -> None:
    """At 5 kn on 060°, one fix a second, positions to 0.0001' (2.6 m a second, 14
    resolutions): every RMC is given a course within 3° of the track's (their
    rounding), 0.5° on average, and counted; the first and the last from the positions
    on their one side."""
    notes, rmc = _import(_log(_track(20, 5.0, 60.0), 5.0), tmp_path)
    assert notes == {"course_from_positions": 20}
    got = [r.cog_true_deg or math.nan for r in rmc]
    assert got == pytest.approx([60.0] * 20, abs=3.0)
    assert sum(got) / len(got) == pytest.approx(60.0, abs=0.5)


def test_coarse_positions_reach_further(tmp_path: Path) -> None:
    """Positions to 0.001' (1.85 m): the course comes from the fixes at least 8
    resolutions (15 m) apart, each within 5 s — at 7 kn (3.6 m a second), 2 or 3
    fixes either side — and is the track's within 5°; the second and third fixes, too
    near the first for a centred span and with one before them, have none."""
    notes, rmc = _import(_log(_track(20, 7.0, 200.0), 7.0, decimals=3), tmp_path)
    assert notes["course_empty"] <= 3
    assert notes["course_from_positions"] == 20 - notes["course_empty"]
    got = [r.cog_true_deg for r in rmc if r.cog_true_deg is not None]
    assert got == pytest.approx([200.0] * len(got), abs=5.0)


@pytest.mark.parametrize(
    ("speed_kn", "decimals"),
    [(0.3, None), (5.0, 2)],
)
def test_no_course_when_speed_or_spacing_do_not_allow(
    tmp_path: Path, speed_kn: float, decimals: int | None
) -> None:
    """At 0.3 kn (1.5 m over 10 s, under the 2 m asked), or with positions to 0.01'
    (18.5 m: 148 m asked), no RMC is given a course: each is counted ``course_empty``."""
    notes, rmc = _import(_log(_track(12, speed_kn, 60.0), speed_kn, decimals=decimals), tmp_path)
    assert notes == {"course_empty": 12}
    assert all(r.cog_true_deg is None for r in rmc)


def test_a_position_jump_gives_no_course(tmp_path: Path) -> None:
    """A fix 60 m off the track (a position jump): the fixes either side of it, whose
    span it ends, disagree with the speed over ground and get no course; the jumped fix
    itself is given the bearing between its neighbours."""
    track = _track(10, 5.0, 60.0)
    t, lat, lon = track[5]
    track[5] = (t, lat + math.degrees(60.0 / 6_371_000.0), lon)
    notes, rmc = _import(_log(track, 5.0), tmp_path)
    assert rmc[4].cog_true_deg is None and rmc[6].cog_true_deg is None
    assert rmc[5].cog_true_deg == pytest.approx(60.0, abs=3.0)
    assert notes == {"course_from_positions": 8, "course_empty": 2}


def test_a_turning_boats_course_does_not_lag(tmp_path: Path) -> None:
    """Turning at 6° a second at 6 kn, positions to 0.0001': the centred course is the
    boat's at the fix's time (its error's mean within 1°), where a bearing from the
    positions before alone lags by half its span (3° for a span of 1 s)."""
    v = 6.0 * KNOT_MPS
    rate = math.radians(6.0)
    radius = v / rate
    track, truth = [], []
    for k in range(40):
        a = rate * k
        north, east = radius * math.sin(a), radius * (1.0 - math.cos(a))
        lat = LAT0 + math.degrees(north / 6_371_000.0)
        lon = LON0 + math.degrees(east / (6_371_000.0 * math.cos(math.radians(LAT0))))
        track.append((T0 + timedelta(seconds=k), lat, lon))
        truth.append(math.degrees(a) % 360.0)
    _, rmc = _import(_log(track, 6.0), tmp_path)
    err = [
        (r.cog_true_deg - c + 180.0) % 360.0 - 180.0
        for r, c in zip(rmc[1:-1], truth[1:-1], strict=True)
        if r.cog_true_deg is not None
    ]
    assert len(err) == 38
    assert abs(sum(err) / len(err)) < 1.0


def test_the_lines_keep_their_order(tmp_path: Path) -> None:
    """The lines held back while an RMC waits for the fixes after it are written in the
    log's order, each RMC with its course, the others byte for byte (the last line, after
    the last fix, has no time and is counted ``after_last_fix``)."""
    lines = _log(_track(8, 5.0, 60.0), 5.0)
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    import_nmea([src], tmp_path / "o.cap")
    out = [r.data.decode().strip() for r in CaptureReader(tmp_path / "o.cap")]
    assert len(out) == len(lines) - 1
    for a, b in zip(out, lines[:-1], strict=True):
        assert a == b if b[3:6] != "RMC" else a.split(",")[:8] == b.split(",")[:8]


def test_an_rmc_with_its_course_is_kept_as_written(tmp_path: Path) -> None:
    """An RMC that has a course is written byte for byte; nothing is noted."""
    lines = [encode_rmc(t, 2.5, 61.0, lat_deg=a, lon_deg=o) for t, a, o in _track(5, 5.0, 60.0)]
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    assert not rep.notes
    assert [r.data.decode().strip() for r in CaptureReader(tmp_path / "o.cap")] == lines


def test_a_waiting_rmc_holds_back_a_bounded_number_of_lines(tmp_path: Path) -> None:
    """An RMC waiting for the fixes after it holds back at most HOLD_MAX_LINES lines (the
    GNSS silent, the log going on), and none past a fix whose time went back (a receiver
    reset): the lines come out as they are read, not at the end of the log."""
    from emlogd.offline.importbase import ImportReport
    from emlogd.offline.importcourse import HOLD_MAX_LINES, CourseFill

    track = _track(3, 5.0, 60.0)
    rmcs = [
        _no_course(encode_rmc(t, 5.0 * KNOT_MPS, 0.0, lat_deg=a, lon_deg=o)) for t, a, o in track
    ]
    vhw = encode_vhw(5.0 * KNOT_MPS)
    fill = CourseFill(ImportReport([], str(tmp_path / "o.cap"), "nmea"))
    out = [x for line in rmcs[:2] for x in fill.lines(line)]
    for _ in range(HOLD_MAX_LINES + 5):
        out += fill.lines(vhw)
    assert len(out) >= HOLD_MAX_LINES  # the silence does not hold the log back for ever
    reset = encode_rmc(T0 - timedelta(hours=1), 5.0 * KNOT_MPS, 0.0, lat_deg=LAT0, lon_deg=LON0)
    fill = CourseFill(ImportReport([], str(tmp_path / "o.cap"), "nmea"))
    out = [x for line in [rmcs[0], _no_course(reset)] for x in fill.lines(line)]
    assert out == [rmcs[0]]  # released at the reset, not waiting for a fix 5 s after it
