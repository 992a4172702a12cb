"""examples/README.md's walk-through, run as written: each command through main(argv),
and each `# → …` line under it found in its output, figures within tolerance."""

from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path

import pytest

from emlogd.cli import main

ROOT = Path(__file__).resolve().parents[2]
WALK = ROOT / "examples" / "README.md"
NUM = re.compile(r"[-+]?\d+(?:\.\d+)?")
REL_TOL = 0.05
"""A quoted figure holds within 5 % of itself (runs differ by floating point only)."""
ABS_TOL = 0.002
"""… or within 0.002 (figures printed as 0.00, an RMSE in m/s to three places)."""


def _steps(text: str) -> list[tuple[str, list[str]]]:
    """(command, expected lines) in the order of the walk-through's sh block."""
    block = text.split("## A walk-through", 1)[1].split("```sh\n", 1)[1].split("```", 1)[0]
    steps: list[tuple[str, list[str]]] = []
    for line in block.splitlines():
        if line.startswith("# → "):
            steps[-1][1].append(line[len("# → ") :])
        elif line.strip() and not line.startswith("#"):
            steps.append((line, []))
    return steps


def _pattern(expected: str) -> tuple[re.Pattern[str], list[float]]:
    """A regex matching ``expected`` with any spacing and any figure, and its figures."""
    parts, figures = [], []
    pos = 0
    for m in NUM.finditer(expected):
        parts.append(expected[pos : m.start()])
        figures.append(float(m.group()))
        pos = m.end()
    parts.append(expected[pos:])

    def lit(s: str) -> str:
        return r"\s+".join(re.escape(w) for w in re.split(r"\s+", s))

    rx = "(" + NUM.pattern + ")"
    return re.compile(rx.join(lit(p) for p in parts)), figures


def _argv(command: str, tmp: Path) -> tuple[list[str], int | None]:
    """The command's arguments for main() (paths under /tmp moved to ``tmp``, globs
    expanded), and the N of a trailing ``| tail -N``."""
    tail = None
    if "|" in command:
        command, pipe = command.split("|", 1)
        m = re.fullmatch(r"\s*tail -(\d+)\s*", pipe)
        assert m, f"a pipe the test cannot run: {pipe!r}"
        tail = int(m.group(1))
    words = shlex.split(command.replace("/tmp/", f"{tmp}/"))
    assert words[0] == "emlogd"
    argv: list[str] = []
    for w in words[1:]:
        argv.extend(sorted(str(p) for p in Path().glob(w)) if "*" in w else [w])
    return argv, tail


def test_the_walkthrough_runs_as_written(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every command exits 0 and prints what the walk-through quotes under it."""
    monkeypatch.chdir(ROOT)
    steps = _steps(WALK.read_text(encoding="utf-8"))
    assert len(steps) >= 8 and sum(len(e) for _, e in steps) >= 10
    for command, expected in steps:
        argv, tail = _argv(command, tmp_path)
        if argv[0] == "report" and importlib.util.find_spec("matplotlib") is None:
            continue  # the [report] extra is not installed
        assert main(argv) == 0, command
        captured = capsys.readouterr()
        out = captured.out
        if tail is not None:
            out = "\n".join(out.splitlines()[-tail:])
        for line in expected:
            rx, want = _pattern(line)
            m = rx.search(out)
            assert m, f"{command}: {line!r} not in its output:\n{out}"
            got = [float(g) for g in m.groups()]
            for g, w in zip(got, want, strict=True):
                assert abs(g - w) <= max(REL_TOL * abs(w), ABS_TOL), (command, line, got)


def test_a_figure_off_by_more_than_the_tolerance_fails() -> None:
    """The matcher compares figures, not only words (0.0279 quoted, 0.0350 printed)."""
    rx, want = _pattern("RMSE cal 0.0279 m/s")
    m = rx.search("RMSE cal     0.0350 m/s")
    assert m and want == [0.0279]
    assert abs(float(m.group(1)) - 0.0279) > max(REL_TOL * 0.0279, ABS_TOL)
    assert not rx.search("RMSE raw     0.0279 m/s")
