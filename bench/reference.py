"""The reference table of docs/BENCHMARKS.md: every figure rerun on this tree.

Runs the bench scripts one after the other as subprocesses (``PYTHONPATH`` at this
tree, from its root), reads the figures they print and prints the table as Markdown:
figure, value, target, met, command, commit (``git rev-parse --short HEAD``, with
``-dirty`` when tracked files differ from it) and the 1-minute load average before and
after the command, under a line giving the date, the machine and the load once. The
simulated trial (seed 1) is made once in the folder given: ``DIR/full`` at full scale,
``DIR/scale-0.2`` for the CPU-time replay; a folder that already holds the five
captures is reused. A bench that fails or prints something unreadable gives a row
saying why, and the others still run. Progress goes to stderr.

Run: ``PYTHONPATH=. python bench/reference.py DIR [--quick] [--skip KEY ...]
[--only KEY ...]`` (keys: see ``--help``).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

KF_STEP_US = 5.0
"""Target: one KF-EM3 step (predict, reference and raw update), µs."""
KF_CURRENT_STEP_US = 20.0
"""Target: a 5- or 6-state step with the current, µs ("well under": 16 a second)."""
LS_MS = 10.0
"""Target: LS-EM3 over 130 000 samples, ms."""
CROSSVAL_S = 10.0
"""Target: cross-validation of the 1 Hz trial, and the ``emlogd crossval`` command on
the full simulated trial (wall, the whole command), s."""
REAL_TIME_X = 1000.0
"""Target: replay speed, times real time (the pipeline, and the ``replay`` command)."""
ANCHOR_X = 1.3
"""Target: the pipeline's time over the parsing anchor's."""
IMPORT_RSS_SLACK_MB = 3.0
"""Constant memory: the import's peak RSS at the larger size at most this much above
the smaller size's (the 6 MB more of text, held, would exceed it)."""
IMPORT_MB = (2.0, 8.0)
"""The two log sizes imported, MB."""
READY_S = 1.5
"""Target: start → ``READY=1``, s."""
LATENCY_MEDIAN_MS, LATENCY_P99_MS, FORWARDER_X = 1.0, 5.0, 2.0
"""Targets: VHW in → corrected VHW out, median and p99, ms, and both over a bare
single-threaded forwarder's."""
LIVE_CPU_PCT = 1.0
"""Target: the daemon's CPU at live rates, % of one core."""
RSS_MIB = 80.0
"""Target: the daemon's resident memory at live rates, MiB."""
CROSSVAL_ARGS = ("--uut", "emlog1", "--ref", "dvl", "--lag", "3.3")
"""The ``emlogd crossval`` row's arguments after the captures."""

NUM = r"([-+]?\d+(?:\.\d+)?)"
"""A printed number."""


class BenchError(ValueError):
    """A bench's output lacks a figure the table reads."""


@dataclass(frozen=True)
class Figure:
    """One row's figure, value, target and whether it is met (yes, no, —, or per part)."""

    figure: str
    value: str
    target: str = "—"
    met: str = "—"


@dataclass(frozen=True)
class Context:
    """What the benches run against: the two trials, and the folder of their outputs."""

    full: Path
    small: Path
    out: Path


Row = tuple[Figure, str, str, str]
"""A table row: the figure, its command as shown, the commit, the load before → after."""


def grab(pattern: str, text: str, n: int = 1) -> list[float]:
    """The ``n`` numbers of the first match of ``pattern`` (its groups) in ``text``."""
    m = re.search(pattern, text, re.MULTILINE)
    if m is None or len(m.groups()) < n:
        raise BenchError(f"no line matching {pattern!r}")
    return [float(g) for g in m.groups()[:n]]


def met(*checks: tuple[str, bool]) -> str:
    """ "yes" or "no" when every check agrees, else each check's name and verdict."""
    verdicts = {ok for _, ok in checks}
    if len(verdicts) == 1:
        return "yes" if verdicts.pop() else "no"
    return "; ".join(f"{name} {'yes' if ok else 'no'}" for name, ok in checks)


def yes(ok: bool) -> str:
    """One check's verdict."""
    return "yes" if ok else "no"


