"""The pipeline on synthetic streams: learn, freeze, output, status, persistence, memory."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from datetime import UTC, datetime

import pytest

from calib.models import Params
from drivers.framing import split_nmea
from drivers.nmea0183 import encode_vhw
from drivers.rdi_ascii import encode_pd6
from emlogd.pipeline.core import (
    Emit,
    Output,
    Pipeline,
    PortSettings,
    RefBuffer,
    Snapshot,
    UutSettings,
)

TRUE = Params("EM3", m=0.15, b_mps=0.1)
T0 = 1_750_000_000.0


def _speed(t: float) -> float:
    return 1.6 + 0.5 * math.sin(2 * math.pi * t / 90.0)


def _stream(
    seconds: float,
    *,
    lock: Callable[[float], bool] | None = None,
    start: float = 0.0,
    dvl_silent_after: float | None = None,
    speed: Callable[[float], float] = _speed,
) -> Iterator[tuple[float, str, bytes]]:
    """EMlog VHW at 1 Hz (no latency), DVL PD6 at 10 Hz, time-sorted."""
    n = int(seconds * 10)
    for k in range(n):
        t = start + k * 0.1
        v = speed(t)
        if dvl_silent_after is None or t < dvl_silent_after:
            ok = lock(t) if lock is not None else True
            lines = encode_pd6(
                timestamp=datetime.fromtimestamp(T0 + t, UTC),
                heading_deg=10.0,
                bottom_ship_mps=(0.0, v, 0.0) if ok else None,
                range_m=20.0 if ok else None,
            )
            yield T0 + t, "dvl", "".join(x + "\r\n" for x in lines).encode()
        if k % 10 == 5:
            yield T0 + t + 0.01, "log", (encode_vhw(TRUE.forward(v), talker="VW") + "\r\n").encode()


def _pipeline(**kw: object) -> Pipeline:
    settings = UutSettings(
        port="log",
        reference_port="dvl",
        lag_s=0.0,
        persist_interval_s=30.0,
        **kw,  # type: ignore[arg-type]
    )
    return Pipeline([PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")], [settings])


def _run(p: Pipeline, items: Iterator[tuple[float, str, bytes]]) -> Output:
    out = Output()
    for t, port, data in items:
        p.feed(t, port, data, out)
        p.tick(t, out)
    return out


def _sentences(out: Output, kind: str) -> list[list[str]]:
    return [
        split_nmea(e.sentence.encode()).decode().split(",")
        for e in out.emits
        if e.sentence[3:6] == kind
    ]


def test_ref_buffer_interpolates_and_never_bridges() -> None:
    rb = RefBuffer(100, max_gap_s=0.5)
    for k in range(10):
        rb.add(k * 0.1, 1.0 + k, True)
    assert rb.at(0.25) == pytest.approx(3.5)
    assert rb.at(0.3) == pytest.approx(4.0)
    assert rb.at(5.0) is None  # in the future
    rb.add(1.0, None, False)
    rb.add(1.1, 5.0, True)
    assert rb.at(0.95) is None  # next to an invalid sample
    rb.add(3.0, 6.0, True)
    assert rb.at(2.0) is None  # gap wider than max_gap_s
    small = RefBuffer(3)
    for k in range(10):
        small.add(float(k), float(k), True)
    assert small.at(1.5) is None and small.at(8.5) == pytest.approx(8.5)


def test_uncalibrated_says_so_and_emits_no_speed() -> None:
    p = _pipeline(learn=False)
    out = _run(p, _stream(30))
    assert _sentences(out, "VHW") == []
    statuses = [e.sentence for e in out.emits if e.sentence.startswith("$PEMLS")]
    assert statuses and all(s.split(",")[2] == "U" for s in statuses)


def test_learns_converges_and_corrects() -> None:
    p = _pipeline()
    out = _run(p, _stream(900))
    st = p.status()["uuts"]["log"]  # type: ignore[index]
    assert st["state"] == "learning"
    assert st["params"]["m"] == pytest.approx(0.15, abs=0.01)
    assert st["params"]["b"] == pytest.approx(0.1, abs=0.015)
    vhw = _sentences(out, "VHW")
    assert vhw, "no corrected VHW"
    kn, kmh = float(vhw[-1][5]), float(vhw[-1][7])
    assert kmh == pytest.approx(kn * 1.852, abs=0.011)
    assert st["rmse_corrected"] < 0.1 * st["rmse_raw"]
    assert [e.kind for e in out.events].count("calibrated") == 1
    assert out.persist, "a converged calibration is persisted"
    for e in out.emits:
        assert len(e.sentence) + 2 <= 82
        split_nmea(e.sentence.encode())  # valid checksum


def test_each_sentence_is_delivered_before_the_filter_learns_from_its_sample() -> None:
    """Live outputs deliver at once: the update stays off the latency path, and the
    scored corrected error is one-step-ahead (the parameters have not seen it)."""
    p = _pipeline()
    _run(p, _stream(300))  # calibrated, learning
    u = p.uuts["log"]
    at_delivery: list[int] = []

    def deliver(emits: list[Emit]) -> None:
        assert [e.sentence[3:6] for e in emits] == ["VHW"]
        at_delivery.append(u.n_learnt)
        kept.extend(emits)

    kept: list[Emit] = []
    out = Output(deliver=deliver)
    samples = []
    for t, port, data in _stream(30, start=300.0):
        before = u.n_learnt
        at_delivery.clear()
        p.feed(t, port, data, out)
        if port == "log":
            samples.append((before, list(at_delivery), u.n_learnt))
        assert [e.sentence[3:6] for e in out.emits] in ([], ["MLS"])  # status: the caller's
        out.emits.clear()
    assert len(samples) == 30 and len(kept) == 30
    for before, delivered, after in samples:
        assert delivered == [before]  # delivered once, before the update
        assert after == before + 1  # then learnt from


def test_reference_loss_freezes_and_output_continues() -> None:
    p = _pipeline()
    _run(p, _stream(600))
    frozen = p.status()["uuts"]["log"]["params"]  # type: ignore[index]
    out = _run(p, _stream(120, start=600.0, lock=lambda t: False))
    st = p.status()["uuts"]["log"]  # type: ignore[index]
    assert st["state"] == "frozen" and st["reference"] == "lost"
    assert st["params"] == frozen
    assert len(_sentences(out, "VHW")) >= 100
    assert any(e.kind == "reference" and e.detail["to"] == "lost" for e in out.events)
    # the reference comes back: learning resumes from the frozen values
    _run(p, _stream(60, start=720.0))
    assert p.status()["uuts"]["log"]["state"] == "learning"  # type: ignore[index]


def test_stale_reference_and_port_events() -> None:
    p = _pipeline()
    out = _run(p, _stream(400, dvl_silent_after=300.0))
    st = p.status()["uuts"]["log"]  # type: ignore[index]
    assert st["reference"] == "stale"
    assert p.status()["ports"]["dvl"]["stale"] is True  # type: ignore[index]
    assert any(e.kind == "stale" and e.port == "dvl" for e in out.events)


def test_no_learning_without_excitation() -> None:
    p = _pipeline()
    out = _run(p, _stream(600, speed=lambda t: 1.6))  # constant speed
    st = p.status()["uuts"]["log"]  # type: ignore[index]
    assert st["identifiable"] is False
    assert st["samples_learnt"] == 0
    assert not out.persist


def test_switches_reset_and_warm_start() -> None:
    p = _pipeline()
    _run(p, _stream(600))
    assert p.set_learning(False) == ["log"]
    _run(p, _stream(30, start=600.0))
    assert p.status()["uuts"]["log"]["state"] == "frozen"  # type: ignore[index]
    snap = p.snapshot("log")
    assert isinstance(snap, Snapshot) and snap.params.m == pytest.approx(0.15, abs=0.01)
    warm = Pipeline(
        [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")],
        [UutSettings(port="log", reference_port="dvl", lag_s=0.0, learn=False)],
        {"log": snap},
    )
    out = _run(warm, _stream(20, start=700.0))
    assert _sentences(out, "VHW"), "frozen parameters are applied at once after a restart"
    assert p.reset() == ["log"]
    assert p.status()["uuts"]["log"]["state"] == "uncalibrated"  # type: ignore[index]


def test_bad_input_is_counted_never_fatal() -> None:
    p = _pipeline()
    out = Output()
    for data in (b"\x00\xff" * 100, b"$VWVHW,x,T,,M,1,N,,K*00\r\n", b":BS,abc\r\n", b"\n" * 5000):
        p.feed(T0, "log", data, out)
        p.feed(T0, "dvl", data, out)
    p.feed(T0, "unknown-port", b"$junk\r\n", out)
    st = p.status()["ports"]  # type: ignore[index]
    assert sum(st["log"]["rejects"].values()) > 0  # type: ignore[index]
    assert sum(st["dvl"]["rejects"].values()) > 0  # type: ignore[index]


def test_persist_hysteresis() -> None:
    p = _pipeline()
    out = _run(p, _stream(3600))
    # converged parameters barely move: far fewer persists than the 30 s interval allows
    assert 1 <= len(out.persist) < 3600 / 30 / 2


def test_deterministic() -> None:
    a = _run(_pipeline(), _stream(300))
    b = _run(_pipeline(), _stream(300))
    assert [e.sentence for e in a.emits] == [e.sentence for e in b.emits]


def test_auto_lag_found_and_a_negative_lag_refused() -> None:
    ports = [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")]
    auto = Pipeline(ports, [UutSettings(port="log", reference_port="dvl", lag_window_s=200.0)])
    out = _run(auto, _stream(400))
    found = [e for e in out.events if e.kind == "lag_estimated"]
    assert found and abs(found[0].detail["lag_s"]) < 0.2  # the stream has no latency
    # the reference arrives 3 s late: the EMlog would lead it, which the pipeline refuses
    late = Pipeline(ports, [UutSettings(port="log", reference_port="dvl", lag_window_s=200.0)])
    shifted = sorted(
        ((t + 3.0, p, d) if p == "dvl" else (t, p, d) for t, p, d in _stream(400)),
        key=lambda x: x[0],
    )
    out = _run(late, iter(shifted))
    assert not [e for e in out.events if e.kind == "lag_estimated"]
    retries = [e for e in out.events if e.kind == "lag_retry"]
    assert retries and "negative lag" in str(retries[0].detail["why"])
    assert late.status()["uuts"]["log"]["lag_s"] is None  # type: ignore[index]
