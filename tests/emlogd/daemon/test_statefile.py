"""State persistence: round trip, corruption, backup, failed writes, kill -9."""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.calfile import CalibrationFileError, dumps, loads
from emlogd.daemon.statefile import (
    MAX_STATE_BYTES,
    MAX_STATE_BYTES_PER_UUT,
    StateLockedError,
    StateStore,
    StateWriteError,
    max_state_bytes,
)
from emlogd.pipeline.calibration import Calibration, check
from emlogd.pipeline.integrity import Envelope
from tests.emlogd.daemon.harness import saved_calibration
from tests.synth import TWO_AXIS_FIGURES as FIGURES


def _state(m: float = 0.1, n: int = 100) -> Calibration:
    return saved_calibration(m, n=n)


def parse_state(text: str) -> dict[str, Calibration]:
    return loads(text)[0]


def test_round_trip(tmp_path: Path) -> None:
    """A saved calibration loads back equal, mode 0640."""
    store = StateStore(tmp_path / "state.yaml")
    assert store.load() == ({}, [])
    store.save({"emlog1": _state()})
    states, report = store.load()
    assert report == []
    assert states == {"emlog1": _state()}
    assert oct((tmp_path / "state.yaml").stat().st_mode & 0o777) == oct(0o640)


def test_previous_good_file_is_kept_as_backup(tmp_path: Path) -> None:
    """Each save keeps the previous good file as .bak."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    store.save({"emlog1": _state(0.2)})
    assert parse_state(store.backup.read_text())["emlog1"].params.m == 0.1
    assert parse_state(store.path.read_text())["emlog1"].params.m == 0.2


@pytest.mark.parametrize(
    "damage",
    [
        lambda t: t[: len(t) // 2],  # torn write
        lambda t: "garbage: [\n",
        lambda t: t.replace("schema: 2", "schema: 3"),
        lambda t: t.replace("m: 0.2", "m: .nan"),
        lambda t: "",
        lambda t: t.replace("model: EM3", "model: EM9"),
        lambda t: t.replace("b: 0.05", "z: 0.05", 1),  # parameters that do not fit the model
        lambda t: t.replace("n_samples: 100", "n_samples: -4"),
        lambda t: t.replace("nis_mean: 1.01", "nis_mean: lots"),
    ],
    ids=["torn", "garbage", "schema", "nan", "empty", "model", "params", "count", "nis"],
)
def test_damaged_file_falls_back_to_the_backup(tmp_path: Path, damage: object) -> None:
    """A damaged file is reported and the backup used; it never replaces the good backup."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    store.save({"emlog1": _state(0.2)})
    damaged = damage(store.path.read_text())  # type: ignore[operator]
    assert damaged != store.path.read_text()
    store.path.write_text(damaged)
    states, report = store.load()
    assert states["emlog1"].params.m == 0.1
    assert any("damaged" in r for r in report) and any("backup" in r for r in report)
    # saving again never backs up the damaged file over the good backup
    store.save({"emlog1": _state(0.3)})
    assert parse_state(store.backup.read_text())["emlog1"].params.m == 0.1


def test_both_damaged_starts_uncalibrated(tmp_path: Path) -> None:
    """Without a good file or backup the daemon starts uncalibrated."""
    store = StateStore(tmp_path / "state.yaml")
    store.path.write_text("x")
    store.backup.write_text("y")
    states, report = store.load()
    assert states == {} and "starting uncalibrated" in report[-1]


