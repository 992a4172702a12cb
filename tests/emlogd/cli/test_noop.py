"""No silent no-ops: a command with nothing to do fails or says what did not match,
and a numeric option is checked like its config key (exit 2)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

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
    naming the unknown port, and its summary says nothing of persists without --state."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text(_CFG)
    cap = write_capture(
        {"emlog1": "nmea0183", "log9": "nmea0183"},
        [(0.0, "emlog1", _VHW, False), (0.5, "log9", _VHW, False)],
    )
    assert main(["replay", str(cap), "--config", str(cfg), "--out", str(tmp_path / "o")]) == 0
    out, err = capsys.readouterr()
    assert err.count("warning") == 1 and "port log9 not in" in err
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