def thousands(x: float) -> str:
    """An integer with a space between thousands (as the docs write them)."""
    return f"{x:,.0f}".replace(",", " ")


# the parsers: one per bench script, each reading the figures it prints


def parse_kf(text: str) -> list[Figure]:
    """``bench_kf.py``: the KF-EM3 step, the steps with the current, the numpy filter."""
    (em3,) = grab(r"KF-EM3 \(plain floats\)\s*:\s*" + NUM, text)
    (em3c,) = grab(r"KF-EM3 \+ current \(5 states\):\s*" + NUM, text)
    (em4c,) = grab(r"KF-EM4 \+ current \(6 states\):\s*" + NUM, text)
    numpy, slower = grab(r"numpy reference \(Joseph\)\s*:\s*" + NUM + r" µs/step\s*\(\s*" + NUM, text, 2)  # fmt: skip
    return [
        Figure("KF-EM3 step (predict + reference + raw update), wall, best of 5",
               f"{em3:.2f} µs", f"≤ {KF_STEP_US:g} µs", yes(em3 <= KF_STEP_US)),
        Figure("KF-EM3 + current (5 states) / KF-EM4 + current (6 states)",
               f"{em3c:.2f} / {em4c:.2f} µs", f"well under {KF_CURRENT_STEP_US:g} µs",
               yes(max(em3c, em4c) < KF_CURRENT_STEP_US)),
        Figure("the same step in numpy (the reference filter, Joseph form), against KF-EM3",
               f"{numpy:.2f} µs, {slower:.1f}× slower"),
    ]  # fmt: skip


def parse_ls(text: str) -> list[Figure]:
    """``bench_ls.py``: LS-EM3 unweighted."""
    (samples, repeat) = grab(r"least squares on (\d+) samples \(best of (\d+)\)", text, 2)
    (ms,) = grab(r"LS-EM3\s+:\s*" + NUM + " ms", text)
    return [
        Figure(f"LS-EM3 over {thousands(samples)} samples (Gauss–Newton, identifiability of "
               f"every unknown), wall, best of {repeat:.0f}",
               f"{ms:.2f} ms", f"≤ {LS_MS:g} ms", yes(ms <= LS_MS)),
    ]  # fmt: skip


def parse_crossval(text: str) -> list[Figure]:
    """``bench_crossval.py``: the evaluations at 1 Hz and 10 Hz."""
    n1, t1 = grab(r"^\s*1 Hz UUT, \d+ samples: " + NUM + " evaluations in\\s*" + NUM, text, 2)
    _, t10 = grab(r"^\s*10 Hz UUT, \d+ samples: " + NUM + " evaluations in\\s*" + NUM, text, 2)
    return [
        Figure(f"cross-validation, {n1:.0f} evaluations, 1 Hz / 10 Hz synthetic trial, one worker",
               f"{t1:.2f} s / {t10:.2f} s", f"≤ {CROSSVAL_S:g} s (1 Hz)", yes(t1 <= CROSSVAL_S)),
    ]  # fmt: skip


REPLAY_LINES = (
    r"trial: \d+ captures, (?P<records>\d+) records, (?P<lines>\d+) lines, (?P<minutes>#) min",
    r"pipeline \(decode\+align\+KF\+encode\):\s*(?P<pipe>#) s\s+(?P<lps>#) lines/s\s+(?P<rt>#)x",
    r"anchor \(pynmea2[^:]*:\s*(?P<anchor>#) s",
    r"pipeline / anchor: (?P<ratio>#)",
    r"decoding alone:\s*(?P<dec>#) s = (?P<dec_x>#)x the anchor;.*?:\s*(?P<rest>#) s = (?P<rest_x>#)x",
    r"emlogd replay --fast \(whole command[^:]*:\s*(?P<cmd>#) s, (?P<cmd_x>#)x",
    r"reading the captures \(CaptureReader[^:]*:\s*(?P<read>#) s; starting Python[^:]*:\s*(?P<start>#)",
)
"""What ``bench_replay.py`` prints, line by line, each number named (``#``: a number)."""


