"""bench/reference.py: its parsers read what each bench script prints, and it turns a
failing bench into a row saying why.

The scripts' outputs are samples kept in ``tests/bench/samples/`` (one run of each script,
as ``bench/reference.py`` keeps them in ``DIR/out/``); the two cheapest scripts also run
here at a tiny size. No timing is asserted: only that every figure is read.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import pytest

from tests.scripts import load_script

SAMPLES = Path(__file__).resolve().parent / "samples"


def _script() -> ModuleType:
    return load_script("bench/reference.py")


ref = _script()


def _sample(name: str) -> str:
    return (SAMPLES / f"{name}.txt").read_text(encoding="utf-8")


PARSERS = {
    "kf": (ref.parse_kf, 3),
    "ls": (ref.parse_ls, 1),
    "crossval": (ref.parse_crossval, 1),
    "replay": (ref.parse_replay, 5),
    "replay_cpu": (ref.parse_replay_cpu, 2),
    "import": (ref.parse_import, 1),
    "daemon": (ref.parse_daemon, 4),
    "wake_costs": (ref.parse_wake_costs, 2),
    "live_profile": (ref.parse_live_profile, 1),
}
"""Each kept output's parser and the rows it gives."""


class TestParsers:
    """Each script's printed output gives its rows, every value a number read from it."""

    @pytest.mark.parametrize("name", sorted(PARSERS))
    def test_sample_gives_its_rows(self, name: str) -> None:
        parse, n_rows = PARSERS[name]
        figures = parse(_sample(name))
        assert len(figures) == n_rows
        for f in figures:
            assert any(ch.isdigit() for ch in f.value), f
            assert f.met in ("yes", "no", "—") or ";" in f.met

    @pytest.mark.parametrize("name", sorted(PARSERS))
    def test_a_missing_line_is_an_error_not_a_row(self, name: str) -> None:
        parse, _ = PARSERS[name]
        lines = _sample(name).splitlines()
        for cut in ("", "\n".join(lines[-len(lines) // 3 :])):
            with pytest.raises(ref.BenchError):
                parse(cut)

    def test_replay_figures_read_by_name(self) -> None:
        f = ref.named(ref.REPLAY_LINES, _sample("replay"))
        assert f["rt"] > 0 and f["cmd_x"] > 0
        assert f["dec"] + f["rest"] == pytest.approx(f["pipe"], abs=0.02)

    def test_crossval_command(self) -> None:
        (f,) = ref.parse_crossval_command(_sample("crossval-cmd"), _sample("crossval-cmd-current"))
        assert "CPU" in f.value and "wall" in f.value

    def test_import_judges_constant_memory_per_format(self) -> None:
        text = (
            "nmea    2.0 MB,    60000 lines:    1.5 s, peak RSS   38.0 MB\n"
            "nmea    8.0 MB,   240000 lines:    4.5 s, peak RSS   38.4 MB\n"
            "csv     2.0 MB,    30000 lines:    1.4 s, peak RSS   38.1 MB\n"
            "csv     8.0 MB,   130000 lines:    5.8 s, peak RSS   52.0 MB\n"
        )
        (f,) = ref.parse_import(text)
        assert f.met == "NMEA yes; CSV no"


class TestRows:
    """The verdicts and the table."""

    def test_met_names_the_parts_only_when_they_differ(self) -> None:
        assert ref.met(("a", True), ("b", True)) == "yes"
        assert ref.met(("a", False), ("b", False)) == "no"
        assert ref.met(("a", True), ("b", False)) == "a yes; b no"

    def test_a_failing_bench_gives_a_row_saying_why(self, tmp_path: Path) -> None:
        def fails(ctx: object) -> list[object]:
            raise ref.BenchError("exit status 1")

        bench = ref.Bench("kf", "`bench/bench_kf.py`", fails)
        ctx = ref.Context(tmp_path, tmp_path, tmp_path / "out")
        ((f, shown, sha, load),) = ref.measure(bench, ctx, "abc1234")
        assert f.value == "not measured: exit status 1"
        assert (shown, sha) == ("`bench/bench_kf.py`", "abc1234")
        assert "→" in load

    def test_table_has_one_line_per_row_and_escapes_bars(self) -> None:
        rows = [(ref.Figure("a | b", "1 s", "≤ 2 s", "yes"), "`cmd`", "abc1234", "1.0 → 1.1")]
        lines = ref.table(rows).splitlines()
        assert len(lines) == 3
        assert lines[2].count(" | ") == 6 and "a \\| b" in lines[2]


class TestTrials:
    """The benches that read a simulated trial name it, and its simulation is made once."""

    def test_each_bench_reading_a_trial_names_it_in_its_command(self) -> None:
        for b in ref.BENCHES:
            assert ("DIR/full" in b.shown) == (b.trial == 1.0), b.key
            assert ("DIR/scale-0.2" in b.shown) == (b.trial == 0.2), b.key

    def test_a_trial_present_is_reused_and_a_failed_simulation_said(
        self, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
    ) -> None:
        calls: list[list[str]] = []

        def fails(argv: list[str]) -> str:
            calls.append(argv)
            raise ref.BenchError("exit status 2")

        monkeypatch.setattr(ref, "run", fails)
        ctx = ref.Context(tmp_path / "full", tmp_path / "small", tmp_path / "out")
        ctx.full.mkdir()
        for name in ("1-a", "2-b", "3-c", "4-d", "5-e"):
            (ctx.full / f"{name}.cap").touch()
        ref.simulate(ctx, 1.0)
        assert calls == []
        ref.simulate(ctx, 0.2)
        assert calls[0][-3:] == ["--scale", "0.2", str(ctx.small)]
        assert "failed: exit status 2" in capsys.readouterr().err


class TestScriptsRun:
    """The cheapest scripts, run at a tiny size through the runner, parse."""

    def test_bench_ls(self, tmp_path: Path) -> None:
        ctx = ref.Context(tmp_path, tmp_path, tmp_path / "out")
        measure = ref._script("bench_ls.py", lambda c: ["--samples", "2000", "--repeat", "1"], ref.parse_ls)  # fmt: skip
        (f,) = measure(ctx)
        assert f.value.endswith(" ms")
        assert (tmp_path / "out" / "ls.txt").read_text().startswith("batch least squares")

    def test_bench_kf(self, tmp_path: Path) -> None:
        ctx = ref.Context(tmp_path, tmp_path, tmp_path / "out")
        measure = ref._script("bench_kf.py", lambda c: ["--samples", "200"], ref.parse_kf)
        assert len(measure(ctx)) == 3