def test_failed_write_leaves_the_previous_file(tmp_path: Path) -> None:
    """A failed write raises StateWriteError and leaves the previous file and no temporary."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    before = store.path.read_bytes()
    # the directory is replaced by a file: every write fails (works as root too)
    blocked = StateStore(tmp_path / "state.yaml" / "inner.yaml")
    with pytest.raises(StateWriteError, match="cannot write"):
        blocked.save({"emlog1": _state(0.2)})
    assert store.path.read_bytes() == before
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_fifo_at_the_temporary_path_does_not_hold_the_save(tmp_path: Path) -> None:
    """A FIFO put where the save writes its temporary file (``.state.yaml.PID.tmp``, a
    name anyone who can write the directory can tell): the save writes the state file
    all the same, at once. Its open waited for a reader of the FIFO, for ever: the
    daemon's one thread held, no output, no answer."""
    store = StateStore(tmp_path / "state.yaml")
    os.mkfifo(tmp_path / f".state.yaml.{os.getpid()}.tmp")
    saving = threading.Thread(target=store.save, args=({"emlog1": _state(0.1)},), daemon=True)
    saving.start()
    saving.join(5.0)
    if saving.is_alive():  # let the held save go: open the FIFO for reading
        os.close(os.open(tmp_path / f".state.yaml.{os.getpid()}.tmp", os.O_RDONLY))
        saving.join(5.0)
        pytest.fail("the save waited on the FIFO")
    assert store.load()[0]["emlog1"].estimate.params.m == 0.1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.yaml"]


def test_a_directory_at_the_path_is_never_moved_aside(tmp_path: Path) -> None:
    """A directory where the state file should be (``state_file: /var/lib/emlogd/``
    given to ``--state``, or made there): the save refuses, the directory and its files
    left where they are; it was moved aside to ``.refused`` like a damaged file, with
    every file in it, and a state file written in its place."""
    store = StateStore(tmp_path / "state")
    store.path.mkdir()
    (store.path / "other.yaml").write_text("kept")
    with pytest.raises(StateWriteError, match="a directory, left where it is"):
        store.save({"emlog1": _state()})
    assert (store.path / "other.yaml").read_text() == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only directory")
