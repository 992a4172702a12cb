"""No silent no-ops: a command with nothing to do fails or says what did not match,
and a numeric option is checked like its config key (exit 2)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import IO

import pytest

from emlogd.cli import main

_CFG = (
    "ports:\n"
    "  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}\n"
    "  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}\n"
    "calibration:\n"
    "  - {uut: emlog1, reference: dvl}\n"
)
_VHW = b"$VWVHW,,T,,M,6.0,N,11.1,K*54"


def _readline(stream: IO[str], deadline: float) -> str:
    """One line of a subprocess's pipe, or "" when none arrives by ``deadline``."""
    import selectors
    import time

    sel = selectors.DefaultSelector()
    sel.register(stream, selectors.EVENT_READ)
    try:
        wait = deadline - time.monotonic()
        return stream.readline() if wait > 0 and sel.select(wait) else ""
    finally:
        sel.close()


def test_replay_of_a_capture_with_no_configured_port_exits_1(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, write_capture: Callable[..., Path]
) -> None:
    """A capture whose only port the config does not declare: exit 1, the capture's and
    the configured ports named, nothing emitted."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(_CFG)
    cap = write_capture({"log9": "nmea0183"}, [(0.0, "log9", _VHW, False)])
    assert main(["replay", str(cap), "--config", str(cfg)]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith("emlogd replay: error: ") and err.count("\n") == 1
    assert "log9" in err and "emlog1, dvl" in err


def test_replay_names_the_ports_not_configured_and_says_no_persists_without_state(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, write_capture: Callable[..., Path]
) -> None:
    """A capture with one configured and one unknown port replays (exit 0), warns once
    naming the unknown port (and that the UUT gave no reading), and its summary says
    nothing of persists without --state."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(_CFG)
    cap = write_capture(
        {"emlog1": "nmea0183", "log9": "nmea0183"},
        [(0.0, "emlog1", _VHW, False), (0.5, "log9", _VHW, False)],
    )
    assert main(["replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert err.count("port log9 not in") == 1
    # emlog1's one sentence has a wrong checksum: no reading of it decoded
    assert err.count("warning") == 2 and "emlog1: no speed reading of the log" in err
    assert "persists" not in out


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--lag", "-3"], "--lag"),
        (["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--lag", "100"], "--lag"),
        (["crossval", "x.cap", "y.cap", "--uut", "e", "--ref", "d", "--lag", "31"], "--lag"),
        (["report", "x.cap", "--out", "o", "--uut", "e", "--ref", "d", "--lag", "-0.1"], "--lag"),
        (["evaluate", "x.cap", "--params", "p.yaml", "--lag", "-3"], "--lag"),
        (["evaluate", "x.cap", "--params", "p.yaml", "--lag", "auto"], "--lag"),
        (["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--r-raw", "0"], "--r-raw"),
        (["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--variation", "200"], "--variation"),
        (["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--average", "-1"], "--average"),
        (["crossval", "x.cap", "y.cap", "--uut", "e", "--ref", "d", "--workers", "0"], "--workers"),
        (
            ["import", "x.csv", "--format", "csv", "--out", "o.cap", "--utc-offset", "25"],
            "--utc-offset",
        ),
        (["dump", "x.nmea", "--max-length", "5"], "--max-length"),
    ],
)
def test_a_numeric_option_out_of_its_keys_range_exits_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], named: str
) -> None:
    """An option out of the range its config key declares is a usage error before any
    file is read: exit 2, one line naming the option."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and named in err and ": error: " in err


def test_the_lag_option_takes_the_bounds_of_the_lag_key(capsys: pytest.CaptureFixture[str]) -> None:
    """--lag's message gives the key's range as the key declares it (not retyped)."""
    from emlogd.pipeline.keys import lag

    assert main(["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--lag", "-3"]) == 2
    assert f"the config key lag: {lag.text} s" in capsys.readouterr().err


def test_one_error_format_for_usage_and_runtime_errors(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A usage error found by a command (simulate --scale 0) and a runtime error read the
    same: ``emlogd CMD: error: …``; --trace without --method kf is a usage error (exit 2)."""
    assert main(["simulate", str(tmp_path / "x"), "--scale", "0"]) == 2
    assert capsys.readouterr().err.startswith("emlogd simulate: error: --scale")
    argv = ["calibrate", "x.cap", "--uut", "e", "--ref", "d", "--trace", "t.csv"]
    assert main(argv) == 2
    assert capsys.readouterr().err.startswith("emlogd calibrate: error: --trace")