def named(patterns: tuple[str, ...], text: str) -> dict[str, float]:
    """The named numbers of every pattern (``#`` standing for a number) in ``text``."""
    out: dict[str, float] = {}
    for pattern in patterns:
        m = re.search(pattern.replace("#", NUM[1:-1]), text, re.MULTILINE)
        if m is None:
            raise BenchError(f"no line matching {pattern!r}")
        out.update((k, float(v)) for k, v in m.groupdict().items())
    return out


def parse_replay(text: str) -> list[Figure]:
    """``bench_replay.py`` on the full trial, wall time."""
    f = named(REPLAY_LINES, text)
    rt_target = f"≥ {REAL_TIME_X:g}× real time"
    return [
        Figure(f"replay through the pipeline, full trial ({f['lines'] / 1e6:.2f} M lines, "
               f"{f['minutes']:.0f} min), records in memory, `examples/emlogd.yaml`, wall, best of 3",
               f"{f['pipe']:.2f} s, {thousands(f['lps'])} lines/s, {f['rt']:.0f}× real time",
               rt_target, yes(f["rt"] >= REAL_TIME_X)),
        Figure("of which decoding (framing, checksums, validation, records)",
               f"{f['dec']:.2f} s, {f['dec_x']:.2f}× the anchor"),
        Figure("of which alignment, lag search, identifiability, filter, supervision, encoding",
               f"{f['rest']:.2f} s, {f['rest_x']:.2f}× the anchor"),
        Figure("the anchor: `pynmea2.parse(check=True)` on the NMEA lines + split/convert of "
               "the PD6 lines", f"{f['anchor']:.2f} s; the pipeline {f['ratio']:.2f}× it",
               f"pipeline ≤ {ANCHOR_X:g}×", yes(f["ratio"] <= ANCHOR_X)),
        Figure("`emlogd replay --fast` command on the full trial, reading the captures",
               f"{f['cmd']:.2f} s, {f['cmd_x']:.0f}× real time (reading the captures "
               f"{f['read']:.2f} s, starting Python {f['start']:.2f} s)",
               rt_target, yes(f["cmd_x"] >= REAL_TIME_X)),
    ]  # fmt: skip


def parse_replay_cpu(text: str) -> list[Figure]:
    """``bench_replay.py --cpu`` on the trial at scale 0.2."""
    f = named(REPLAY_LINES, text)
    return [
        Figure(f"replay through the pipeline in CPU time, trial at scale 0.2 "
               f"({f['lines'] / 1e3:.0f} k lines, {f['minutes']:.1f} min), best of 3",
               f"{f['pipe']:.2f} s, {f['rt']:.0f}× real time; the anchor {f['anchor']:.2f} s, the "
               f"pipeline {f['ratio']:.2f}× it (decoding {f['dec_x']:.2f}×, the rest {f['rest_x']:.2f}×)",
               f"≥ {REAL_TIME_X:g}× real time", yes(f["rt"] >= REAL_TIME_X)),
        Figure("`emlogd replay --fast` command on the trial at scale 0.2, wall",
               f"{f['cmd']:.2f} s, {f['cmd_x']:.0f}× real time (starting Python {f['start']:.2f} s)",
               f"≥ {REAL_TIME_X:g}× real time", yes(f["cmd_x"] >= REAL_TIME_X)),
    ]  # fmt: skip


def parse_import(text: str) -> list[Figure]:
    """``bench_import.py --mb SMALL LARGE``: peak RSS at both sizes, per format."""
    runs: dict[str, list[tuple[float, float, float, float]]] = {}
    for m in re.finditer(r"^(nmea|csv)\s+" + NUM + r" MB,\s+(\d+) lines:\s+" + NUM + r" s, peak RSS\s+" + NUM + " MB", text, re.MULTILINE):  # fmt: skip
        runs.setdefault(m[1], []).append((float(m[2]), float(m[3]), float(m[4]), float(m[5])))
    if set(runs) != {"nmea", "csv"} or any(len(r) < 2 for r in runs.values()):
        raise BenchError("not two sizes of both formats")
    small, large = runs["nmea"][0][0], runs["nmea"][-1][0]
    parts, checks = [], []
    for fmt, label in (("nmea", "NMEA"), ("csv", "CSV")):
        lo, hi = runs[fmt][0], runs[fmt][-1]
        parts.append(
            f"{label} {lo[3]:.1f} → {hi[3]:.1f} MB ({hi[1] / 1e6:.2f} M lines in {hi[2]:.1f} s)"
        )
        checks.append((label, hi[3] - lo[3] <= IMPORT_RSS_SLACK_MB))
    return [
        Figure(f"`emlogd import` of a synthetic NMEA log / Expedition-style CSV, "
               f"{small:g} MB then {large:g} MB: peak RSS",
               "; ".join(parts),
               f"constant memory: ≤ {IMPORT_RSS_SLACK_MB:g} MB more at {large:g} MB", met(*checks)),
    ]  # fmt: skip


