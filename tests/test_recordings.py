"""The tests' reading of captures once per run (tests/recordings.py): served again only
for the same inputs, equal to a reading of its own, a copy, shared through a folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from emlogd.offline.dataset import record_captures
from emlogd.offline.jobs import OfflineError
from emlogd.offline.twoaxis import record_two_axis
from emlogd.pipeline.settings import UutSettings
from tests.recordings import ReadOnce, TwoAxisOnce

ROOT = Path(__file__).resolve().parents[1]
CAPTURE = ROOT / "examples" / "captures" / "3-straight.cap.gz"
OTHER = ROOT / "examples" / "captures" / "2-figure8.cap.gz"
E1 = UutSettings(port="emlog1", reference_port="dvl", lag_s=3.2)


def test_a_capture_is_read_once_for_the_same_inputs_and_again_for_others(
    tmp_path: Path,
) -> None:
    """The same capture and settings (another lag: the reading uses none) are served
    without a second reading and equal the reading's own; another UUT, strict, or a
    rewritten file are read again; each caller gets its own copy."""
    cap = tmp_path / CAPTURE.name
    shutil.copyfile(CAPTURE, cap)
    once = ReadOnce(record_captures)
    once([cap], E1, workers=1)
    again = once([cap], UutSettings(port="emlog1", reference_port="dvl", lag_s=0.5))[0]
    assert once.reads == 1
    own = record_captures([cap], E1, workers=1)[0]
    for name in ("t_read", "raw", "t_ref", "v_ref", "ok_ref", "heading"):
        assert np.array_equal(getattr(again, name), getattr(own, name), equal_nan=True), name
    assert again.counters == own.counters and again.path == own.path
    again.raw[:] = -1.0
    assert not np.array_equal(once([cap], E1)[0].raw, again.raw)
    assert once.reads == 1
    once([cap], UutSettings(port="emlog2", reference_port="dvl"))
    assert once.reads == 2
    once([cap], E1, strict=True)
    assert once.reads == 3
    shutil.copyfile(OTHER, cap)  # another capture at the same path
    assert once([cap], E1)[0].raw.size == record_captures([OTHER], E1)[0].raw.size
    assert once.reads == 4


def test_progress_is_said_for_each_capture_in_order() -> None:
    """Served or read, each capture's progress is said as the real reading says it."""
    once = ReadOnce(record_captures)
    said: list[tuple[str, float]] = []
    for _ in range(2):
        said.clear()
        once([CAPTURE, CAPTURE], E1, progress=lambda m, f: said.append((m, f)))
        assert said == [(f"read {CAPTURE.name}", 0.5), (f"read {CAPTURE.name}", 1.0)]


def test_what_one_process_read_another_loads_from_the_folder(tmp_path: Path) -> None:
    """Two readers on one folder (two workers of a run): what the first read, the second
    serves without reading, equal; without the folder it reads its own."""
    first = ReadOnce(record_captures, tmp_path / "shared")
    a = first([CAPTURE], E1)[0]
    second = ReadOnce(record_captures, tmp_path / "shared")
    b = second([CAPTURE], E1)[0]
    assert second.reads == 0
    assert np.array_equal(a.raw, b.raw) and a.counters == b.counters
    alone = ReadOnce(record_captures)
    alone([CAPTURE], E1)
    assert alone.reads == 1
    two = TwoAxisOnce(record_two_axis, tmp_path / "shared")
    two(CAPTURE, "emlog2", "dvl")
    other = TwoAxisOnce(record_two_axis, tmp_path / "shared")
    assert np.array_equal(
        other(CAPTURE, "emlog2", "dvl").raw_t, two(CAPTURE, "emlog2", "dvl").raw_t
    )
    assert (two.reads, other.reads) == (1, 0)


def test_a_two_axis_reading_is_kept_per_file_and_ports(tmp_path: Path) -> None:
    """``--axes 2``'s reading: served again for the same file and ports, equal to a
    reading of its own and a copy; other ports (here a log without VBW: refused) or a
    rewritten file are read again."""
    cap = tmp_path / CAPTURE.name
    shutil.copyfile(CAPTURE, cap)
    once = TwoAxisOnce(record_two_axis)
    once(cap, "emlog2", "dvl").raw_l[:] = -1.0
    again = once(cap, "emlog2", "dvl")
    assert once.reads == 1
    own = record_two_axis(cap, "emlog2", "dvl")
    for name in ("t_read", "raw_l", "raw_t"):
        assert np.array_equal(getattr(again, name), getattr(own, name), equal_nan=True), name
    with pytest.raises(OfflineError, match="emlog1 sends no VBW"):
        once(cap, "emlog1", "dvl")  # read: emlog1 has no athwart speed to give
    shutil.copyfile(OTHER, cap)
    assert (
        once(cap, "emlog2", "dvl").raw_l.size == record_two_axis(OTHER, "emlog2", "dvl").raw_l.size
    )
    assert once.reads == 2