def test_save_into_a_missing_directory_fails_before_the_fit_and_names_the_path(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """calibrate --save DIR/p.yaml with DIR missing: exit 1 naming that path (no internal
    temporary file), before the captures are read."""
    target = tmp_path / "missing" / "p.yaml"
    argv = ["calibrate", str(trial_files["figure-8"]), "--uut", "emlog1", "--ref", "dvl"]
    assert main([*argv, "--lag", "3.3", "--save", str(target)]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert f"--save {target}:" in err and ".tmp" not in err


def test_fake_link_to_a_port_the_capture_lacks_names_the_captures_ports(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, write_capture: Callable[..., Path]
) -> None:
    """fake --link emlog3=PATH on a capture of emlog1 and dvl: exit 2 naming both."""
    cap = write_capture({"emlog1": "nmea0183", "dvl": "pd6"}, [(0.0, "emlog1", _VHW, False)])
    assert main(["fake", str(cap), "--link", f"emlog3={tmp_path / 'l'}"]) == 2
    err = capsys.readouterr().err
    assert "no port 'emlog3'" in err and "emlog1, dvl" in err


def test_fake_says_when_the_capture_has_ended(
    tmp_path: Path, write_capture: Callable[..., Path]
) -> None:
    """emlogd fake (a subprocess) says on stderr that the capture has ended, while it
    keeps the link open."""
    import os
    import subprocess
    import sys
    import time

    cap = write_capture(
        {"emlog1": "nmea0183"}, [(k * 0.01, "emlog1", _VHW, False) for k in range(5)]
    )
    link = tmp_path / "links" / "emlog1"
    root = Path(__file__).resolve().parents[3]
    env = {**os.environ, "PYTHONPATH": str(root)}
    argv = [sys.executable, "-m", "emlogd", "fake", str(cap), "--link", str(link), "--fast"]
    fake = subprocess.Popen(argv, stderr=subprocess.PIPE, text=True, env=env)
    fd = -1
    try:
        deadline = time.monotonic() + 20
        while not link.exists():
            assert time.monotonic() < deadline and fake.poll() is None
            time.sleep(0.02)
        fd = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        assert fake.stderr is not None
        lines = [_readline(fake.stderr, deadline=time.monotonic() + 10) for _ in range(2)]
        assert "serving emlog1" in lines[0]
        assert "has ended (5 records sent)" in lines[1]
        assert fake.poll() is None  # still serving the link
    finally:
        fake.terminate()
        fake.wait(10)
        if fd >= 0:
            os.close(fd)


Arrival = tuple[float, str]
"""When a line of a subprocess's pipe arrived (``time.monotonic()``), and the line."""


@pytest.fixture(scope="module")
def piped_simulate(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[list[Arrival], list[Arrival], float]:
    """``emlogd simulate --scale 0.2`` with stdout and stderr both pipes, run once for the
    tests below: the stdout lines, the stderr lines as they arrived, and when it ended."""
    import os
    import selectors
    import subprocess
    import sys
    import time

    root = Path(__file__).resolve().parents[3]
    env = {**os.environ, "PYTHONPATH": str(root)}
    env.pop("PYTHONUNBUFFERED", None)  # the line buffering tested is the command's own
    out_dir = tmp_path_factory.mktemp("piped") / "s"
    argv = [sys.executable, "-m", "emlogd", "simulate", str(out_dir), "--scale", "0.2"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert proc.stdout is not None and proc.stderr is not None
    arrivals: dict[int, list[Arrival]] = {}
    pending: dict[int, bytes] = {}
    sel = selectors.DefaultSelector()
    for stream in (proc.stdout, proc.stderr):
        fd = stream.fileno()
        arrivals[fd], pending[fd] = [], b""
        sel.register(fd, selectors.EVENT_READ)
    deadline = time.monotonic() + 60
    while sel.get_map():
        assert time.monotonic() < deadline, "simulate did not end within 60 s"
        for key, _ in sel.select(timeout=1.0):
            fd = int(key.fd)
            chunk = os.read(fd, 65536)
            if not chunk:
                sel.unregister(fd)
                continue
            now = time.monotonic()
            *lines, pending[fd] = (pending[fd] + chunk).split(b"\n")
            arrivals[fd].extend((now, ln.decode() + "\n") for ln in lines)
    sel.close()
    assert proc.wait(60) == 0
    t_end = time.monotonic()
    return arrivals[proc.stdout.fileno()], arrivals[proc.stderr.fileno()], t_end


def test_progress_lines_arrive_while_the_work_runs_when_piped(
    piped_simulate: tuple[list[Arrival], list[Arrival], float],
) -> None:
    """simulate with stderr a pipe: timestamped progress lines (``emlogd simulate:
    [ELAPSED s] …``) arrive one by one while it runs, not all at its end."""
    import re

    _, arrivals, t_end = piped_simulate
    lines = [line for _, line in arrivals]
    assert len(lines) >= 3
    assert all(re.match(r"emlogd simulate: \[ *\d+\.\d s\] simulate: ", x) for x in lines)
    times = [t for t, _ in arrivals]
    assert times[-1] - times[0] > 0.3  # spread over the work, not one burst
    assert t_end - times[0] > 0.3  # the first arrived well before the end


def _help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main([*argv, "--help"]) == 0
    return capsys.readouterr().out


def test_help_gaps_are_closed(capsys: pytest.CaptureFixture[str]) -> None:
    """check-config has a description; --method, learn's state, replay --learn and
    simulate --scale say what they do and their default; evaluate --uut does not say
    "to calibrate"; report's --json says it is for two axes only."""
    assert "without opening a device" in _help(["check-config"], capsys)
    text = " ".join(_help(["calibrate"], capsys).split())
    assert "ls (default): least squares over every sample the daemon learns from" in text
    assert "learn from the incoming data" in _help(["learn"], capsys)
    assert "default: each calibration's learn key" in " ".join(_help(["replay"], capsys).split())
    assert "(default 1;" in _help(["simulate"], capsys)
    evaluate = " ".join(_help(["evaluate"], capsys).split())
    assert "to calibrate" not in evaluate and "default: the parameters file's" in evaluate
    assert "with --axes 2: the calibrations" in " ".join(_help(["report"], capsys).split())


def test_evaluate_prints_the_parameters_not_a_python_dict(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path], tmp_path: Path
) -> None:
    """evaluate's first line gives the parameters as ``m = +…, b = +…``, no ``{'m': …}``."""
    import re

    params = tmp_path / "p.yaml"
    fig8 = str(trial_files["figure-8"])
    pair = ["--uut", "emlog1", "--ref", "dvl", "--lag", "3.3"]
    assert main(["calibrate", fig8, *pair, "--save", str(params)]) == 0
    capsys.readouterr()
    assert main(["evaluate", fig8, "--params", str(params)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "{'" not in first and re.search(r"\(m = [+-]\d\.\d{5}, b = [+-]\d", first)


def test_dump_knows_emlogds_own_sentences(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """dump of emlogd's output shows $PEMLS and $PEMLF as emlogd's own (fields listed),
    not as unknown sentences; another proprietary sentence is still a reject."""
    import json

    from drivers.framing import with_checksum

    body = ["VWVHW,,T,,M,6.00,N,11.11,K", "PEMLS,emlog1,L,EM3,,+0.1712,+0.120,,,,1.02,V",
            "PEMLF,4.21,0.04,1,emlog2,A,", "PXYZA,1,2"]  # fmt: skip
    log = tmp_path / "out.nmea"
    log.write_text("".join(with_checksum(b) + "\r\n" for b in body))
    assert main(["dump", str(log), "--json"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    kinds = [x["record"]["type"] for x in lines[:-1]]
    assert kinds == ["Vhw", "EmlogdStatus", "EmlogdFused", "Rejected"]
    summary = lines[-1]["summary"]["out"]
    assert summary["emlogd"] == {"PEMLS": 1, "PEMLF": 1}
    assert summary["rejects"]["unknown_sentence"] == 1


def test_crossval_says_a_lag_fallback_once_on_stderr(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path]
) -> None:
    """crossval without --lag on runs the lag search cannot read: 0 s is used and stderr
    says so once, like calibrate."""
    caps = [str(trial_files["straight"]), str(trial_files["return"])]
    assert main(["crossval", *caps, "--uut", "emlog1", "--ref", "dvl", "--workers", "1"]) == 0
    out, err = capsys.readouterr()
    assert "lag 0.00 s" in out
    assert err.count("emlogd crossval: warning: lag not measured") == 1


def test_piped_simulate_writes_each_file_as_it_is_written(
    piped_simulate: tuple[list[Arrival], list[Arrival], float],
) -> None:
    """simulate with stdout a pipe: each capture's line arrives when that file is
    written (stdout line-buffered), the first well before the end."""
    arrivals, _, t_end = piped_simulate
    assert len(arrivals) == 6 and "1-transit.cap" in arrivals[0][1]
    assert arrivals[4][0] - arrivals[0][0] > 0.3  # the five files, one by one
    assert t_end - arrivals[0][0] > 0.3