def parse_daemon(text: str) -> list[Figure]:
    """``bench_daemon.py --skip growth``: READY, latency, live CPU and RSS."""
    (ready,) = grab(r"start -> READY=1: median " + NUM, text)
    med, p99 = grab(r"daemon\s+median " + NUM + r" ms\s+p99 " + NUM, text, 2)
    fmed, fp99 = grab(r"forwarder median " + NUM + r" ms\s+p99 " + NUM, text, 2)
    rmed, rp99 = grab(r"ratio\s+median " + NUM + r"x\s+p99 " + NUM, text, 2)
    (cpu,) = grab(r"CPU " + NUM + " % of one core", text)
    wakes, floor = grab(r"^\s*" + NUM + r" wake-ups/s; a bare Python.*? costs " + NUM, text, 2)
    rss, peak = grab(r"RSS " + NUM + r" MiB, peak " + NUM, text, 2)
    return [
        Figure("start → `READY=1`, median of 3 starts", f"{ready:.3f} s",
               f"≤ {READY_S:g} s", yes(ready <= READY_S)),
        Figure("latency VHW in → corrected VHW out (10 Hz, a 10 Hz PD6 DVL alongside)",
               f"median {med:.3f} ms, p99 {p99:.3f} ms; {rmed:.2f}× / {rp99:.2f}× a bare "
               f"forwarder ({fmed:.3f} / {fp99:.3f} ms)",
               f"median ≤ {LATENCY_MEDIAN_MS:g} ms, p99 ≤ {LATENCY_P99_MS:g} ms, "
               f"≤ {FORWARDER_X:g}× a bare forwarder",
               met((f"median ≤ {LATENCY_MEDIAN_MS:g} ms", med <= LATENCY_MEDIAN_MS),
                   (f"p99 ≤ {LATENCY_P99_MS:g} ms", p99 <= LATENCY_P99_MS),
                   ("median ≤ 2× the forwarder's", rmed <= FORWARDER_X),
                   ("p99 ≤ 2× the forwarder's", rp99 <= FORWARDER_X))),
        Figure("CPU at live rates (1 Hz VHW, 10 Hz VBW + 5 Hz VHW, 10 Hz PD6)",
               f"{cpu:.2f} % of a core at {wakes:.1f} wake-ups/s (a bare Python epoll loop "
               f"at that rate: {floor:.2f} %)", f"≤ {LIVE_CPU_PCT:g} % of a core",
               yes(cpu <= LIVE_CPU_PCT)),
        Figure("RSS at live rates", f"{rss:.1f} MiB (peak {peak:.1f} MiB)",
               f"≤ {RSS_MIB:g} MiB", yes(peak <= RSS_MIB)),
    ]  # fmt: skip


def _call(label: str, text: str) -> tuple[float, float, float]:
    """(calls, µs a call, % of a core) of one ``bench_wake_costs.py`` step."""
    calls, us, pct = grab(re.escape(label) + r"\s+(\d+) calls\s+" + NUM + r" us\s+" + NUM + " %", text, 3)  # fmt: skip
    return calls, us, pct


