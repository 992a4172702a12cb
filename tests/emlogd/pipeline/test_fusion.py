"""The fused speed: inverse-variance weighting, failover, and what reaches the outputs."""

from __future__ import annotations

import math

import pytest

from calib.models import Params
from drivers.framing import split_nmea
from drivers.nmea0183 import encode_vhw
from drivers.records import KNOT_MPS
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import FUSED_PORT, Emit, Output, Pipeline, PortSettings, UutSettings
from emlogd.pipeline.fusion import Fused, Fusion, FusionSettings
from emlogd.pipeline.sentences import encode_fused_status
from emlogd.pipeline.supervisor import RESTORE_WAIT_S


class TestFusion:
    """The weighted mean of the latest speeds."""

    def test_inverse_variance_weights(self) -> None:
        """Two logs, σ 0.1 and 0.2: the mean leans 4:1 to the first; σ is 1/√(Σ 1/σ²)."""
        f = Fusion(FusionSettings(min_interval_s=0.0))
        f.update("a", 0.0, 2.0, 0.1)
        fused = f.update("b", 0.1, 3.0, 0.2)
        assert fused is not None
        assert fused.speed_mps == pytest.approx((4 * 2.0 + 1 * 3.0) / 5)
        assert fused.std_mps == pytest.approx(1 / math.sqrt(100 + 25))
        assert fused.sources == ("a", "b")

    def test_a_silent_log_drops_out(self) -> None:
        """A log not heard for max_age_s no longer counts: the other carries on alone."""
        f = Fusion(FusionSettings(max_age_s=2.0, min_interval_s=0.0))
        f.update("a", 0.0, 2.0, 0.1)
        f.update("b", 0.0, 3.0, 0.1)
        fused = f.update("b", 2.5, 3.0, 0.1)
        assert fused is not None and fused.sources == ("b",) and fused.speed_mps == 3.0

    def test_rate_limit_and_bad_values(self) -> None:
        """At most one fused speed per min_interval_s; a non-finite speed is not kept."""
        f = Fusion(FusionSettings(min_interval_s=1.0))
        assert f.update("a", 0.0, 2.0, 0.1) is not None
        assert f.update("a", 0.5, 2.0, 0.1) is None
        f.update("b", 1.0, math.nan, 0.1)
        assert "b" not in f.latest


class TestStatusSentence:
    """$PEMLF: speed, σ, the number of sources and their names, within 82 characters."""

    def test_fields_and_length(self) -> None:
        """Knots with two decimals; names cut to fit; the count stays the true count."""
        fused = Fused(2.0 * KNOT_MPS, 0.05 * KNOT_MPS, tuple(f"emlog{i:02d}xx" for i in range(9)))
        s = encode_fused_status(fused, "EML")
        assert len(s) + 2 <= 82
        fields = split_nmea(s.encode()).decode().split(",")
        assert fields[:4] == ["PEMLF", "2.00", "0.05", "9"]
        assert fields[4].split(";")[0] == "emlog00xx"


def _pipeline(speed_only: bool = True, calibrated: str | None = None) -> Pipeline:
    cals = {}
    if calibrated is not None:
        cals[calibrated] = Calibration(calibrated, Params("EM3", m=0.0, b_mps=0.0), {}, None)
    return Pipeline(
        [PortSettings("a", "nmea0183"), PortSettings("b", "nmea0183"), PortSettings("dvl", "pd6")],
        [
            UutSettings(port="a", reference_port="dvl", lag_s=0.0),
            UutSettings(port="b", reference_port="dvl", lag_s=0.0),
        ],
        cals,
        fusion=FusionSettings(only=speed_only, min_interval_s=0.0),
    )


def _speeds(emits: list[Emit], port: str) -> list[float]:
    out = []
    for e in emits:
        if e.port == port and e.sentence[3:6] == "VHW":
            out.append(float(split_nmea(e.sentence.encode()).decode().split(",")[5]) * KNOT_MPS)
    return out


class TestPipeline:
    """What the autopilot receives with ``outputs.speed: fused``."""

    def test_one_stream_with_failover(self) -> None:
        """Only fused VHW (and status) go out; when log b falls silent, a carries on."""
        p = _pipeline()
        out = Output()
        t0 = 1_750_000_000.0
        for k in range(10):
            p.feed(t0 + k, "a", (encode_vhw(2.0) + "\r\n").encode(), out)
            if k < 5:
                p.feed(t0 + k + 0.5, "b", (encode_vhw(3.0) + "\r\n").encode(), out)
        assert not [e for e in out.emits if e.port in ("a", "b") and e.sentence[3:6] == "VHW"]
        fused = _speeds(out.emits, FUSED_PORT)
        # both uncalibrated: σ² = r_raw + (0.1·v)² + 0.1², the slower log weighs more
        wa, wb = 1 / (0.0514**2 + 0.04 + 0.01), 1 / (0.0514**2 + 0.09 + 0.01)
        assert fused[1] == pytest.approx((2.0 * wa + 3.0 * wb) / (wa + wb), abs=0.01)
        assert fused[-1] == pytest.approx(2.0, abs=0.01)  # b silent for > 2 s
        assert any(e.sentence.startswith("$PEMLF") for e in out.emits)
        assert p.status()["fused"]["sources"] == ("a",)  # type: ignore[index]

    def test_a_calibrated_log_outweighs_an_uncalibrated_one(self) -> None:
        """Log a has a calibration (σ from its noise), b none (10 % + 0.1 m/s). (Restored
        without a reference, it is applied unverified RESTORE_WAIT_S after the first reading.)"""
        p = _pipeline(calibrated="a")
        out = Output()
        t0 = 1_750_000_000.0
        for k in range(3 * int(RESTORE_WAIT_S)):
            p.feed(t0 + k, "a", (encode_vhw(2.0) + "\r\n").encode(), out)
        t0 += 3 * RESTORE_WAIT_S
        p.feed(t0, "a", (encode_vhw(2.0) + "\r\n").encode(), out)
        p.feed(t0 + 0.1, "b", (encode_vhw(3.0) + "\r\n").encode(), out)
        assert _speeds(out.emits, FUSED_PORT)[-1] == pytest.approx(2.0, abs=0.1)

    def test_both_keeps_each_logs_sentences(self) -> None:
        """``speed: both`` sends the logs' corrected sentences and the fused one."""
        p = _pipeline(speed_only=False)
        out = Output()
        p.feed(1_750_000_000.0, "a", (encode_vhw(2.0) + "\r\n").encode(), out)
        assert _speeds(out.emits, "a") and _speeds(out.emits, FUSED_PORT)

    def test_a_uut_called_fused_is_refused(self) -> None:
        """The fused output's port name cannot be a UUT's."""
        with pytest.raises(ValueError, match="fused"):
            Pipeline(
                [PortSettings("fused", "nmea0183"), PortSettings("dvl", "pd6")],
                [UutSettings(port="fused", reference_port="dvl")],
                fusion=FusionSettings(),
            )
