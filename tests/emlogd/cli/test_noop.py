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
