"""Heading sources that disagree, through the real pipeline and ``emlogd replay``.

The simulated trial (seed 1, transit and figure-8 at 10 % scale) with a compass
(``HDT``) 180° off the DVL's heading edited in, the DVL's attitude missing 10 s in
every 20 (the compass fills the gaps), against the DVL's bottom track with current
states (:mod:`emlogd.pipeline.headingsources`): with the GNSS course heard the compass
is named wrong and never read; without it nothing tells which is right and the logs
have no heading (no current learnt with either); a DVL heading frozen while the vessel
turns is named frozen and left out until it moves.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from emlogd.cli import main
from emlogd.config import parse_config
from emlogd.offline.replay import ReplayResult, replay
from emlogd.offline.simkinematics import START_EPOCH_S
from emlogd.offline.simulate import SimulationResult, simulate
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config
from tests.emlogd.daemon.test_redteam_twelve import CFG, Edit, Record, _compass, write_edited

DVL_CFG = CFG.replace("reference: REF", "reference: dvl")
"""Both logs against the DVL with current states; GNSS and compass ports beside."""

FROZEN_FOR_S = 120.0
"""How long the DVL's heading is frozen from the figure-8's start, s."""


@pytest.fixture(scope="module")
def trial(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    return simulate(tmp_path_factory.mktemp("trial"), seed=1, scale=0.1)


def _files(trial: SimulationResult) -> list[Path]:
    """The transit and the figure-8."""
    return [f for f in trial.files if f.name.startswith(("1-", "2-"))]


def _first_t(path: Path) -> float:
    """A capture's first receive time."""
    with path.open() as f:
        return next(float(line[1 : line.index(")")]) for line in f if line.startswith("("))


def _without_gnss(edit: Edit) -> Edit:
    def inner(rel: float, t: float, port: str, s: str) -> list[Record]:
        return [] if port == "gnss" else edit(rel, t, port, s)

    return inner


def _frozen_from(t0: float) -> Edit:
    """The DVL's heading held at its value of ``t0`` for :data:`FROZEN_FOR_S`."""
    held: list[str] = []

    def edit(rel: float, t: float, port: str, s: str) -> list[Record]:
        parts = s.split(",")
        sa = port == "dvl" and s.startswith(":SA,") and len(parts) == 4
        if sa and t0 <= t < t0 + FROZEN_FOR_S:
            held[:] = held or [parts[3]]
            s = ",".join([*parts[:3], held[0]])
        return [(t, port, s)]

    return edit


def _replay(files: list[Path]) -> ReplayResult:
    ports, uuts = pipeline_from_config(parse_config(DVL_CFG))
    return replay(Pipeline(ports, uuts, {}), files)


def _uut(res: ReplayResult, name: str = "emlog1") -> dict[str, object]:
    uuts = res.status["uuts"]
    assert isinstance(uuts, dict)
    u = uuts[name]
    assert isinstance(u, dict)
    return u


def test_the_course_names_the_compass_180_off_and_the_dvl_heading_is_used(
    trial: SimulationResult, tmp_path: Path
) -> None:
    res = _replay(write_edited(_files(trial), _compass(180.0, gaps=True), tmp_path))
    assert res.event_counts.get("heading_source_wrong") == 1
    wrong = [e for e in res.events if e.kind == "heading_source_wrong"]
    assert wrong[0].port == "compass" and "gnss.course agrees with dvl.PD6" in str(wrong[0].detail)
    assert wrong[0].t - START_EPOCH_S < 90.0  # half the window, the course's judged too
    # held suspect at most until the course's window is judged, then trusted for good
    # (through the figure-8's turns, where the course is not compared)
    said = [e.kind for e in res.events if e.port == "emlog1" and e.kind.startswith("heading")]
    assert said in ([], ["heading_suspect", "heading_consistent"])
    for name in ("emlog1", "emlog2"):
        u = _uut(res, name)
        heading = u["heading"]
        assert isinstance(heading, dict)
        assert heading["port"] == "dvl"
        assert list(heading["sources"]["wrong"]) == ["compass.HDT"]
        assert u["heading_suspect"] == ""


def test_without_a_third_source_the_heading_is_suspect_and_no_current_is_learnt(
    trial: SimulationResult,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No GNSS: the two sources' disagreement is said (events, status, reason) and the
    logs read no heading from then on; ``emlogd replay --json`` counts the events (the
    status read from the result of that replay)."""
    files = write_edited(_files(trial), _without_gnss(_compass(180.0, gaps=True)), tmp_path)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(DVL_CFG)
    results: list[ReplayResult] = []

    def kept(*args: Any, **kwargs: Any) -> ReplayResult:
        results.append(replay(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr("emlogd.offline.replay.replay", kept)  # what the command calls
    assert main(["replay", *map(str, files), "--config", str(cfg), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["events"]["heading_sources_disagree"] == 1
    assert doc["events"]["heading_suspect"] == 2
    (res,) = results
    u = _uut(res)
    assert "heading sources disagree: compass.HDT and dvl.PD6 180° apart" in str(u["reason"])
    assert u["heading_suspect"] == u["reason"]
    assert u["heading"]["sources"]["unresolved"] == ["compass.HDT/dvl.PD6"]  # type: ignore[index]
    counters = u["counters"]
    assert isinstance(counters, dict)
    assert counters["no_heading"] > 0.8 * int(u["samples_learnt"])  # type: ignore[call-overload]
    current = u["current"]
    assert current is None or not current["determined"]  # type: ignore[index]
    assert res.event_counts["heading_suspect"] == 2  # one per log


def test_a_dvl_heading_frozen_in_the_figure_8_is_left_out_until_it_moves(
    trial: SimulationResult, tmp_path: Path
) -> None:
    files = _files(trial)
    t0 = _first_t(files[1])
    res = _replay(write_edited(files, _frozen_from(t0), tmp_path))
    wrong = [e for e in res.events if e.kind == "heading_source_wrong"]
    assert [e.port for e in wrong] == ["dvl"]
    assert "dvl.PD6 frozen: repeats" in str(wrong[0].detail)
    assert t0 + 20.0 <= wrong[0].t < t0 + 60.0
    right = [e for e in res.events if e.kind == "heading_source_right"]
    assert len(right) == 1 and t0 + FROZEN_FOR_S <= right[0].t < t0 + FROZEN_FOR_S + 10.0
    assert not res.event_counts.get("heading_suspect")
    counters = _uut(res)["counters"]
    assert isinstance(counters, dict)
    assert counters["no_heading"] > 50  # its readings while the DVL's was left out
