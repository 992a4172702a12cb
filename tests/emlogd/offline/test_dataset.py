"""Speed series from captures, interpolation across gaps, alignment."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.io.capture import CaptureWriter
from emlogd.offline.dataset import align, interpolate_valid, load_capture


def test_series_per_port_and_source(trial_files: dict[str, Path]) -> None:
    d = load_capture(trial_files["figure-8"])
    assert set(d.sources("emlog2")) >= {"VHW", "VBW"}
    assert d.sources("emlog1") == ["VHW"]
    assert "PD6:BS" in d.sources("dvl")
    vhw = d.uut_series("emlog1")
    assert vhw.source == "VHW" and vhw.kind == "stw"
    assert np.all(np.diff(vhw.t) >= 0)
    bs = d.reference_series("dvl", "bottom")
    assert bs.kind == "sog" and np.isfinite(bs.heading[bs.valid]).all()
    assert d.counters["dvl"]["records"] > 0
    with pytest.raises(KeyError, match="no port"):
        d.uut_series("nope")
    with pytest.raises(KeyError, match="no PD6:WS"):
        d.reference_series("dvl", "water")


def test_only_the_requested_ports_are_decoded(trial_files: dict[str, Path]) -> None:
    d = load_capture(trial_files["straight"], ["emlog1"])
    assert set(d.counters) == {"emlog1"}
    with pytest.raises(KeyError, match="no port"):
        load_capture(trial_files["straight"], ["emlog9"])


def test_interpolation_never_bridges_an_outage() -> None:
    t_ref = np.array([0.0, 0.1, 0.2, 5.0, 5.1])
    v_ref = np.array([1.0, 1.1, 1.2, 2.0, 2.1])
    q = np.array([0.05, 0.15, 2.5, 5.05, 6.0, 0.2])
    out = interpolate_valid(t_ref, v_ref, q, max_gap_s=0.5)
    assert out[0] == pytest.approx(1.05) and out[1] == pytest.approx(1.15)
    assert np.isnan(out[2]) and np.isnan(out[4])
    assert out[3] == pytest.approx(2.05)
    assert out[5] == pytest.approx(1.2)


def test_align_applies_the_lag(tmp_path: Path) -> None:
    path = tmp_path / "a.cap"
    with CaptureWriter(path, {"log": "nmea0183", "ref": "nmea0183"}) as w:
        for k in range(100):
            t = 1000.0 + k * 0.5
            # the reference speed is t-dependent; the log reports it 2 s late
            ref_kn = (1.0 + 0.01 * k) / 0.514444
            w.write_line(t, "ref", _vhw(ref_kn).encode())
            if k >= 4:
                w.write_line(t + 0.001, "log", _vhw((1.0 + 0.01 * (k - 4)) / 0.514444).encode())
    d = load_capture(path)
    pair = align(d.uut_series("log"), d.uut_series("ref"), 2.0, component="longitudinal")
    assert len(pair) > 80
    assert np.allclose(pair.raw, pair.ref, atol=0.01)
    skewed = align(d.uut_series("log"), d.uut_series("ref"), 0.0, component="longitudinal")
    assert not np.allclose(skewed.raw, skewed.ref, atol=0.01)


def _vhw(kn: float) -> str:
    from drivers.nmea0183 import encode_vhw

    return encode_vhw(kn * 0.514444, talker="VW", decimals=3)