def parse_wake_costs(text: str) -> list[Figure]:
    """``bench_wake_costs.py``: CPU per wake-up by part, and learning one reading."""
    seconds, rate = grab(r"live rates for " + NUM + " s, " + NUM + " wake-ups/s", text, 2)
    wait, daemon, feed = grab(r"mean of all wake-ups\s+" + NUM + r"\s+" + NUM + r"\s+" + NUM + r"\s+" + NUM, text, 4)[1:]  # fmt: skip
    shares = grab(r"share of one core: wait " + NUM + " %, daemon " + NUM + " %, feed " + NUM, text, 3)  # fmt: skip
    dvl = _call("pipeline feed of dvl (decode, route, learn)", text)
    uut = _call("pipeline feed of emlog2 (decode, route, learn)", text)
    learn = _call("learn one reading (align, health, filter, supervise)", text)
    step = _call("of which the filter and identifiability (step)", text)
    sup = _call("of which the supervisor's verdicts (observe)", text)
    align = _call("of which align it with the reference", text)
    ref = _call("of which a reference sample (glitch filter, alignment)", text)
    return [
        Figure(f"where the live CPU goes, per wake-up at {rate:.1f} wake-ups/s",
               f"the wait {wait:.1f} µs, the daemon's own Python {daemon:.1f} µs, `Pipeline.feed` "
               f"{feed:.1f} µs: {shares[0]:.2f} %, {shares[1]:.2f} %, {shares[2]:.2f} % of a core; "
               f"a DVL read's feed {dvl[1]:.0f} µs, a UUT read's (emlog2) {uut[1]:.0f} µs"),
        Figure(f"learning one UUT reading at live rates ({learn[0] / seconds:.1f} a second)",
               f"{learn[1]:.0f} µs, {learn[2]:.3f} % of a core: the filter and identifiability "
               f"(`Learner.step`) {step[1]:.0f} µs, the supervisor's verdicts "
               f"(`Supervisor.observe`) {sup[1]:.0f} µs, the alignment {align[1]:.0f} µs; a "
               f"reference sample's routing {ref[1]:.0f} µs"),
    ]  # fmt: skip


def parse_live_profile(text: str) -> list[Figure]:
    """``bench_live_profile.py``: the largest shares of the loop's CPU a function holds of
    its own, and with what it calls (the loop itself left out)."""
    total, seconds = grab(r"the loop's CPU under the profiler: " + NUM + " s over about " + NUM, text, 2)  # fmt: skip
    row = re.compile(r"^  (.+?)\s+\d+\s+" + NUM + r"\s+" + NUM + " %$", re.MULTILINE)
    own, _, cum = text.partition("by cumtime:")
    tops = []
    for block in (own.partition("by tottime:")[2], cum):
        found = [(m[1], float(m[3])) for m in row.finditer(block) if "(_loop)" not in m[1]]
        if not found:
            raise BenchError("no function in the profile")
        tops.append(", ".join(f"`{name}` {pct:.1f} %" for name, pct in found[:3]))
    return [
        Figure(f"the daemon's loop function by function at live rates (cProfile on the thread's "
               f"CPU clock, {seconds:.0f} s: {total:.2f} s of CPU)",
               f"the largest shares of the loop's CPU a function holds of its own: {tops[0]}; "
               f"with what it calls: {tops[1]}"),
    ]  # fmt: skip


def parse_crossval_command(plain: str, current: str) -> list[Figure]:
    """Two ``emlogd crossval`` runs (without, with ``--current``), each its output followed
    by a ``wall W cpu C`` line this script appends."""
    pat = r"(\d+) out-of-sample evaluations, lag " + NUM + " s, " + NUM + " s"
    runs = []
    for text in (plain, current):
        n, _, evals = grab(pat, text, 3)
        wall, cpu = grab(r"^wall " + NUM + " cpu " + NUM, text, 2)
        runs.append((n, evals, wall, cpu))
    (n, e0, w0, c0), (_, e1, w1, c1) = runs
    return [
        Figure(f"`emlogd crossval` on the full simulated trial ({n:.0f} evaluations), "
               "without / with `--current`",
               f"{c0:.1f} s / {c1:.1f} s CPU; wall {w0:.1f} s / {w1:.1f} s for the whole "
               f"command, of which the evaluations (the time the command prints) "
               f"{e0:.1f} s / {e1:.1f} s",
               f"≤ {CROSSVAL_S:g} s wall", met(("without", w0 <= CROSSVAL_S), ("with", w1 <= CROSSVAL_S))),
    ]  # fmt: skip


# running


