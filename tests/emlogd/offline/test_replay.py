"""Replay: the daemon's pipeline over captures, state across files, pacing, JSON view."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from emlogd.config import parse_config
from emlogd.offline.replay import replay
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config

CFG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 3.3, max_param_std: {m: 0.05, b: 0.08}}
  - {uut: emlog2, reference: dvl, lag: 0.5}
"""


def _pipeline(cfg: str = CFG) -> Pipeline:
    ports, uuts = pipeline_from_config(parse_config(cfg))
    return Pipeline(ports, uuts)


def test_replay_learns_and_emits(trial_files: dict[str, Path]) -> None:
    p = _pipeline()
    sink = io.BytesIO()
    res = replay(p, [trial_files["transit"], trial_files["figure-8"]], sink=sink)
    doc = res.to_dict()
    e1 = doc["uuts"]["emlog1"]  # type: ignore[index]
    assert e1["state"] in ("learning", "frozen")
    assert e1["params"] is not None
    assert e1["rmse_corrected"] < 0.5 * e1["rmse_raw"]
    assert doc["ports"]["dvl"]["records"] > 0  # type: ignore[index]
    assert set(doc["ports"]["dvl"]["rejects"]) >= {"checksum", "framing"}  # type: ignore[index]
    lines = sink.getvalue().split(b"\r\n")
    assert any(ln.startswith(b"$VWVHW") for ln in lines)
    assert any(ln.startswith(b"$PEMLS,emlog1,") for ln in lines)
    assert res.emitted == len([ln for ln in lines if ln])
    assert res.span_s > 0 and res.records > 0


def test_state_carries_across_files(trial_files: dict[str, Path]) -> None:
    both = _pipeline()
    replay(both, [trial_files["transit"], trial_files["return"]])
    split = _pipeline()
    replay(split, [trial_files["transit"]])
    replay(split, [trial_files["return"]])
    assert both.status()["uuts"] == split.status()["uuts"]


def test_unknown_ports_are_counted(trial_files: dict[str, Path]) -> None:
    cfg = CFG.replace("  - {uut: emlog2, reference: dvl, lag: 0.5}\n", "").replace(
        "  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}\n", ""
    )
    res = replay(_pipeline(cfg), [trial_files["straight"]])
    assert res.unknown_ports.get("emlog2", 0) > 0


def test_paced_replay_sleeps_by_record_time(trial_files: dict[str, Path]) -> None:
    clock = [0.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        clock[0] += s

    res = replay(
        _pipeline(), [trial_files["straight"]], speed=100.0, sleep=sleep, monotonic=lambda: clock[0]
    )
    assert sum(slept) == pytest.approx(res.span_s / 100.0, rel=0.02)
