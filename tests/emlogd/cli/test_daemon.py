"""run, check-config and the control commands through main(argv)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from emlogd.cli import main


def test_check_config(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """check-config prints 'FILE: ok' with the example's ports and calibrations; a config with an
    unknown protocol exits 1 with one line naming FILE:LINE."""
    example = Path(__file__).resolve().parents[3] / "examples" / "emlogd.yaml"
    assert main(["check-config", str(example)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{example}: ok\n")
    assert "dvl (pd6, reference)" in out and "emlog1 EM3 vs dvl (bottom)" in out
    bad = tmp_path / "bad.yaml"
    bad.write_text("ports:\n  - {name: a, url: /dev/null, protocol: pd9, role: uut}\n")
    assert main(["check-config", str(bad)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"emlogd check-config: error: {bad}:2: ")


def test_control_commands_without_daemon(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """status against a socket nobody serves exits 1 asking whether emlogd is running."""
    assert main(["status", "--socket", str(tmp_path / "none.sock")]) == 1
    assert "is emlogd running" in capsys.readouterr().err


@pytest.mark.soak
def test_demo_with_a_relative_workdir(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """demo --workdir with a relative path runs (the daemon runs inside it) and keeps its state.
    (Soak: the default run's tests/emlogd/offline/test_demo.py::
    test_demo_runs_improves_and_matches_replay runs the same command and checks the same.)"""
    monkeypatch.chdir(tmp_path)
    rc = main(["demo", "--workdir", "demo_wd", "--speed", "50"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "better" in captured.out and "Traceback" not in captured.err, captured.err
    assert (tmp_path / "demo_wd" / "daemon.log").exists()
    assert (tmp_path / "demo_wd" / "state" / "state.yaml").exists(), captured.out


@pytest.mark.parametrize("speed", ["0", "-2", "100"])
def test_demo_rejects_a_bad_speed(capsys: pytest.CaptureFixture[str], speed: str) -> None:
    """demo --speed outside 1..50 is a usage error: exit 2, one line on stderr."""
    assert main(["demo", "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--speed" in err


@pytest.fixture
def control_socket(
    tmp_path: Path, two_port_config: Path, trial_files: dict[str, Path]
) -> Iterator[tuple[Path, list[dict[str, object]]]]:
    """A control socket answering as the daemon does, with a real pipeline's status after a
    replay of the figure-8; yields its path and the requests it received."""
    import selectors
    import threading

    from emlogd.config import load_config
    from emlogd.daemon.control import ControlServer
    from emlogd.offline.replay import replay
    from emlogd.pipeline.core import Pipeline
    from emlogd.settings import pipeline_from_config

    pipeline = Pipeline(*pipeline_from_config(load_config(two_port_config)))
    status = replay(pipeline, [trial_files["figure-8"]]).status
    seen: list[dict[str, object]] = []

    def handle(req: dict[str, object]) -> dict[str, object]:
        seen.append(req)
        if req.get("port") not in (None, "emlog1"):
            raise ValueError(f"no UUT {req['port']!r}; UUTs: emlog1")
        if req["cmd"] == "status":
            return {"status": status, "state_file": "/var/lib/emlogd/state.yaml",
                    "state_errors": 0, "persists": 3}  # fmt: skip
        if req["cmd"] == "freeze":
            return {"uuts": ["emlog1"], "learning": False, "states": {"emlog1": "frozen"}}
        if req["cmd"] == "learn":
            return {"uuts": ["emlog1"], "learning": bool(req.get("on", False))}
        if req["cmd"] == "reset":
            return {
                "uuts": ["emlog1"],
                "reset": {
                    "emlog1": {
                        "kept": {"lag_s": 3.2, "learning_enabled": True},
                        "cleared": ["EM3 calibration", "current estimate"],
                    }
                },
            }
        return {"uuts": ["emlog1"]}

    sel = selectors.DefaultSelector()
    path = tmp_path / "control.sock"
    server = ControlServer(path, handle, sel)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            for key, _ in sel.select(0.05):
                key.data()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield path, seen
    stop.set()
    thread.join(5)
    server.close()


def test_control_commands_print_text_unless_json(
    capsys: pytest.CaptureFixture[str], control_socket: tuple[Path, list[dict[str, object]]]
) -> None:
    """status, freeze, learn and reset print readable lines (not JSON) unless --json."""
    path, seen = control_socket
    sock = ["--socket", str(path)]
    assert main(["status", *sock]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].startswith("emlog1: ") and "RMSE raw" in lines[0] and "% better" in lines[0]
    assert any(line.startswith("port dvl: ") for line in lines)
    assert lines[-1] == "state file /var/lib/emlogd/state.yaml: 3 persists"
    assert "{" not in out and '"' not in out
    assert main(["status", *sock, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"]["uuts"]["emlog1"]["model"] == "EM3"
    for argv, text in (
        (["freeze"], "emlog1: frozen (learning off, the calibration applied)\n"),
        (["learn", "on", "--uut", "emlog1"], "emlog1: learning on\n"),
        (["learn", "off"], "emlog1: learning off\n"),
        (
            ["reset"],
            "emlog1: cleared EM3 calibration, current estimate; kept lag 3.200 s, learning on\n",
        ),
    ):
        assert main([*argv, *sock]) == 0
        assert capsys.readouterr().out == text
    assert seen[-3] == {"cmd": "learn", "port": "emlog1", "on": True}
    assert main(["freeze", "--uut", "emlog9", *sock]) == 1
    err = capsys.readouterr().err
    assert err == "emlogd freeze: error: the daemon refused: no UUT 'emlog9'; UUTs: emlog1\n"


def test_run_with_stdout_output_logs_to_stderr(tmp_path: Path) -> None:
    """With outputs.stdout the log goes to stderr, so stdout carries NMEA only."""
    from emlogd.launch import DaemonProcess

    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n  - {name: log, url: missing/log, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: missing/dvl, protocol: pd6, role: reference}\n"
        "calibration:\n  - {uut: log, reference: dvl}\n"
        "outputs: {pty: null, stdout: true}\n"
        "state_file: state.yaml\ncontrol_socket: control.sock\nlog_format: json\n"
    )
    with DaemonProcess(
        cfg, socket="control.sock", log="stdout.txt", err_log="stderr.txt", cwd=tmp_path
    ) as d:
        assert d.stop() == 0
    assert b'"event": "ready"' in (tmp_path / "stderr.txt").read_bytes()
    out = (tmp_path / "stdout.txt").read_bytes()
    assert not [ln for ln in out.splitlines() if not ln.startswith(b"$")]


def test_status_of_a_daemon_whose_devices_are_missing(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """The real daemon with no device behind its ports: status says why each log is
    uncalibrated and that every port is not open (and why), never a quiet healthy count;
    ``--uut`` leaves the other log and its port out of the text and the JSON; ``freeze`` of
    an uncalibrated log says there is no calibration to apply."""
    from emlogd.launch import DaemonProcess

    cfg = tmp_path / "c.yaml"
    cfg.write_text(
        "ports:\n  - {name: log, url: missing/log, protocol: nmea0183, role: uut}\n"
        "  - {name: log2, url: missing/log2, protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: missing/dvl, protocol: pd6, role: reference}\n"
        "calibration:\n  - {uut: log, reference: dvl}\n  - {uut: log2, reference: dvl, talker: VM}\n"
        "outputs: {pty: null}\n"
        "state_file: state.yaml\ncontrol_socket: control.sock\nlog_format: json\n"
    )
    sock = ["--socket", str(tmp_path / "control.sock")]
    with DaemonProcess(
        cfg, socket="control.sock", log="out.txt", err_log="err.txt", cwd=tmp_path
    ) as d:
        assert main(["status", *sock]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert main(["status", "--uut", "log", *sock]) == 0
        one = capsys.readouterr().out
        assert main(["status", "--uut", "log", "--json", *sock]) == 0
        doc = json.loads(capsys.readouterr().out)["status"]
        assert main(["freeze", "--uut", "log", *sock]) == 0
        frozen = capsys.readouterr().out
        assert d.stop() == 0
    log_line = next(line for line in lines if line.startswith("log: "))
    assert log_line.startswith("log: uncalibrated (") and "reference none" in log_line
    for port in ("log", "log2", "dvl"):
        line = next(line for line in lines if line.startswith(f"port {port}: "))
        assert line.startswith(f"port {port}: not open (cannot open "), line
        assert f"missing/{port}" in line and "No such file" in line, line
    assert "log2" not in one and "port log: not open" in one and "port dvl: not open" in one
    assert set(doc["uuts"]) == {"log"} and set(doc["ports"]) == {"log", "dvl"}
    dvl = doc["ports"]["dvl"]
    assert (dvl["open"], dvl["stale"], dvl["state"]) == (False, True, "not open")
    assert "reading" in doc["uuts"]["log"]["inputs"]
    assert frozen == "log: learning off; no calibration to apply (raw readings pass through)\n"


def test_status_text_shows_the_imo_verdict_raw_and_corrected() -> None:
    """The status line of a log carries the IMO A.824 verdict of its raw and emitted
    readings against the reference once it has scored samples (the status JSON's imo)."""
    from emlogd.cli.daemon import _status_text
    from emlogd.pipeline.counters import Score

    score = Score()
    for _ in range(20):
        score.add(0.3, 0.02, 3.0)
    raw, cor = score.imo()
    u = {
        "state": "frozen",
        "reference": "valid",
        "model": "EM3",
        "rmse_raw": 0.3,
        "rmse_corrected": 0.02,
        "scored_samples": 20,
        "imo": {"raw": raw.as_dict(), "corrected": cor.as_dict()},
    }
    text = _status_text({"status": {"uuts": {"log": u}, "ports": {}}})
    assert "IMO A.824 (within 2 % or 0.2 kn) raw 0.0 % fails, corrected 100.0 % meets" in text
    u["imo"] = {"raw": Score().imo()[0].as_dict(), "corrected": Score().imo()[1].as_dict()}
    assert "IMO" not in _status_text({"status": {"uuts": {"log": u}, "ports": {}}})


def test_status_without_a_daemon_or_config_names_the_options(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """`emlogd status` with neither --config nor --socket, and no default config: one
    error line that says how to name the daemon (--config or --socket)."""
    from emlogd.cli import main
    from emlogd.config import DEFAULT_PATH

    if Path(DEFAULT_PATH).exists():
        pytest.skip(f"{DEFAULT_PATH} exists on this machine")
    assert main(["status"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--config FILE" in err and "--socket PATH" in err


def test_status_text_shows_the_two_axis_figures_and_the_refusal() -> None:
    """``axes: 2``: a line under the UUT with the figures applied (α ± σ, m_t, b_t),
    whether the forward speed is the two-axis fit's, the leeway, and why the latest
    window refused α."""
    from emlogd.cli.daemon import _status_text

    fig = {
        "misalign_deg": 3.05,
        "misalign_std_deg": 0.12,
        "m_t": -0.081,
        "m_t_std": 0.004,
        "b_t_mps": 0.041,
        "b_t_std_mps": 0.003,
    }
    two = {"state": "applied", "applied": fig, "estimate": None, "leeway_deg": -1.25}
    two["refused"] = "misalignment not separable: speed through water nearly constant"
    u = {"state": "frozen", "reference": "valid", "model": "EM3", "two_axis": two}
    text = _status_text({"status": {"uuts": {"log": u}, "ports": {}}})
    assert (
        "  two axes: applied, misalignment +3.05 ± 0.12°, m_t -0.0810 ± 0.0040, "
        "b_t +0.041 ± 0.003 m/s, leeway -1.2°; latest window: misalignment refused: "
        "misalignment not separable: speed through water nearly constant\n"
    ) in text
    two["forward"] = "two_axis"
    text = _status_text({"status": {"uuts": {"log": u}, "ports": {}}})
    assert "b_t +0.041 ± 0.003 m/s, forward speed by the two-axis fit, leeway -1.2°" in text
