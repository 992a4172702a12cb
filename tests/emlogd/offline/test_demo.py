"""The demo end to end (the README's first command runs it)."""

from __future__ import annotations

import io
import threading
from pathlib import Path

import pytest

from emlogd.offline.demo import DemoError, run_demo


def test_demo_runs_improves_and_matches_replay(tmp_path: Path) -> None:
    """The demo calibrates EMlog1 (≥ 30 % better), never makes EMlog2 worse than raw, and
    reports for both an improvement within 5 points of emlogd replay's on the same capture."""
    out = io.StringIO()
    lines: list[str] = []
    uuts = run_demo(speed=25.0, out=out, workdir=tmp_path, progress=lines.append)
    text = out.getvalue()
    assert "corrected VHW" in text and "better" in text and "What this shows" in text
    assert lines and "emlog1" in lines[-1]
    for name, factor in (("emlog1", 0.7), ("emlog2", 1.0)):
        u = uuts[name]
        raw, cor = u["rmse_raw"], u["rmse_corrected"]
        assert isinstance(raw, float) and isinstance(cor, float)
        assert cor < factor * raw, (name, u)
        live, replayed = u["improvement_pct"], u["replay_improvement_pct"]
        assert isinstance(live, float) and isinstance(replayed, float)
        assert abs(live - replayed) <= 5.0, (name, live, replayed)
        assert f"({live:.0f} % better; replay {replayed:.0f} %)" in text
    assert (tmp_path / "state" / "state.yaml").exists()


def test_a_daemon_that_cannot_start_is_a_demo_error(tmp_path: Path) -> None:
    """When the daemon exits at once (here its interpreter is /bin/false), the demo raises
    DemoError naming the exit code and leaves no fake device behind."""
    with pytest.raises(DemoError, match="exited with 1"):
        run_demo(speed=25.0, out=io.StringIO(), workdir=tmp_path, python="/bin/false")
    assert not any(t.name.startswith("fake-") for t in threading.enumerate())
    assert not (tmp_path / "links" / "dvl").exists()
