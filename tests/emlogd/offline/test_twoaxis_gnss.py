"""A GNSS receiver and a heading as the two-axis reference."""

from __future__ import annotations

import math
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from drivers.framing import with_checksum
from drivers.io.capture import CaptureWriter
from drivers.nmea0183.encoders import encode_rmc, encode_vbw
from emlogd.offline.jobs import OfflineError
from emlogd.offline.twoaxis import record_two_axis
from emlogd.offline.twoaxis_gnss import record_two_axis_gnss

T0 = 1749715200.0


def _capture(path: Path, compass: str) -> Path:
    """60 s: the log's VBW at 10 Hz, a fix a second heading 090 over ground at 2 m/s
    (course 090), and the compass's ``compass`` sentence (HDT/HDG body) at 5 Hz."""
    lines = [(T0 + 0.1 * i, "log", encode_vbw(1.9, 0.1)) for i in range(600)]
    lines += [(T0 + 0.2 * i + 0.01, "hdg", with_checksum(compass)) for i in range(300)]
    lines += [
        (T0 + i + 0.5, "gps", encode_rmc(datetime.fromtimestamp(T0 + i, UTC), 2.0, 90.0))
        for i in range(60)
    ]
    with CaptureWriter(path, {"log": "nmea0183", "gps": "nmea0183", "hdg": "nmea0183"}) as w:
        for t, port, line in sorted(lines):
            w.write_line(t, port, line.encode())
    return path


def test_true_heading_turns_the_ground_velocity_into_the_hull_frame(tmp_path: Path) -> None:
    """Course 090 at 2 m/s on a heading of 060: 2·cos 30° forward, 2·sin 30° to
    starboard (the hull points left of the track)."""
    rec = record_two_axis_gnss(_capture(tmp_path / "a.cap", "HCHDT,60.0,T"), "log", "gps")
    cos30, sin30 = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    assert rec.ref_fwd == pytest.approx(np.full(60, 2.0 * cos30), abs=0.003)  # SOG in
    assert rec.ref_stb == pytest.approx(np.full(60, 2.0 * sin30), abs=0.003)  # 0.1 kn
    assert rec.heading == pytest.approx(np.full(60, 60.0))
    assert rec.raw_t.size == 600 and rec.raw_t[0] == pytest.approx(0.1, abs=0.003)


def test_magnetic_heading_needs_a_variation(tmp_path: Path) -> None:
    """HDG without its variation: refused with the reason unless one is given; with
    its own variation it is turned by it."""
    cap = _capture(tmp_path / "m.cap", "HCHDG,58.0,,,,")
    with pytest.raises(OfflineError, match=r"only magnetic headings .* pass --variation"):
        record_two_axis_gnss(cap, "log", "gps")
    rec = record_two_axis_gnss(cap, "log", "gps", variation_deg=2.0)
    assert rec.heading == pytest.approx(np.full(60, 60.0))
    own = _capture(tmp_path / "v.cap", "HCHDG,58.0,,,2.0,E")
    assert record_two_axis_gnss(own, "log", "gps").heading == pytest.approx(np.full(60, 60.0))


def test_no_heading_is_refused(tmp_path: Path) -> None:
    cap = _capture(tmp_path / "n.cap", "HCHDT,,T")
    with pytest.raises(OfflineError, match=r"needs the heading .* no heading sent"):
        record_two_axis_gnss(cap, "log", "gps")
    with pytest.raises(OfflineError, match="no port compass"):
        record_two_axis_gnss(cap, "log", "gps", heading="compass")


def test_simulated_receiver_agrees_with_the_dvl(trial_files: dict[str, Path]) -> None:
    """On the simulated figure-8 (the DVL's heading): the receiver's velocity in the
    hull frame is the DVL's within the GNSS noise when the heading is taken at the
    velocity's age; taken at the fix's receipt, the turns put the starboard axis off."""
    path = trial_files["figure-8"]
    dvl = record_two_axis(path, "emlog2", "dvl")
    ok = np.isfinite(dvl.ref_fwd)
    rms: dict[float, tuple[float, float]] = {}
    for age in (0.77, 0.0):
        g = record_two_axis_gnss(path, "emlog2", "gnss", heading="dvl", age_s=age)
        ok_g = np.isfinite(g.heading)
        at = g.t_ref[ok_g] - 0.77
        fwd = np.interp(at, dvl.t_ref[ok], dvl.ref_fwd[ok])
        stb = np.interp(at, dvl.t_ref[ok], dvl.ref_stb[ok])
        rms[age] = (
            float(np.sqrt(np.mean((g.ref_fwd[ok_g] - fwd) ** 2))),
            float(np.sqrt(np.mean((g.ref_stb[ok_g] - stb) ** 2))),
        )
    assert max(rms[0.77]) < 0.07
    assert rms[0.0][1] > 0.1
