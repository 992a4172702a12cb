"""Recordings: a UUT's inputs read from captures exactly as the daemon sees them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.errors import CaptureFormatError
from drivers.io.capture import CaptureWriter
from drivers.nmea0183 import encode_vhw
from emlogd.offline.dataset import CaptureContentError, record_capture, record_captures
from emlogd.pipeline.settings import UutSettings

E1 = UutSettings(port="emlog1", reference_port="dvl")


class TestRecording:
    """What one capture gives."""

    def test_readings_references_and_headings(self, trial_files: dict[str, Path]) -> None:
        """The UUT's VHW readings, the DVL's bottom track and its heading, in time order."""
        rec = record_capture(trial_files["figure-8"], E1)
        assert rec.name == "2-figure8" and rec.uut == "emlog1"
        assert rec.raw.size > 200 and np.all(np.diff(rec.t_read) > 0)
        assert rec.t_ref.size > 10 * rec.raw.size * 0.8
        assert 0.8 < rec.ok_ref.mean() <= 1.0  # bottom-lock losses are invalid samples
        assert np.isfinite(rec.heading).mean() > 0.95
        assert np.all(
            (rec.heading[np.isfinite(rec.heading)] >= 0)
            & (rec.heading[np.isfinite(rec.heading)] < 360)
        )
        records = rec.counters["dvl"]["records"]
        assert isinstance(records, int) and records > 0

    def test_aligned_at_a_lag_uses_the_alignment_rule(self, trial_files: dict[str, Path]) -> None:
        """Alignment pairs each reading with the reference at t − lag, nan across outages."""
        rec = record_capture(trial_files["figure-8"], E1)
        a = rec.aligned(3.3)
        ok = a.usable()
        assert 0.7 < ok.mean() <= 1.0
        i = int(np.flatnonzero(ok)[10])
        j = int(np.searchsorted(rec.t_ref, a.t[i] - 3.3))
        lo, hi = rec.v_ref[j - 1], rec.v_ref[j]
        assert min(lo, hi) - 1e-9 <= a.ref[i] <= max(lo, hi) + 1e-9

    def test_a_missing_port_is_named(self, trial_files: dict[str, Path]) -> None:
        """A capture without the UUT's port raises CaptureContentError listing its ports."""
        with pytest.raises(CaptureContentError, match="no port emlog9"):
            record_capture(
                trial_files["figure-8"], UutSettings(port="emlog9", reference_port="dvl")
            )

    def test_readings_out_of_range_and_bursts_are_not_recorded(self, tmp_path: Path) -> None:
        """The daemon's guards apply: a 77.7 kn reading is refused, a burst keeps its newest."""
        cap = tmp_path / "x.cap"
        with CaptureWriter(cap, {"log": "nmea0183", "dvl": "pd6"}) as w:
            w.write_line(1.0, "log", encode_vhw(2.0).encode())
            w.write_line(2.0, "log", encode_vhw(40.0).encode())
            w.write_chunk(
                3.0, "log", b"".join((encode_vhw(v) + "\r\n").encode() for v in (2.1, 2.2))
            )
        rec = record_capture(cap, UutSettings(port="log", reference_port="dvl"))
        assert rec.raw.tolist() == pytest.approx([2.0, 2.2], abs=0.003)
        assert rec.uut_counters["out_of_range"] == 1 and rec.uut_counters["backlog"] == 1


def test_several_captures_in_parallel_give_the_same_recordings(
    trial_files: dict[str, Path],
) -> None:
    """record_captures with worker processes equals the one-by-one reading, in order."""
    paths = [trial_files["straight"], trial_files["figure-8"]]
    serial = record_captures(paths, E1, workers=1)
    parallel = record_captures(paths, E1, workers=2)
    assert [r.name for r in parallel] == ["3-straight", "2-figure8"]
    for a, b in zip(serial, parallel, strict=True):
        np.testing.assert_array_equal(a.raw, b.raw)
        np.testing.assert_array_equal(a.v_ref, b.v_ref)


def test_a_malformed_capture_read_in_a_worker_is_its_own_error(
    trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """A file that is no capture among several read by worker processes: the parent
    raises its ``CaptureFormatError`` naming the file and line. The error could not be
    rebuilt in the parent (its three arguments): the pool broke and ``calibrate``,
    ``evaluate``, ``crossval`` and ``report`` ended with ``internal error:
    BrokenProcessPool``, the file unnamed."""
    empty = tmp_path / "empty.cap"
    empty.write_bytes(b"")
    with pytest.raises(CaptureFormatError, match=r"empty\.cap:1: not a capture v1 file"):
        record_captures([trial_files["straight"], empty], E1, workers=2)