def test_read_only_directory(tmp_path: Path) -> None:
    """A directory without write permission refuses the save; the file is intact."""
    store = StateStore(tmp_path / "d" / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    before = store.path.read_bytes()
    store.path.parent.chmod(0o500)
    try:
        with pytest.raises(StateWriteError, match="cannot write"):
            store.save({"emlog1": _state(0.2)})
    finally:
        store.path.parent.chmod(0o700)
    assert store.path.read_bytes() == before
    assert store.load() == ({"emlog1": _state(0.1)}, [])


def test_the_lock_is_taken_on_the_real_path(tmp_path: Path) -> None:
    """Two stores reaching one state file, through a symlink to the file and through a
    symlinked directory, share one lock: the second is refused with a message naming the
    real path; another file is not."""
    real_dir = tmp_path / "real"
    real_dir.mkdir()
    (tmp_path / "link.yaml").symlink_to(real_dir / "state.yaml")
    (tmp_path / "dirlink").symlink_to(real_dir)
    first = StateStore(real_dir / "state.yaml")
    fd = first.lock()
    assert fd is not None
    try:
        for other in (tmp_path / "link.yaml", tmp_path / "dirlink" / "state.yaml"):
            with pytest.raises(StateLockedError, match=f"real path {real_dir}/state.yaml"):
                StateStore(other).lock()
        free = StateStore(real_dir / "other.yaml").lock()
        assert free is not None
        os.close(free)
    finally:
        os.close(fd)


def test_orphaned_temp_files_of_dead_writers_are_removed(tmp_path: Path) -> None:
    """Temp files of a killed writer go at the next save; a live writer's stay."""
    dead = int(Path("/proc/sys/kernel/pid_max").read_text()) + 1
    live = os.getppid()
    names = [
        f".state.yaml.{dead}.tmp",
        f".state.yaml.bak.{dead}.tmp",
        f".state.yaml.{live}.tmp",
        f".other.yaml.{dead}.tmp",
    ]
    for name in names:
        (tmp_path / name).write_text("partial")
    StateStore(tmp_path / "state.yaml").save({"emlog1": _state()})
    assert sorted(f.name for f in tmp_path.iterdir()) == sorted(
        [f".state.yaml.{live}.tmp", f".other.yaml.{dead}.tmp", "state.yaml"]
    )


def test_backup_is_copied_where_hard_links_fail(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a file system without hard links the backup is a synced copy."""

    def no_link(src: object, dst: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    monkeypatch.setattr(os, "link", no_link)
    store.save({"emlog1": _state(0.2)})
    assert parse_state(store.backup.read_text())["emlog1"].params.m == 0.1
    assert store.load()[0]["emlog1"].params.m == 0.2
    assert sorted(f.name for f in tmp_path.iterdir()) == ["state.yaml", "state.yaml.bak"]


def test_full_filesystem_simulated_with_a_tiny_limit(tmp_path: Path) -> None:
    """RLIMIT_FSIZE makes the write fail like a full disk (EFBIG) in a child process."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    before = store.path.read_bytes()
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (64, 64))\n"
        "from emlogd.daemon.statefile import StateLockedError, StateStore, StateWriteError\n"
        "from emlogd.pipeline.calibration import Calibration\n"
        "from calib.estimate import Estimate\n"
        "from calib.models import Params\n"
        f"s = StateStore({str(store.path)!r})\n"
        "try:\n"
        "    s.save({'emlog1': Calibration('emlog1', Estimate(Params('EM3', m=0.5), {}), None)})\n"
        "except StateWriteError as e:\n"
        "    print('refused', e); sys.exit(0)\n"
        "sys.exit(3)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "refused" in r.stdout
    assert store.path.read_bytes() == before


def test_dump_marks_the_end() -> None:
    """The end marker comes last: a file without it is truncated."""
    text = dumps({"emlog1": _state()})
    assert text.rstrip().endswith("end: true")
    with pytest.raises(CalibrationFileError, match="truncated"):
        parse_state(text.replace("end: true", ""))


def test_non_finite_values_are_written_as_null(tmp_path: Path) -> None:
    """A nan NIS and an undetermined σ are written as null and read back as None."""
    s = Calibration(
        "u", Estimate(Params("EM3", m=0.1), {"m": None, "b": 0.01}), None, nis_mean=math.nan
    )
    store = StateStore(tmp_path / "s.yaml")
    store.save({"u": s})
    loaded = store.load()[0]["u"]
    assert loaded.nis_mean is None and loaded.param_std["m"] is None


@pytest.mark.parametrize(
    "poison",
    [
        lambda t: t.replace("m: 0.2", "m: -2.0"),
        lambda t: t.replace("b: 0.05", "b: 1000000.0"),
        lambda t: t.replace("b: 0.05", "b: 1.0e+300"),
        lambda t: t.replace("- - 0.0001", "- - -0.0001"),
        lambda t: t.replace("- 1.0e-06", "- 1.0e+300"),
        lambda t: t.replace("lag_s: 3.2", "lag_s: 1.0e+9"),
    ],
    ids=["m=-2", "b=1e6", "b=1e300", "not-spd", "cov-1e300", "lag"],
)
def test_a_poisoned_file_is_refused_and_the_backup_used(tmp_path: Path, poison: object) -> None:
    """Absurd parameters, a covariance that is not SPD or a lag that is not one: the .bak."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    store.save({"emlog1": _state(0.2)})
    text = store.path.read_text()
    poisoned = poison(text)  # type: ignore[operator]
    assert poisoned != text
    store.path.write_text(poisoned)
    states, report = store.load(check=lambda c: check(c, Envelope()))
    assert states["emlog1"].params.m == 0.1
    assert any("refused" in r or "damaged" in r for r in report)
    store.backup.write_text(poisoned)
    states, report = store.load(check=lambda c: check(c, Envelope()))
    assert states == {} and "starting uncalibrated" in report[-1]


KILLER = """
import sys
from calib.estimate import Estimate
from calib.models import Params
from emlogd.daemon.statefile import StateStore
from emlogd.pipeline.calibration import Calibration
store = StateStore(sys.argv[1])
i = 0
while True:
    i += 1
    store.save({"emlog1": Calibration("emlog1", Estimate(Params("EM3", m=i * 1e-6), {}), None,
                                      n_samples=i)})
"""


def _kill_loop(tmp_path: Path, rounds: int) -> None:
    path = tmp_path / "state.yaml"
    last = 0
    for k in range(rounds):
        before = path.stat().st_mtime_ns if path.exists() else None
        proc = subprocess.Popen([sys.executable, "-c", KILLER, str(path)])
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:  # wait for this process's first save
            if path.exists() and path.stat().st_mtime_ns != before:
                break
            time.sleep(0.005)
        time.sleep((k % 7) * 0.011)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        states, report = StateStore(path).load()
        assert "emlog1" in states, report
        assert not any("damaged" in r for r in report if "bak" not in r), report
        n = states["emlog1"].n_samples
        assert n >= 1
        last = n
    assert last > 0
    StateStore(path).save({"emlog1": _state()})
    assert sorted(f.name for f in tmp_path.iterdir()) == ["state.yaml", "state.yaml.bak"]


@pytest.mark.parametrize("rounds", [8, pytest.param(60, marks=pytest.mark.soak)])
def test_kill_9_while_saving_never_loses_the_file(tmp_path: Path, rounds: int) -> None:
    """kill -9 at any moment of a save leaves a loadable file (8 kills; 60 in the soak run)."""
    _kill_loop(tmp_path, rounds)


def test_a_backup_that_is_the_same_file_leaves_no_temporary(tmp_path: Path) -> None:
    """A writer killed between linking the backup and replacing the file leaves the
    file and its backup as one inode; rename() between them does nothing, so the
    next save must remove its link itself (it once stayed, named with our own pid)."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state()})
    store.backup.unlink(missing_ok=True)
    os.link(store.path, store.backup)
    store.save({"emlog1": _state()})
    assert sorted(f.name for f in tmp_path.iterdir()) == ["state.yaml", "state.yaml.bak"]
    assert store.load()[0]["emlog1"] == _state()


# -- the rules a state file obeys at load and save --------------------------------


def _check(max_lag_s: float = 10.0) -> object:
    return lambda c: check(c, Envelope(), max_lag_s)


@pytest.mark.parametrize(
    "poison",
    [
        lambda t: t.replace("m: 0.2", "m: -2.0"),
        lambda t: t.replace("lag_s: 3.2", "lag_s: -50.0"),
        lambda t: t[: len(t) // 2],
    ],
    ids=["m=-2", "lag=-50", "torn"],
)
def test_a_refused_file_never_becomes_the_backup(tmp_path: Path, poison: object) -> None:
    """A refused (or damaged) state file is moved aside to .refused at the next save; the
    good .bak stays as it was, and the new file is written."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    store.save({"emlog1": _state(0.2)})
    good_backup = store.backup.read_bytes()
    bad = poison(store.path.read_text())  # type: ignore[operator]
    store.path.write_text(bad)
    states, report = store.load(check=_check())  # type: ignore[arg-type]
    assert states["emlog1"].params.m == 0.1 and "using the backup" in report[-1]
    assert store.save({"emlog1": _state(0.3)}) == store.refused
    assert store.backup.read_bytes() == good_backup
    assert store.refused.read_text() == bad
    assert parse_state(store.path.read_text())["emlog1"].params.m == 0.3
    # the file written is good: the next save backs it up as usual
    assert store.save({"emlog1": _state(0.4)}) is None
    assert parse_state(store.backup.read_text())["emlog1"].params.m == 0.3


def test_a_refused_file_is_set_aside_even_without_a_backup(tmp_path: Path) -> None:
    """With no backup at all, a refused file is still kept aside and no .bak is made of it."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    store.path.write_text(store.path.read_text().replace("m: 0.1", "m: -2.0"))
    states, report = store.load(check=_check())  # type: ignore[arg-type]
    assert states == {} and "refused" in report[0]
    assert store.save({"emlog1": _state(0.2)}) == store.refused
    assert not store.backup.exists()
    assert "m: -2.0" in store.refused.read_text()


@pytest.mark.parametrize("blocked", ["backup", "refused"])
def test_a_directory_where_the_backup_goes_costs_the_backup_alone(
    tmp_path: Path, blocked: str
) -> None:
    """A directory (holding a file) at ``.bak``, or at ``.refused`` with the current file
    refused: the save writes the new file all the same, the directory and its file stay,
    and ``backup_problem`` says which step was skipped; the next save without it clears
    it. Before, every save failed (StateWriteError) and each calibration learnt from then
    on was lost at the next restart."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    in_the_way = store.backup if blocked == "backup" else store.refused
    in_the_way.mkdir()
    (in_the_way / "notes.txt").write_text("kept")
    if blocked == "refused":
        store.path.write_text(store.path.read_text().replace("m: 0.1", "m: -2.0"))
        store.load(check=_check())  # type: ignore[arg-type]
    assert store.save({"emlog1": _state(0.2)}) is None
    assert parse_state(store.path.read_text())["emlog1"].params.m == 0.2
    assert str(in_the_way) in (store.backup_problem or "")
    assert (in_the_way / "notes.txt").read_text() == "kept"
    (in_the_way / "notes.txt").unlink()
    in_the_way.rmdir()
    assert store.save({"emlog1": _state(0.3)}) is None and store.backup_problem is None
    assert parse_state(store.backup.read_text())["emlog1"].params.m == 0.2


@pytest.mark.parametrize(
    ("lag", "max_lag", "why"),
    [
        (-50.0, 10.0, "lag -50.0 s is outside [0, 10] s (max_lag_s)"),
        (-0.1, 10.0, "lag -0.1 s is outside [0, 10] s (max_lag_s)"),
        (12.0, 10.0, "lag 12.0 s is outside [0, 10] s (max_lag_s)"),
        (25.0, 30.0, ""),
        (0.0, 10.0, ""),
    ],
)
def test_the_lag_obeys_the_configs_bounds(
    tmp_path: Path, lag: float, max_lag: float, why: str
) -> None:
    """A state's lag outside [0, max_lag_s] refuses the file with the reason; a reset
    record's lag too (a reset keeps the lag)."""
    store = StateStore(tmp_path / "state.yaml")
    for reset in (False, True):
        cal = dataclasses.replace(_state(), lag_s=lag, reset=reset)
        store.path.unlink(missing_ok=True)
        store.save({"emlog1": cal})
        states, report = store.load(check=_check(max_lag))  # type: ignore[arg-type]
        if why:
            assert states == {} and report[0].endswith(f"is refused: emlog1: {why}"), report
        else:
            assert states["emlog1"].lag_s == lag and report == []


def test_other_models_round_trip_and_are_checked(tmp_path: Path) -> None:
    """The UUTs' calibrations of their other models are saved beside the ones in use, load
    back equal, and are checked like them (an absurd one refuses the file)."""
    store = StateStore(tmp_path / "state.yaml")
    em4 = Calibration("emlog1", Estimate(Params("EM4", a_spm=0.01, m=0.05, b_mps=0.1), {}), 2.5)
    store.save({"emlog1": _state()}, [em4])
    states, others, report = store.load_state(check=_check())  # type: ignore[arg-type]
    assert states == {"emlog1": _state()} and others == [em4] and report == []
    assert parse_state(store.path.read_text()) == {"emlog1": _state()}  # the file's reader
    bad = dataclasses.replace(em4, lag_s=-50.0)
    store.save({"emlog1": _state()}, [bad])
    states, others, report = store.load_state(check=_check())  # type: ignore[arg-type]
    assert "emlog1 EM4: lag -50.0 s is outside" in report[0]


def test_refused_two_axis_figures_never_become_the_backup(tmp_path: Path) -> None:
    """A state file whose two-axis misalignment is beyond 20° is refused: the backup's
    figures are loaded, and the next save sets the refused file aside, the good
    backup kept."""
    fig = FIGURES
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": dataclasses.replace(_state(0.1), two_axis=fig)})
    store.save({"emlog1": dataclasses.replace(_state(0.2), two_axis=fig)})
    good_backup = store.backup.read_bytes()
    store.path.write_text(store.path.read_text().replace("misalign_deg: 3.0", "misalign_deg: 25.0"))
    states, report = store.load(check=lambda c: check(c, Envelope()))
    assert states["emlog1"].two_axis == fig and "using the backup" in report[-1]
    assert store.save({"emlog1": _state(0.3)}) == store.refused
    assert store.backup.read_bytes() == good_backup


@pytest.mark.parametrize("blocked", ["backup", "refused"])
def test_a_file_that_cannot_be_replaced_where_the_backup_goes_costs_the_backup_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, blocked: str
) -> None:
    """A ``.bak`` (or, the current file refused, a ``.refused``) that cannot be replaced
    (``EPERM``: immutable, or another user's in a sticky directory): the save writes
    the new file all the same and ``backup_problem`` names the step and why; no
    temporary file is left; once it can be replaced the backup is kept again. Every
    save failed (StateWriteError), as with the directory of the test above."""
    store = StateStore(tmp_path / "state.yaml")
    store.save({"emlog1": _state(0.1)})
    in_the_way = store.backup if blocked == "backup" else store.refused
    if blocked == "refused":
        store.path.write_text(store.path.read_text().replace("m: 0.1", "m: -2.0"))
        store.load(check=_check())  # type: ignore[arg-type]
    replace = Path.replace

    def refusing(self: Path, target: str | Path) -> Path:
        if Path(target) == in_the_way:
            raise PermissionError(1, "Operation not permitted", str(target))
        return replace(self, target)

    monkeypatch.setattr(Path, "replace", refusing)
    rounds = (0.2, 0.3) if blocked == "backup" else (0.2,)  # a refused file is set aside once
    for m in rounds:
        assert store.save({"emlog1": _state(m)}) is None
        assert parse_state(store.path.read_text())["emlog1"].params.m == m
        assert store.backup_problem is not None, m
        assert str(in_the_way) in store.backup_problem
        assert "not permitted" in store.backup_problem
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    monkeypatch.undo()
    assert store.save({"emlog1": _state(0.4)}) is None and store.backup_problem is None
    assert parse_state(store.backup.read_text())["emlog1"].params.m == rounds[-1]


def test_holds_last_save_tells_a_file_replaced_or_removed(tmp_path: Path) -> None:
    """True right after a save; False before any, and once another process replaced the
    file (same size and all), rewrote it in place or removed it."""
    store = StateStore(tmp_path / "state.yaml")
    assert not store.holds_last_save()
    store.save({"emlog1": saved_calibration(0.1)})
    assert store.holds_last_save()
    other = StateStore(tmp_path / "other.yaml")
    other.save({"emlog1": saved_calibration(0.3)})
    other.path.replace(store.path)
    assert not store.holds_last_save()
    store.save({"emlog1": saved_calibration(0.1)})
    text = store.path.read_text()
    time.sleep(0.05)  # past the file system's clock tick: the edit's time is a new one
    store.path.write_text(text.replace("0.1", "0.3"))
    assert not store.holds_last_save()
    store.save({"emlog1": saved_calibration(0.1)})
    store.path.unlink()
    assert not store.holds_last_save()


def _device_or_socket(path: Path, kind: str) -> socket.socket | None:
    """A null device of its own (``mknod``: skip without the privilege) or a bound unix
    socket at ``path``; the socket, to close."""
    if kind == "device":
        try:
            os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        except PermissionError:
            pytest.skip("mknod needs CAP_MKNOD")
        return None
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(path))
    return sock


