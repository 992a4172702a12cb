"""The red team's findings against the live daemon, each pinned: the config and the
state file made hostile (YAML whose constructors raise, nesting past the stack, a FIFO,
a gigabyte), reloads into them, and what the parsers under them must refuse.

Rule kept (README, docs/RELIABILITY.md): nothing from outside stops the daemon, and bad
input never loses the frozen calibration."""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import signal
from pathlib import Path

import pytest

from calib.estimate import Estimate
from calib.models import Params
from drivers.errors import ConfigError
from emlogd.calfile import CalibrationFileError, dumps, loads_state
from emlogd.config import MAX_CONFIG_BYTES, load_config, parse_config
from emlogd.daemon.statefile import MAX_STATE_BYTES, StateStore
from emlogd.fileio import read_text_bounded
from emlogd.pipeline.calibration import Calibration
from tests.emlogd.daemon.harness import OUTPUTS, Daemon, make_work, wait

CONFIG = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}}
calibration:
  - {{uut: emlog1, reference: dvl, lag: 0.165}}
{OUTPUTS}"""
"""One EMlog and a DVL; no sensor needs to be there (the daemon starts without them)."""

HOSTILE_YAML = {
    "a date that does not exist": "2001-02-30",
    "a timestamp tag on a word": "!!timestamp x",
    "a hex integer without digits": "!!int 0x",
    "an integer of 5000 digits": "!!int " + "1" * 5000,
    "a float tag on a word": "!!float x",
    "a bool tag on a word": "!!bool x",
    "bad base64": "!!binary x",
    "a python tag": "!!python/object/apply:os.system ['true']",
    "nesting past the stack": "[" * 5000 + "]" * 5000,
}
"""YAML values on which PyYAML's safe loader raises something, most not a YAMLError."""


def _cal(m: float = 0.1) -> Calibration:
    return Calibration(
        estimate=Estimate(Params("EM3", m=m, b_mps=0.05), {"m": 0.001, "b": 0.002}),
        uut="emlog1",
        lag_s=0.165,
        covariance=((1e-4, 0.0, 0.0), (0.0, 1e-6, -1e-7), (0.0, -1e-7, 4e-6)),
        t=1.75e9,
        n_samples=100,
        reference={"port": "dvl", "field": "bottom"},
        nis_mean=1.01,
    )


# -- the parsers: every hostile value is their own error --------------------------------


@pytest.mark.parametrize("value", HOSTILE_YAML.values(), ids=HOSTILE_YAML.keys())
def test_a_hostile_yaml_value_in_a_config_is_a_config_error(value: str) -> None:
    """In a key the config reads, each is a ``ConfigError`` naming the line (it was a
    ValueError, AttributeError, KeyError or RecursionError out of ``parse_config``)."""
    good = CONFIG.replace("{tcp}", "10110")
    parse_config(good)
    text = good.replace("status_log_interval_s: 1", f"status_log_interval_s: {value}")
    with pytest.raises(ConfigError, match=r"^c\.yaml:\d+: (status_log_interval_s|not valid)"):
        parse_config(text, "c.yaml")


@pytest.mark.parametrize("value", HOSTILE_YAML.values(), ids=HOSTILE_YAML.keys())
def test_a_hostile_yaml_value_in_a_state_file_is_damage(value: str) -> None:
    """Anywhere in a state file, each is a ``CalibrationFileError`` (the daemon then uses
    the backup), never another exception."""
    text = dumps({"emlog1": _cal()}).replace("end: true", f"x: {value}\nend: true")
    with pytest.raises(CalibrationFileError):
        loads_state(text)


@pytest.mark.parametrize(
    ("old", "new", "why"),
    [
        ("  m: 0.1\n", "  m: " + "9" * 400 + "\n", "finite number"),
        ("    - - 0.0001\n", "    - - 0.0001\n      - 0.0\n", "square"),
        ("  m: 0.1\n", "  m: 0.1\n      1: 0.0\n", "params"),
    ],
    ids=["an integer past a float", "a ragged covariance", "a number for a parameter name"],
)
def test_a_state_record_of_the_wrong_shape_is_damage(old: str, new: str, why: str) -> None:
    """An integer no float holds (OverflowError), a covariance row longer than the others
    (numpy's ValueError in the check), a parameter named by a number (TypeError when
    sorted): each a ``CalibrationFileError`` naming what is wrong."""
    text = dumps({"emlog1": _cal()})
    assert old in text
    with pytest.raises(CalibrationFileError, match=why):
        loads_state(text.replace(old, new, 1))


