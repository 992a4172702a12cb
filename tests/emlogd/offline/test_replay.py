"""Replay: the daemon's pipeline over captures, state across files, pacing, JSON view."""

from __future__ import annotations

import dataclasses
import io
import itertools
import json
from pathlib import Path

import pytest

from calib.estimate import Estimate
from emlogd.cli import main
from emlogd.config import parse_config
from emlogd.offline.replay import ReplayResult, replay
from emlogd.offline.simulate import SimulationResult, TruthError, read_truth, simulate
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config
from tests.jumping import ROOT, run_twice

CFG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl, lag: 3.3, max_param_std: {m: 0.05, b: 0.08}, current: false}
  - {uut: emlog2, reference: dvl, lag: 0.5, current: false, talker: VM}
"""


def _pipeline(cfg: str = CFG) -> Pipeline:
    ports, uuts = pipeline_from_config(parse_config(cfg))
    return Pipeline(ports, uuts)


@pytest.fixture(scope="module")
def transit(trial: SimulationResult, trial_files: dict[str, Path]) -> tuple[ReplayResult, bytes]:
    """The transit then the figure-8 replayed once for the tests that read it, with the
    truth, and what it emitted."""
    sink = io.BytesIO()
    files = [trial_files["transit"], trial_files["figure-8"]]
    res = replay(_pipeline(), files, sink=sink, truth=read_truth(trial.outdir))
    return res, sink.getvalue()


def test_replay_learns_and_emits(transit: tuple[ReplayResult, bytes]) -> None:
    """Replaying transit then figure-8 learns EMlog1 (corrected RMSE under half of raw), counts DVL
    records and reject reasons, and emits VHW and $PEMLS lines, all counted in emitted."""
    res, emitted = transit
    doc = res.to_dict()
    e1 = doc["uuts"]["emlog1"]  # type: ignore[index]
    assert e1["state"] in ("learning", "frozen")
    assert e1["params"] is not None
    assert e1["rmse_corrected"] < 0.5 * e1["rmse_raw"]
    assert doc["ports"]["dvl"]["records"] > 0  # type: ignore[index]
    assert set(doc["ports"]["dvl"]["rejects"]) >= {"checksum", "framing"}  # type: ignore[index]
    lines = emitted.split(b"\r\n")
    assert any(ln.startswith(b"$VWVHW") for ln in lines)
    assert any(ln.startswith(b"$PEMLS,emlog1,") for ln in lines)
    assert res.emitted == len([ln for ln in lines if ln])
    assert res.span_s > 0 and res.records > 0


def test_state_carries_across_files(trial_files: dict[str, Path]) -> None:
    """Two files replayed in one call leave the same UUT status as the same files replayed one after
    the other into one pipeline (the figure-8 teaches EMlog1 a calibration the return carries)."""
    both = _pipeline()
    replay(both, [trial_files["figure-8"], trial_files["return"]])
    split = _pipeline()
    first = replay(split, [trial_files["figure-8"]]).to_dict()["uuts"]
    assert first["emlog1"]["params"] is not None  # type: ignore[index]
    replay(split, [trial_files["return"]])
    assert both.status()["uuts"] == split.status()["uuts"]


def test_unknown_ports_are_counted(trial_files: dict[str, Path]) -> None:
    """Records of a port the config does not declare are counted under unknown_ports."""
    cfg = CFG.replace(
        "  - {uut: emlog2, reference: dvl, lag: 0.5, current: false, talker: VM}\n", ""
    ).replace("  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}\n", "")
    res = replay(_pipeline(cfg), [trial_files["straight"]])
    assert res.unknown_ports.get("emlog2", 0) > 0


def test_paced_replay_sleeps_by_record_time(trial_files: dict[str, Path]) -> None:
    """At speed 100 the replay sleeps the capture's span divided by 100 (within 2 %)."""
    clock = [0.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        clock[0] += s

    res = replay(
        _pipeline(), [trial_files["straight"]], speed=100.0, sleep=sleep, monotonic=lambda: clock[0]
    )
    assert sum(slept) == pytest.approx(res.span_s / 100.0, rel=0.02)


def test_truth_scores_emitted_speeds(
    trial: SimulationResult, trial_files: dict[str, Path], transit: tuple[ReplayResult, bytes]
) -> None:
    """With the truth, each UUT's emitted speeds over both files are scored against the
    true speed through water (the floor the two trajectories' floors pooled by lines)."""
    res = transit[0]
    uuts = res.to_dict()["uuts"]
    trajs = trial.trajectories[:2]
    for name in ("emlog1", "emlog2"):
        t = uuts[name]["truth"]  # type: ignore[index]
        assert set(t) == {"n_samples", "rmse_raw", "rmse_corrected", "rmse_floor", "imo"}
        lines = [tr.lines[name] for tr in trajs]
        assert 0 < t["n_samples"] <= sum(lines)
        pooled = sum(n * tr.rmse_floor_mps[name] ** 2 for n, tr in zip(lines, trajs, strict=True))
        assert t["rmse_floor"] == pytest.approx((pooled / sum(lines)) ** 0.5, rel=0.1)
        assert t["rmse_corrected"] < 0.6 * t["rmse_raw"]
        w = uuts[name]["truth_worst_window"]  # type: ignore[index]
        wins = res.truth_windows[name]
        assert w["windows"] == len(wins) > 0
        assert w["ratio"] == round(max(x.ratio for x in wins), 4)
        assert w["rmse_corrected"] / w["rmse_raw"] == pytest.approx(w["ratio"], abs=1e-3)
    plain = replay(_pipeline(), [trial_files["straight"]]).to_dict()["uuts"]
    assert plain["emlog1"]["truth"] is None  # type: ignore[index]
    assert plain["emlog1"]["truth_worst_window"] is None  # type: ignore[index]


def test_truth_pairs_each_emitted_speed_with_its_reading(tmp_path: Path) -> None:
    """Frozen at the true error models, the emitted speeds score the floor: each emitted VHW
    is paired with the reading it corrects (EMlog2 also emits VBW, which is not scored)."""
    # no current: against a current-free DVL the recheck keeps the true calibrations applied
    sim = simulate(tmp_path, seed=1, scale=0.1, current=(0.0, 0.0))
    truth = read_truth(sim.outdir)
    cfg = CFG.replace("lag: 3.3,", "lag: 3.3, model: EM4,").replace(
        "lag: 0.5,", "lag: 0.5, model: EM4,"
    )
    ports, uuts = pipeline_from_config(parse_config(cfg))
    uuts = [dataclasses.replace(u, learn=False) for u in uuts]
    cals = {}
    for name in ("emlog1", "emlog2"):
        params, latency = truth.emlog(name)
        cals[name] = Calibration(
            name, Estimate(params, {"a": 0.001, "m": 0.001, "b": 0.001}), latency
        )
    pipeline = Pipeline(ports, uuts, cals)
    replay(pipeline, [sim.files[0]])  # the restored calibrations re-validate against the DVL
    res = replay(pipeline, [sim.files[1]], truth=truth)
    for name, vhw_per_line in (("emlog1", 1.0), ("emlog2", 1.0 / 3.0)):
        assert res.status["uuts"][name]["state"] == "frozen"  # type: ignore[index]
        s = res.truth[name]
        assert s.n_samples > 0.95 * sim.trajectories[1].lines[name] * vhw_per_line
        assert s.n_samples < 1.05 * sim.trajectories[1].lines[name] * vhw_per_line
        assert s.rmse_corrected == pytest.approx(s.rmse_floor, abs=0.001)
        assert s.rmse_raw > 0.2


def test_truth_refuses_an_unknown_uut(
    trial: SimulationResult, trial_files: dict[str, Path]
) -> None:
    """A UUT that is not a simulated EMlog is refused before the replay starts."""
    cfg = CFG.replace("name: emlog2,", "name: emlog3,").replace("uut: emlog2", "uut: emlog3")
    with pytest.raises(TruthError, match="no EMlog 'emlog3'"):
        replay(_pipeline(cfg), [trial_files["straight"]], truth=read_truth(trial.outdir))


def test_truth_through_the_commands(
    trial: SimulationResult,
    trial_files: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """replay --truth and evaluate --truth add the truth scores to the JSON and the tables."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(CFG)
    straight, fig8 = str(trial_files["straight"]), str(trial_files["figure-8"])
    argv = ["replay", fig8, "--config", str(cfg), "--truth", str(trial.outdir), "--json"]
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["uuts"]["emlog1"]["truth"]["n_samples"] > 0
    assert main([*argv[:-1], "--out", str(tmp_path / "o.nmea")]) == 0
    assert "truth: raw" in capsys.readouterr().out
    params = tmp_path / "p.yaml"
    cal = ["calibrate", fig8, "--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main([*cal, "--save", str(params)]) == 0
    capsys.readouterr()
    ev = ["evaluate", straight, fig8, "--params", str(params), "--json"]
    assert main(ev) == 0
    assert json.loads(capsys.readouterr().out)["captures"][0]["truth"] is None
    assert main([*ev, "--truth", str(trial.outdir)]) == 0
    rows = json.loads(capsys.readouterr().out)["captures"]
    for row, tr in zip(rows, (trial.trajectories[2], trial.trajectories[1]), strict=True):
        t = row["truth"]
        assert t["n_samples"] == pytest.approx(tr.lines["emlog1"], rel=0.02)
        assert t["rmse_floor"] == pytest.approx(tr.rmse_floor_mps["emlog1"], rel=0.05)
        assert t["rmse_corrected"] < 0.5 * t["rmse_raw"]
    assert main([*ev[:-1], "--truth", str(trial.outdir)]) == 0
    assert "truth: raw" in capsys.readouterr().out
    assert main([*ev, "--truth", str(tmp_path)]) == 1
    assert "truth.csv.gz: no such file" in capsys.readouterr().err


def test_out_capture_holds_each_uuts_sentences(
    trial_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """replay --out FILE.cap.gz writes a capture v1 with one port per UUT, each sentence at
    the receive time of the sample it corrects; it reads back through the decoders."""
    from drivers import make_decoder
    from drivers.io.capture import CaptureReader
    from drivers.nmea0183 import Vhw

    cfg = tmp_path / "c.yaml"
    cfg.write_text(CFG)
    out = tmp_path / "emitted.cap.gz"
    argv = ["replay", str(trial_files["figure-8"]), "--config", str(cfg), "--out", str(out)]
    assert main(argv) == 0
    reader = CaptureReader(out)
    assert reader.ports == {"emlog1": "nmea0183", "emlog2": "nmea0183"}
    recs = list(reader)
    assert recs and all(b.t >= a.t for a, b in itertools.pairwise(recs))
    dec = make_decoder("nmea0183", "x", errors="skip")
    vhw = [x for r in recs if r.port == "emlog1" for x in dec.feed(r.data) if isinstance(x, Vhw)]
    src = CaptureReader(trial_files["figure-8"])
    read_times = {r.t for r in src if r.port == "emlog1"}
    stamps = {r.t for r in recs if r.port == "emlog1" and r.payload[3:6] == "VHW"}
    assert len(vhw) > 100
    assert len(stamps & {round(t, 6) for t in read_times}) > 0.9 * len(stamps)


def _small_capture(path: Path, t0: float = 1_700_000_000.0) -> None:
    """60 s of an EMlog's VHW at 1 Hz and a PD6 DVL at 2 Hz, from ``t0``."""
    from datetime import UTC, datetime

    from drivers.io.capture import CaptureWriter
    from drivers.nmea0183 import encode_vhw
    from drivers.rdi_ascii import encode_pd6

    with CaptureWriter(path, {"emlog1": "nmea0183", "dvl": "pd6"}) as w:
        for k in range(120):
            t = t0 + 0.5 * k
            for line in encode_pd6(
                timestamp=datetime.fromtimestamp(t, UTC), heading_deg=10.0,
                bottom_ship_mps=(0.0, 2.0, 0.0), range_m=20.0,
            ):  # fmt: skip
                w.write_line(t, "dvl", line.encode())
            if k % 2:
                w.write_line(t + 0.01, "emlog1", encode_vhw(2.1, heading_mag_deg=10.0).encode())


def test_a_record_that_fails_in_the_pipeline_costs_that_record_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """replay and the offline commands' reading (record_capture) contain a record whose handling
    raises: it is counted as an internal reject of its port and kept in the report, every other
    record is handled, and the run ends normally."""
    from emlogd.offline.dataset import record_capture
    from emlogd.pipeline.settings import UutSettings

    cap = tmp_path / "small.cap"
    _small_capture(cap)
    real = Pipeline._route
    bad_times = {1_700_000_000.0 + 0.5 * k + 0.01 for k in (11, 31, 51)}

    def route(self: Pipeline, t: float, port: str, items: list[object], out: object) -> None:
        if t in bad_times:
            raise ValueError("math domain error")
        real(self, t, port, items, out)  # type: ignore[arg-type]

    monkeypatch.setattr(Pipeline, "_route", route)
    cfg = CFG.replace("  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}\n", "")
    cfg = cfg.replace(
        "  - {uut: emlog2, reference: dvl, lag: 0.5, current: false, talker: VM}\n", ""
    )
    res = replay(_pipeline(cfg), [cap])
    doc = res.to_dict()
    assert res.records == 120 * 6 + 60 and res.internal["count"] == 3
    first = res.internal["first"]
    assert isinstance(first, list) and first[0]["error"] == "ValueError: math domain error"
    assert first[0]["port"] == "emlog1" and first[0]["data"].startswith("$VWVHW")
    ports = doc["ports"]
    assert isinstance(ports, dict)
    assert ports["emlog1"]["rejects"]["internal"] == 3 and ports["emlog1"]["records"] == 60
    assert doc["internal"] == res.internal
    rec = record_capture(cap, UutSettings("emlog1", reference_port="dvl", lag_s=0.0))
    assert rec.internal["count"] == 3 and rec.counters["emlog1"]["rejects"]["internal"] == 3  # type: ignore[index]
    assert rec.raw.size == 60 - 3


def test_replay_output_is_a_function_of_its_inputs(
    trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """The same capture replayed (lag auto, the current learnt) in two processes, one of them
    with every clock jumping and another hash seed, emits the same capture byte for byte and
    the same summary but the time it took: nothing in the replay reads a clock, and no order
    depends on the hash seed."""
    cap = tmp_path / "emitted.cap"
    args = [
        "replay",
        str(trial_files["figure-8"]),
        "--config",
        str(ROOT / "examples" / "emlogd.yaml"),
    ]
    out = []
    for stdout in run_twice([*args, "--out", str(cap), "--json"]):
        doc = json.loads(stdout)
        doc.pop("elapsed_s")
        out.append((cap.read_bytes(), doc))
    assert out[0][1]["emitted"] > 1000
    assert out[0][1]["uuts"]["emlog2"]["lag_s"] > 0.0
    assert out[1] == out[0]


def test_calibrate_is_a_function_of_its_inputs(trial_files: dict[str, Path]) -> None:
    """calibrate --method kf on two captures (read in two processes, in whichever order they
    finish) gives the same JSON with every clock jumping and another hash seed."""
    caps = [str(trial_files["figure-8"]), str(trial_files["circles"])]
    args = ["calibrate", *caps, "--uut", "emlog2", "--ref", "dvl", "--current", "--method", "kf"]
    first, second = run_twice([*args, "--json"])
    assert json.loads(first)["lag"]["source"] == "auto"
    assert second == first


def test_out_appears_only_once_the_replay_has_run(
    trial_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """replay --out writes beside the file and renames it into place at the end: a replay
    that fails leaves the file it would have replaced as it was, and none leaves a part file;
    an --out that cannot be written is named in the error."""
    from drivers.io.capture import CaptureReader

    cfg = tmp_path / "c.yaml"
    cfg.write_text(CFG)
    out = tmp_path / "emitted.cap"
    bad = tmp_path / "bad.cap"
    bad.write_text(trial_files["straight"].read_text() + "(1.0) emlog1 $VWVHW\n")
    out.write_text("old")
    assert main(["replay", str(bad), "--config", str(cfg), "--out", str(out), "--strict"]) != 0
    assert out.read_text() == "old"
    assert (
        main(["replay", str(trial_files["straight"]), "--config", str(cfg), "--out", str(out)]) == 0
    )
    assert CaptureReader(out).ports == {"emlog1": "nmea0183", "emlog2": "nmea0183"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.cap", "c.yaml", "emitted.cap"]
    capsys.readouterr()
    nowhere = tmp_path / "missing" / "emitted.cap"
    argv = ["replay", str(trial_files["straight"]), "--config", str(cfg), "--out", str(nowhere)]
    assert main(argv) == 1
    assert f"No such file or directory: '{nowhere}'" in capsys.readouterr().err


def test_a_capture_earlier_than_the_one_before_is_ticked_and_spans_its_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two captures given latest first (an hour apart): the pipeline is ticked through the
    second one as through the first, and the span is the two captures' own (the JSON's
    ``span_s``, the ``x real time`` of the summary). The second was never ticked (its
    times all before the last tick: no staleness, no queued learning) and the span was
    negative (``-116x real time``)."""
    late, early = tmp_path / "late.cap", tmp_path / "early.cap"
    _small_capture(late)
    _small_capture(early, t0=1_700_000_000.0 - 3600.0)
    ticks: list[float] = []
    real = Pipeline.tick

    def tick(self: Pipeline, t: float) -> object:
        ticks.append(t)
        return real(self, t)

    monkeypatch.setattr(Pipeline, "tick", tick)
    cfg = CFG.replace("  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}\n", "")
    cfg = cfg.replace(
        "  - {uut: emlog2, reference: dvl, lag: 0.5, current: false, talker: VM}\n", ""
    )
    res = replay(_pipeline(cfg), [late, early])
    in_early = [t for t in ticks if t < 1_700_000_000.0 - 3000.0]
    assert len(in_early) >= 100, len(in_early)  # one per TICK_S of its 60 s
    assert res.span_s == pytest.approx(2 * 59.51, abs=0.02), res.span_s