@pytest.mark.parametrize("kind", ["device", "socket"])
def test_a_device_at_the_state_path_is_left_where_it_is(tmp_path: Path, kind: str) -> None:
    """A character device (``state_file: /dev/null``, meant as "no state") or a socket at
    the state file's path: the save refuses (``StateWriteError`` saying so) and the node
    stays, nothing set aside. It was moved aside to ``.refused`` like a damaged file and a
    regular file written in its place: ``/dev/null`` itself, for a daemon run as root."""
    store = StateStore(tmp_path / "state.yaml")
    sock = _device_or_socket(store.path, kind)
    try:
        mode = store.path.lstat().st_mode
        with pytest.raises(StateWriteError, match="a device or a socket, left where it is"):
            store.save({"emlog1": saved_calibration(0.1)})
        assert store.path.lstat().st_mode == mode
        assert sorted(p.name for p in tmp_path.iterdir()) == ["state.yaml"]
    finally:
        if sock is not None:
            sock.close()


@pytest.mark.parametrize("kind", ["device", "socket"])
def test_a_state_file_linked_to_a_device_is_refused_and_the_link_kept(
    tmp_path: Path, kind: str
) -> None:
    """The state file a symlink to a character device (``→ /dev/null``) or a socket: the
    save refuses (``StateWriteError``), the link and the node stay, and nothing is written
    in the node's directory (``/dev`` for ``/dev/null``). The link was moved aside to
    ``.refused`` and a regular file written in its place."""
    nodes = tmp_path / "dev"
    nodes.mkdir()
    sock = _device_or_socket(nodes / "null", kind)
    store = StateStore(tmp_path / "state.yaml")
    store.path.symlink_to(nodes / "null")
    try:
        with pytest.raises(StateWriteError, match="a device or a socket, left where it is"):
            store.save({"emlog1": saved_calibration(0.1)})
        assert store.path.is_symlink() and sorted(p.name for p in nodes.iterdir()) == ["null"]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["dev", "state.yaml"]
    finally:
        if sock is not None:
            sock.close()


