"""The demo end to end (the README's first command runs it), through ``emlogd demo``."""

from __future__ import annotations

import io
import threading
from pathlib import Path
from typing import Any

import pytest

from emlogd.cli import main
from emlogd.offline import demo
from emlogd.offline.demo import DemoError, run_demo

FAST, SLOW = 50.0, 10.0
"""The demo's speeds in the test: 50x, and 10x once the daemon fell behind at 50x."""


def _fell_behind(uuts: dict[str, dict[str, object]]) -> bool:
    """Whether the daemon read EMlog1's readings (1 Hz, 50 a second at 50x) two or more
    at a time: it fell behind the served capture (a loaded machine) and, learning from
    the newest of each read only, from fewer readings than the replay."""
    counters = uuts["emlog1"]["counters"]
    assert isinstance(counters, dict)
    return bool(counters["backlog"])


def test_demo_runs_improves_and_matches_replay(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``emlogd demo --workdir DIR`` with a relative DIR (the daemon runs inside it and
    keeps its log and state there) exits 0; the demo calibrates EMlog1 (≥ 30 % better),
    never makes EMlog2 worse than raw, and reports for both an improvement within 5
    points of emlogd replay's on the same capture. At 50x; again at 10x when the daemon
    fell behind the capture at 50x (it then learns from fewer readings than the replay,
    which the demo's text names as the condition of the match)."""
    monkeypatch.chdir(tmp_path)
    lines: list[str] = []
    ran: list[dict[str, dict[str, object]]] = []

    def run_and_keep(**kwargs: Any) -> dict[str, dict[str, object]]:
        ran.append(run_demo(**kwargs, progress=lines.append))
        return ran[-1]

    monkeypatch.setattr(demo, "run_demo", run_and_keep)  # what the command calls
    for speed in (FAST, SLOW):
        wd = f"demo_wd_{speed:g}"
        rc = main(["demo", "--workdir", wd, "--speed", f"{speed:g}"])
        captured = capsys.readouterr()
        assert rc == 0 and "Traceback" not in captured.err, captured.err
        if not _fell_behind(ran[-1]):
            break
    text = captured.out
    assert "corrected VHW" in text and "better" in text and "What this shows" in text
    assert lines and "emlog1" in lines[-1]
    uuts = ran[-1]
    for name, factor in (("emlog1", 0.7), ("emlog2", 1.0)):
        u = uuts[name]
        raw, cor = u["rmse_raw"], u["rmse_corrected"]
        assert isinstance(raw, float) and isinstance(cor, float)
        assert cor < factor * raw, (name, u)
        live, replayed = u["improvement_pct"], u["replay_improvement_pct"]
        assert isinstance(live, float) and isinstance(replayed, float)
        assert abs(live - replayed) <= 5.0, (name, speed, live, replayed)
        assert f"({live:.0f} % better; replay {replayed:.0f} %)" in text
    assert (tmp_path / wd / "daemon.log").exists()
    assert (tmp_path / wd / "state" / "state.yaml").exists()


def test_a_daemon_that_cannot_start_is_a_demo_error(tmp_path: Path) -> None:
    """When the daemon exits at once (here its interpreter is /bin/false), the demo raises
    DemoError naming the exit code and leaves no fake device behind."""
    with pytest.raises(DemoError, match="exited with 1"):
        run_demo(speed=25.0, out=io.StringIO(), workdir=tmp_path, python="/bin/false")
    assert not any(t.name.startswith("fake-") for t in threading.enumerate())
    assert not (tmp_path / "links" / "dvl").exists()
