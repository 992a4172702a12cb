"""The status assembled from the pipeline's parts."""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace

import pytest

from calib.estimate import Estimate
from calib.models import Params
from drivers.nmea0183 import encode_vhw
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.status import port_status, status_fields, summary, uut_status
from emlogd.pipeline.supervisor import RESTORE_WAIT_S
from tests.synth import WaterFrameSeries

PORTS = [PortSettings("log", "nmea0183", stale_timeout_s=2.0), PortSettings("dvl", "pd6")]
CAL = Calibration("log", Estimate(Params("EM3", m=0.05, b_mps=0.1), {"m": 0.01, "b": None}), 1.5)


def _pipeline() -> Pipeline:
    return Pipeline(PORTS, [UutSettings(port="log", reference_port="dvl")], {"log": CAL})


def test_ports_show_counters_staleness_and_last_data() -> None:
    """Per port: the decoder's counters, whether it is stale, when it was last heard."""
    p = _pipeline()
    p.feed(100.0, "log", (encode_vhw(2.0) + "\r\n").encode())
    p.tick(103.0)
    ports = port_status(p.decoders, p.liveness)
    assert ports["log"]["records"] == 1 and ports["log"]["stale"] is True
    assert ports["log"]["last_rx"] == 100.0
    assert ports["dvl"]["stale"] is False and ports["dvl"]["last_rx"] is None


def test_a_uut_shows_its_calibration_and_the_status_sentence_its_known_sigmas() -> None:
    """The UUT's status holds the calibration kept, applied once it is trusted (a
    restored one with no reference: after RESTORE_WAIT_S, unverified), and the lag; the
    status sentence's σ leave out the undetermined ones; the summary is one line per UUT."""
    p = _pipeline()
    u = p.uuts["log"]
    doc = uut_status(u, p.headings)
    assert doc["params"] is None and doc["kept"] == {"m": 0.05, "b": 0.1}
    for k in range(int(RESTORE_WAIT_S) + 2):
        p.feed(100.0 + k, "log", (encode_vhw(2.0) + "\r\n").encode())
    doc = uut_status(u, p.headings)
    assert "unverified" in str(doc["reason"])
    assert doc["params"] == {"m": 0.05, "b": 0.1} and doc["lag_s"] == 1.5
    assert doc["state"] == "frozen" and doc["model"] == "EM3"
    fields = status_fields(u)
    assert fields.std == {"m": 0.01} and fields.params == {"m": 0.05, "b": 0.1}
    assert summary(p.uuts) == "log frozen EM3 m=+0.050 b=+0.100 ref stale"


def test_after_the_devices_stop_the_reference_reads_stale_and_the_inputs_say_how_old(
    kit: SimpleNamespace, segment: Callable[..., WaterFrameSeries]
) -> None:
    """While data flows the log's reference is valid and its inputs fresh; once every
    device stops (only ticks), the log's reference reads stale — not ``valid`` beside a
    stale port — and each input says how long it has been silent."""
    s = kit.make_stream(segment("figure-8", 30.0, Params("EM3")))
    p = kit.pipeline(lag_s=0.0)
    kit.run(p, s.items)
    live = p.status()["uuts"]
    assert isinstance(live, dict)
    assert live["log"]["reference"] == "valid"
    assert live["log"]["inputs"]["reference"]["stale"] is False
    t_end = s.items[-1][0]
    p.tick(t_end + 60.0)
    doc = p.status()["uuts"]
    assert isinstance(doc, dict)
    log = doc["log"]
    assert log["reference"] == "stale"
    inputs = log["inputs"]
    assert inputs["reference"]["port"] == "dvl" and inputs["reference"]["stale"] is True
    assert inputs["reference"]["age_s"] == pytest.approx(60.0, abs=0.2)
    assert inputs["reference"]["used_age_s"] >= 60.0
    assert inputs["reading"]["port"] == "log" and inputs["reading"]["stale"] is True