def _many(n: int) -> dict[str, Calibration]:
    return {f"e{i}": dataclasses.replace(_state(), uut=f"e{i}") for i in range(n)}


def test_a_state_file_of_many_uuts_loads_whole(tmp_path: Path) -> None:
    """A config of 600 UUTs: the state file (0.3 MB here) loads whole, saved again its
    previous one is the backup. The read's one bound (256 KiB) refused the file the
    daemon had written itself as damaged at its next start: every calibration lost."""
    store = StateStore(tmp_path / "s.yaml", uuts=600)
    assert store.max_bytes == 600 * MAX_STATE_BYTES_PER_UUT
    store.save(_many(600))
    assert store.path.stat().st_size > MAX_STATE_BYTES
    states, report = StateStore(tmp_path / "s.yaml", uuts=600).load()
    assert len(states) == 600 and report == []
    assert store.save(_many(600)) is None  # the good file made the backup, not refused
    assert store.backup.stat().st_size > MAX_STATE_BYTES
    assert max_state_bytes(3) == MAX_STATE_BYTES


def test_a_save_past_what_a_load_reads_keeps_the_file_that_loads(tmp_path: Path) -> None:
    """States longer than the store's bound (600 UUTs' for a store of one): the save
    is refused with ``StateWriteError`` and the previous file is byte-identical, rather
    than replaced by a file the next start would refuse."""
    store = StateStore(tmp_path / "s.yaml")
    store.save({"emlog1": _state()})
    before = store.path.read_bytes()
    with pytest.raises(StateWriteError, match="past the 262144 a load reads"):
        store.save(_many(600))
    assert store.path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]
