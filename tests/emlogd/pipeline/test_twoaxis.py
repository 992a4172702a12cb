"""A two-axis log's corrected VBW: both axes in the hull frame, read by pynmea2."""

from __future__ import annotations

import math

import pynmea2
import pytest

from drivers.nmea0183 import encode_vbw as raw_vbw
from drivers.records import KNOT_MPS
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.twoaxis import configured, hull_frame

PORTS = [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")]


def _vbw_out(s: UutSettings, forward: float, athwart: float) -> str:
    """The corrected VBW the pipeline emits for one raw VBW (no calibration yet: the
    forward reading as it is)."""
    p = Pipeline(PORTS, [s])
    out = p.feed(1000.0, "log", (raw_vbw(forward, athwart, talker="VM") + "\r\n").encode())
    (line,) = [e.sentence for e in out.emits if "VBW" in e.sentence]
    return line


def test_corrected_vbw_turns_both_axes_back() -> None:
    """A log turned 3° to starboard reads −sin 3°·u athwart at 3 m/s ahead: its
    corrected VBW (checksum and fields read by pynmea2) says 0 athwart, 3 m/s ahead,
    valid; without the figures the athwart reading passes as it is."""
    alpha = math.radians(3.0)
    u = 3.0
    fwd, ath = u * math.cos(alpha), -u * math.sin(alpha)
    s = UutSettings(port="log", reference_port="dvl", uut_source="VBW", misalign_deg=3.0)
    msg = pynmea2.parse(_vbw_out(s, fwd, ath), check=True)
    assert msg.sentence_type == "VBW"
    assert float(msg.lon_water_spd) * KNOT_MPS == pytest.approx(u, abs=0.01)
    assert float(msg.trans_water_spd) * KNOT_MPS == pytest.approx(0.0, abs=0.01)
    assert msg.data_validity_water_spd == "A"
    plain = UutSettings(port="log", reference_port="dvl", uut_source="VBW")
    msg = pynmea2.parse(_vbw_out(plain, fwd, ath), check=True)
    assert float(msg.trans_water_spd) * KNOT_MPS == pytest.approx(ath, abs=0.01)


def test_hull_frame_scale_and_bias() -> None:
    s = UutSettings(
        port="log", reference_port="dvl", transverse_scale=-0.1, transverse_bias_mps=0.05
    )
    assert configured(s)
    assert not configured(UutSettings(port="log", reference_port="dvl"))
    u, w = hull_frame(s, 2.0, 0.05 + 0.9 * 0.3)
    assert (u, w) == pytest.approx((2.0, 0.3))