def run(argv: list[str]) -> str:
    """stdout of ``python ARGV`` from the tree's root with the tree on the path; its stderr
    passes through. Raises :class:`BenchError` when it fails."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, *argv], cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True
    )
    if done.returncode != 0:
        raise BenchError(f"exit status {done.returncode}")
    return done.stdout


def timed(argv: list[str]) -> str:
    """:func:`run`, with a last line ``wall W cpu C``: its wall and children's CPU, s."""

    def cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    c0, t0 = cpu(), time.perf_counter()
    out = run(argv)
    return out + f"\nwall {time.perf_counter() - t0:.3f} cpu {cpu() - c0:.3f}\n"


def _captures(trial: Path) -> list[str]:
    return [str(p) for p in sorted(trial.glob("[1-5]-*.cap"))]


def _crossval_command(ctx: Context) -> list[Figure]:
    argv = ["-m", "emlogd", "crossval", *_captures(ctx.full), *CROSSVAL_ARGS]
    plain = keep(ctx, "crossval-cmd", timed(argv))
    current = keep(ctx, "crossval-cmd-current", timed([*argv, "--current"]))
    return parse_crossval_command(plain, current)


def keep(ctx: Context, name: str, text: str) -> str:
    """``text`` (a command's output), also written to ``DIR/out/NAME.txt``."""
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / f"{name}.txt").write_text(text)
    return text


@dataclass(frozen=True)
class Bench:
    """One command of the table: its key, the command as the table shows it (``DIR``: the
    folder given), how it runs, whether it takes minutes, and the scale of the simulated
    trial it reads (None: none)."""

    key: str
    shown: str
    measure: Callable[[Context], list[Figure]]
    slow: bool = False
    trial: float | None = None


def _script(name: str, args: Callable[[Context], list[str]], parse: Callable[[str], list[Figure]]) -> Callable[[Context], list[Figure]]:  # fmt: skip
    """Run ``bench/NAME ARGS``, keep its output (named after its parser), parse it."""
    key = parse.__name__.removeprefix("parse_")
    return lambda ctx: parse(keep(ctx, key, run([f"bench/{name}", *args(ctx)])))


BENCHES = (
    Bench("kf", "`bench/bench_kf.py`", _script("bench_kf.py", lambda c: [], parse_kf)),
    Bench("ls", "`bench/bench_ls.py`", _script("bench_ls.py", lambda c: [], parse_ls)),
    Bench("crossval", "`bench/bench_crossval.py`",
          _script("bench_crossval.py", lambda c: [], parse_crossval)),
    Bench("replay", "`bench/bench_replay.py --outdir DIR/full`",
          _script("bench_replay.py", lambda c: ["--outdir", str(c.full)], parse_replay), slow=True, trial=1.0),
    Bench("replay-cpu", "`bench/bench_replay.py --cpu --scale 0.2 --outdir DIR/scale-0.2`",
          _script("bench_replay.py", lambda c: ["--cpu", "--scale", "0.2", "--outdir", str(c.small)],
                  parse_replay_cpu), trial=0.2),
    Bench("crossval-cmd", f"`time emlogd crossval DIR/full/[1-5]-*.cap {' '.join(CROSSVAL_ARGS)} [--current]`",
          _crossval_command, trial=1.0),
    Bench("import", f"`bench/bench_import.py --mb {' '.join(f'{x:g}' for x in IMPORT_MB)}`",
          _script("bench_import.py", lambda c: ["--mb", *(f"{x:g}" for x in IMPORT_MB)], parse_import)),
    Bench("daemon", "`bench/bench_daemon.py --skip growth --trial DIR/full`",
          _script("bench_daemon.py", lambda c: ["--skip", "growth", "--trial", str(c.full)], parse_daemon),
          slow=True, trial=1.0),
    Bench("profile", "`bench/bench_live_profile.py --trial DIR/full --top 12`",
          _script("bench_live_profile.py", lambda c: ["--trial", str(c.full), "--top", "12"], parse_live_profile),
          slow=True, trial=1.0),
    Bench("wake", "`bench/bench_wake_costs.py --trial DIR/full`",
          _script("bench_wake_costs.py", lambda c: ["--trial", str(c.full)], parse_wake_costs),
          slow=True, trial=1.0),
)  # fmt: skip