def test_the_bounded_read_refuses_a_fifo_a_directory_and_a_long_file(tmp_path: Path) -> None:
    """No wait on a FIFO without a writer, no gigabyte read; a regular file within the
    bound reads whole."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big"
    with open(big, "wb") as f:
        f.truncate(1 << 30)  # sparse: a gigabyte that costs no disk
    for path, why in ((fifo, "not a regular file"), (tmp_path, "not a regular file")):
        with pytest.raises(OSError, match=why):
            read_text_bounded(path, 100)
    with pytest.raises(OSError, match="longer than 100 bytes"):
        read_text_bounded(big, 100)
    (tmp_path / "ok").write_text("x" * 100)
    assert read_text_bounded(tmp_path / "ok", 100) == "x" * 100


def test_a_config_too_long_or_a_fifo_is_refused_by_load_config(tmp_path: Path) -> None:
    """``load_config`` reads through the bound (:data:`MAX_CONFIG_BYTES`)."""
    long = tmp_path / "long.yaml"
    long.write_text(CONFIG.replace("{tcp}", "10110") + "#" * MAX_CONFIG_BYTES)
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    for path in (long, fifo):
        with pytest.raises(ConfigError, match="cannot read the config"):
            load_config(path)


# -- the live daemon ---------------------------------------------------------------------


def _log(d: Daemon) -> list[dict[str, object]]:
    """The daemon's JSON log lines."""
    return [json.loads(x) for x in d.log_path.read_text().splitlines() if x.startswith("{")]


def _failed_reloads(d: Daemon, n: int) -> bool:
    return d.events("reload_failed") >= n


def _work(tmp_path: Path) -> Path:
    return make_work(tmp_path, CONFIG)


def test_reloads_into_hostile_configs_keep_the_running_one(tmp_path: Path) -> None:
    """SIGHUP into each hostile value, a FIFO and a config past the bound: every one a
    ``reload_failed`` with the running config kept and the daemon answering (a date
    ``2001-02-30`` made it exit 1, a FIFO would have hung it); a good config after them
    reloads."""
    work = _work(tmp_path)
    cfg = work / "emlogd.yaml"
    good = cfg.read_text()
    d = Daemon(work)
    try:
        bad = [
            good.replace("status_log_interval_s: 1", f"status_log_interval_s: {v}")
            for v in HOSTILE_YAML.values()
        ]
        bad.append(good + "#" * MAX_CONFIG_BYTES)
        for n, text in enumerate([*bad, None], start=1):
            cfg.unlink()
            if text is None:
                os.mkfifo(cfg)
            else:
                cfg.write_text(text)
            d.send_signal(signal.SIGHUP)
            wait(functools.partial(_failed_reloads, d, n), f"reload_failed #{n}", 10.0)
            assert d.running and d.answers(), d.tail()
        cfg.unlink()
        cfg.write_text(good.replace("status_log_interval_s: 1", "status_log_interval_s: 2"))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 1, "the good config reloaded", 10.0)
        assert d.stop() == 0
    finally:
        d.kill()


@pytest.mark.parametrize(
    "damage",
    ["a date that does not exist", "nesting past the stack", "fifo", "a gigabyte"],
)
def test_a_hostile_state_file_starts_from_the_backup(tmp_path: Path, damage: str) -> None:
    """The state file damaged so that its parser raised (a date ``2001-02-30``: the daemon
    exited 1 at start, its good backup unused) or its read would block (a FIFO) or take
    a gigabyte: the daemon starts on the backup's calibration, then moves the bad file
    aside at its first save, the backup kept."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal(0.1)})
    store.save({"emlog1": _cal(0.2)})  # the backup: m = 0.1; the current file: m = 0.2
    backup = store.backup.read_bytes()
    store.path.unlink()
    if damage == "fifo":
        os.mkfifo(store.path)
    elif damage == "a gigabyte":
        with open(store.path, "wb") as f:
            f.truncate(1 << 30)
    else:
        text = dumps({"emlog1": _cal(0.2)})
        store.path.write_text(text.replace("end: true", f"x: {HOSTILE_YAML[damage]}\nend: true"))
    assert store.path.lstat().st_size <= 1 << 30
    d = Daemon(work)
    try:
        assert d.events("state_file") >= 1
        assert "using the backup" in d.log_path.read_text()
        loaded = [e for e in _log(d) if e.get("event") == "calibration_loaded"]
        assert [(e["uut"], e["m"]) for e in loaded] == [("emlog1", 0.1)], loaded
        assert d.ask(cmd="freeze", port="emlog1").get("ok") is True, d.tail()
        assert store.refused.exists() and store.backup.read_bytes() == backup
        assert d.stop() == 0
    finally:
        d.kill()


def test_a_fifo_planted_as_the_state_file_of_the_running_daemon(tmp_path: Path) -> None:
    """A FIFO put where the running daemon's state file is: its next save (a ``reset``)
    does not block on it (it hung the daemon for good), moves it aside and writes."""
    work = _work(tmp_path)
    store = StateStore(work / "state" / "state.yaml")
    store.save({"emlog1": _cal()})
    d = Daemon(work)
    try:
        store.path.unlink()
        os.mkfifo(store.path)
        answer = d.ask(cmd="reset", port="emlog1")  # a material change: written at once
        assert answer.get("ok") is True, answer
        assert store.path.is_file() and store.refused.exists()
        assert loads_state(store.path.read_text())[0]["emlog1"].reset
        assert d.stop() == 0
    finally:
        d.kill()


def test_the_state_bound_holds_a_full_state_file() -> None:
    """The bound is far above what a state file holds: eight UUTs with their records of
    all four models."""
    cals = {f"u{k}": dataclasses.replace(_cal(), uut=f"u{k}") for k in range(8)}
    assert len(dumps(cals).encode()) * 4 < MAX_STATE_BYTES
