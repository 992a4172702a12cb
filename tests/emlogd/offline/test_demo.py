"""The demo end to end (the README's first command runs it)."""

from __future__ import annotations

import io
from pathlib import Path

from emlogd.offline.demo import run_demo


def test_demo_runs_and_improves(tmp_path: Path) -> None:
    """The demo calibrates EMlog1 (≥ 30 % better) and never makes EMlog2 worse than raw."""
    out = io.StringIO()
    lines: list[str] = []
    uuts = run_demo(speed=25.0, out=out, workdir=tmp_path, progress=lines.append)
    text = out.getvalue()
    assert "corrected VHW" in text and "better" in text
    assert lines and "emlog1" in lines[-1]
    for name, factor in (("emlog1", 0.7), ("emlog2", 1.0)):
        u = uuts[name]
        raw, cor = u["rmse_raw"], u["rmse_corrected"]
        assert isinstance(raw, float) and isinstance(cor, float)
        assert cor < factor * raw, (name, u)
    assert (tmp_path / "state" / "state.yaml").exists()