def commit() -> str:
    """``git rev-parse --short HEAD``, ``-dirty`` when a tracked file differs from it."""

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()  # fmt: skip

    dirty = git("status", "--porcelain", "--untracked-files=no")
    return git("rev-parse", "--short", "HEAD") + ("-dirty" if dirty else "")


def machine() -> str:
    """Cores, CPU model and Python, as the table's header states them."""
    model = "unknown CPU"
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    return f"{os.cpu_count()} cores ({model}), {platform.system()}, Python {platform.python_version()}"  # fmt: skip


def simulate(ctx: Context, scale: float) -> None:
    """``emlogd simulate`` (seed 1) at ``scale`` into its folder unless it holds the five
    captures; a failure is said on stderr (each bench then simulates its own or fails)."""
    trial = ctx.full if scale == 1.0 else ctx.small
    if len(_captures(trial)) == 5:
        return
    print(f"reference: simulating the trial at scale {scale:g} into {trial}", file=sys.stderr)
    try:
        run(["-m", "emlogd", "simulate", "--seed", "1", "--scale", f"{scale:g}", str(trial)])
    except BenchError as e:
        print(f"reference: simulating into {trial} failed: {e}", file=sys.stderr)


def table(rows: list[Row]) -> str:
    """The Markdown table: (figure, its command, the commit, the load) per row."""
    out = ["| figure | value | target | met | command | commit | load |", "|" + "---|" * 7]
    for f, cmd, sha, load in rows:
        cells = (f.figure, f.value, f.target, f.met, cmd, sha, load)
        out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(out)


def measure(bench: Bench, ctx: Context, sha: str) -> list[Row]:
    """The rows of one bench; one row saying why when it fails or prints no figure."""
    print(f"reference: {bench.key}: {bench.shown} ...", file=sys.stderr, flush=True)
    before, t0 = os.getloadavg()[0], time.perf_counter()
    try:
        figures = bench.measure(ctx)
    except BenchError as e:
        figures = [Figure(f"`{bench.key}`", f"not measured: {e}")]
    load = f"{before:.1f} → {os.getloadavg()[0]:.1f}"
    print(f"reference: {bench.key}: done in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return [(f, bench.shown, sha, load) for f in figures]


def main() -> None:
    """Simulate the trials, run the benches chosen, print the table."""
    keys = [b.key for b in BENCHES]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="the folder of the simulated trials (made if missing)")
    ap.add_argument("--skip", nargs="+", default=[], choices=keys, help="benches not to run")
    ap.add_argument("--only", nargs="+", choices=keys, help="run only these benches")
    ap.add_argument("--quick", action="store_true",
                    help=f"skip the benches that take minutes ({', '.join(b.key for b in BENCHES if b.slow)})")  # fmt: skip
    args = ap.parse_args()
    chosen = [
        b for b in BENCHES
        if b.key not in args.skip and (args.only is None or b.key in args.only)
        and not (args.quick and b.slow)
    ]  # fmt: skip
    ctx = Context(args.dir / "full", args.dir / "scale-0.2", args.dir / "out")
    sha, start, load0 = commit(), datetime.now(UTC), os.getloadavg()[0]
    for scale in sorted({b.trial for b in chosen if b.trial is not None}, reverse=True):
        simulate(ctx, scale)
    rows = [row for b in chosen for row in measure(b, ctx, sha)]
    minutes = (datetime.now(UTC) - start).total_seconds() / 60
    print(
        f"Run on {sha}, {start:%Y-%m-%d %H:%M} UTC ({minutes:.0f} min), with `PYTHONPATH=. "
        f"python bench/reference.py DIR{' --quick' if args.quick else ''}` (every command below "
        f"from the repository root with `PYTHONPATH=.`): {machine()}; "
        f"load average (1 min, `uptime`) {load0:.1f} at the start, {os.getloadavg()[0]:.1f} "
        "at the end. `DIR/full`: `emlogd simulate DIR/full` (seed 1); `DIR/scale-0.2`: the "
        "same with `--scale 0.2`; each command's own output in `DIR/out/`.\n"
    )
    print(table(rows))


if __name__ == "__main__":
    main()
