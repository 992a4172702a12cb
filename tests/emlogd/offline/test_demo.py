"""The demo end to end (the README's first command runs it)."""

from __future__ import annotations

import io
from pathlib import Path

from emlogd.offline.demo import run_demo


def test_demo_runs_and_improves(tmp_path: Path) -> None:
    out = io.StringIO()
    lines: list[str] = []
    uuts = run_demo(speed=25.0, out=out, workdir=tmp_path, progress=lines.append)
    text = out.getvalue()
    assert "corrected VHW" in text and "better" in text
    assert lines and "emlog1" in lines[-1]
    for name in ("emlog1", "emlog2"):
        u = uuts[name]
        raw, cor = u["rmse_raw"], u["rmse_corrected"]
        assert isinstance(raw, float) and isinstance(cor, float)
        assert cor < 0.7 * raw, (name, u)
    assert (tmp_path / "state" / "state.yaml").exists()
