"""``emlogd import --format nmea`` when the GNSS fix time jumps back: a receiver reset,
a date that does not advance at midnight. Synthetic logs only."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from drivers.io.capture import CaptureReader
from drivers.nmea0183 import encode_rmc, encode_vhw
from emlogd.offline.importnmea import RESET_FIXES, import_nmea

T0 = datetime(2026, 3, 4, 10, 0, 0, tzinfo=UTC)


def _log(fixes: list[datetime], tmp_path: Path) -> Path:
    """An RMC at each time, each followed by a VHW."""
    lines: list[str] = []
    for k, t in enumerate(fixes):
        lines += [encode_rmc(t, 3.0, 90.0), encode_vhw(2.9 + k / 100)]
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    return src


def _times(cap: Path) -> list[float]:
    return [r.t for r in CaptureReader(cap)]


def test_a_receiver_reset_starts_a_new_time_base(tmp_path: Path) -> None:
    """Ten fixes, then the receiver's clock an hour back for ten more: after RESET_FIXES
    fixes on it the new time base is taken, shifted to follow the old one a fix
    interval after its last fix; only the sentence between the two bases is lost
    (``time_reset``), every sentence after the reset is kept, in time order."""
    back = T0 - timedelta(hours=1)
    fixes = [T0 + timedelta(seconds=k) for k in range(10)]
    fixes += [back + timedelta(seconds=k) for k in range(10)]
    rep = import_nmea([_log(fixes, tmp_path)], tmp_path / "o.cap")
    assert rep.skipped == {"time_reset": 1, "after_last_fix": 1}
    assert rep.notes == {"time_base_reset": 1}
    assert rep.sentences == {"RMC": 20, "VHW": 18}
    times = _times(tmp_path / "o.cap")
    assert times == sorted(times)
    assert rep.t_start == T0.timestamp() and rep.t_end == T0.timestamp() + 19.0


def test_fewer_going_back_than_reset_fixes_time_nothing(tmp_path: Path) -> None:
    """Two fixes going back (fewer than RESET_FIXES, 3), then the old time base again:
    no new base; those fixes time nothing (noted), and their sentences are spread as
    before."""
    assert RESET_FIXES == 3
    fixes = [T0 + timedelta(seconds=k) for k in range(5)]
    fixes += [T0 - timedelta(hours=1, seconds=-k) for k in range(2)]
    fixes += [T0 + timedelta(seconds=5 + k) for k in range(5)]
    rep = import_nmea([_log(fixes, tmp_path)], tmp_path / "o.cap")
    assert rep.notes == {"fix_time_not_increasing": 2}
    assert rep.skipped == {"after_last_fix": 1}
    assert rep.written == 2 * len(fixes) - 1 and rep.t_end == T0.timestamp() + 9.0


def test_fixes_going_back_out_of_order_are_no_time_base(tmp_path: Path) -> None:
    """Fixes an hour back but not following one another (each earlier than the one
    before): no new base; the rest of the log is untimed as before."""
    fixes = [T0 + timedelta(seconds=k) for k in range(5)]
    fixes += [T0 - timedelta(hours=1, seconds=k) for k in range(5)]
    rep = import_nmea([_log(fixes, tmp_path)], tmp_path / "o.cap")
    assert "time_base_reset" not in rep.notes
    assert rep.notes == {"fix_time_not_increasing": 5} and rep.skipped == {"after_last_fix": 11}


def test_a_date_advancing_late_at_midnight_loses_nothing(tmp_path: Path) -> None:
    """RMC whose time rolls over at midnight while its date stays the day before for 5
    s: the jump back by a whole day is taken as a new base a day on (no sentence
    lost), and when the date catches up the fixes are on the first base again."""
    t0 = datetime(2026, 3, 4, 23, 59, 55, tzinfo=UTC)
    fixes = [t0 + timedelta(seconds=k) for k in range(15)]
    lines: list[str] = []
    for k, t in enumerate(fixes):
        rmc = encode_rmc(t, 3.0, 90.0)
        if 5 <= k < 10:  # 00:00:00 to 00:00:04 under the day before's date
            rmc = encode_rmc(t - timedelta(days=1), 3.0, 90.0)
        lines += [rmc, encode_vhw(3.0 + k / 100)]
    src = tmp_path / "log.nmea"
    src.write_text("\n".join(lines) + "\n")
    rep = import_nmea([src], tmp_path / "o.cap")
    assert rep.notes == {"time_base_reset": 1, "time_base_returned": 1}
    assert rep.skipped == {"after_last_fix": 1} and rep.written == 29
    times = _times(tmp_path / "o.cap")
    assert times == pytest.approx([t0.timestamp() + k / 2 for k in range(29)])


def test_a_reset_to_a_default_date_and_back(tmp_path: Path) -> None:
    """A receiver reset to a default date (2006) for 8 s, then its own time again: the
    default date's fixes follow the log's, and the log's time is taken again when it
    comes back; the times stay in order and near the log's."""
    default = datetime(2006, 1, 1, tzinfo=UTC)
    fixes = [T0 + timedelta(seconds=k) for k in range(10)]
    fixes += [default + timedelta(seconds=k) for k in range(8)]
    fixes += [T0 + timedelta(seconds=20 + k) for k in range(10)]
    rep = import_nmea([_log(fixes, tmp_path)], tmp_path / "o.cap")
    assert rep.notes == {"time_base_reset": 1, "time_base_returned": 1}
    assert rep.skipped == {"time_reset": 1, "after_last_fix": 1}
    times = _times(tmp_path / "o.cap")
    assert times == sorted(times) and rep.t_end == T0.timestamp() + 29.0
    assert rep.sentences["RMC"] == 28
