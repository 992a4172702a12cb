"""Persistence of the frozen calibration: a YAML state file, written atomically.

The file holds one entry per UUT (model, parameters, their σ, the filter
covariance, the record time of the calibration, the number of samples learnt, the
lag and the excitation figures) under a schema version. Writing is crash-safe:

1. the new content goes to a temporary file in the same directory, flushed and
   fsync-ed;
2. if the current file is valid it is hard-linked to ``<file>.bak`` (through a
   temporary name and a rename, so the backup is always a whole good file);
3. the temporary file is renamed over the current one (atomic) and the directory
   is fsync-ed.

A kill -9 at any point leaves the previous or the new file, never a torn one.
A write that fails (disk full, read-only, permissions) raises
:class:`StateWriteError` and leaves the previous file untouched. On load a corrupt
file is reported and the backup used.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml

from calib.models import PARAM_NAMES
from drivers.errors import EmlogdError

SCHEMA = 1
KIND = "emlogd-state"


class StateWriteError(EmlogdError):
    """The state file could not be written; the previous file is intact."""


class StateFormatError(EmlogdError):
    """A state file is damaged or of another schema."""


@dataclass(frozen=True, slots=True)
class CalibrationState:
    """The persisted calibration of one UUT."""

    uut: str
    model: str
    params: Mapping[str, float]
    param_std: Mapping[str, float] = field(default_factory=dict)
    covariance: tuple[tuple[float, ...], ...] = ()
    t: float = 0.0
    n_samples: int = 0
    lag_s: float | None = None
    excitation: Mapping[str, float] = field(default_factory=dict)
    nis_mean: float | None = None
    saved_at: str = ""

    def as_dict(self) -> dict[str, Any]:
        """Plain types for YAML (non-finite numbers as null)."""

        def f(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "model": self.model,
            "params": {k: f(v) for k, v in self.params.items()},
            "param_std": {k: f(v) for k, v in self.param_std.items()},
            "covariance": [[f(x) for x in row] for row in self.covariance],
            "t": self.t,
            "n_samples": self.n_samples,
            "lag_s": f(self.lag_s),
            "excitation": {k: f(v) for k, v in self.excitation.items()},
            "nis_mean": f(self.nis_mean),
            "saved_at": self.saved_at,
        }


def _float(v: Any, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise StateFormatError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def _state(uut: str, d: Any) -> CalibrationState:
    if not isinstance(d, dict):
        raise StateFormatError(f"uuts.{uut}: expected a mapping")
    try:
        model = d["model"]
        if model not in PARAM_NAMES:
            raise StateFormatError(
                f"uuts.{uut}.model: {model!r} is not one of {', '.join(PARAM_NAMES)}"
            )
        params = {str(k): _float(v, f"uuts.{uut}.params.{k}") for k, v in d["params"].items()}
        if sorted(params) != sorted(PARAM_NAMES[model]):
            raise StateFormatError(
                f"uuts.{uut}.params: {model} has {', '.join(PARAM_NAMES[model])},"
                f" the file has {', '.join(params) or 'none'}"
            )
        n_samples = d.get("n_samples", 0)
        if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 0:
            raise StateFormatError(f"uuts.{uut}.n_samples: expected a count, got {n_samples!r}")
        std = {
            str(k): (math.inf if v is None else _float(v, f"uuts.{uut}.param_std.{k}"))
            for k, v in (d.get("param_std") or {}).items()
        }
        cov = tuple(
            tuple(_float(x, f"uuts.{uut}.covariance") for x in row)
            for row in d.get("covariance") or ()
        )
        n = len(cov)
        if any(len(row) != n for row in cov):
            raise StateFormatError(f"uuts.{uut}.covariance: not square")
        lag = d.get("lag_s")
        exc = {
            str(k): (math.nan if v is None else _float(v, f"uuts.{uut}.excitation.{k}"))
            for k, v in (d.get("excitation") or {}).items()
        }
        nis = d.get("nis_mean")
        return CalibrationState(
            uut=uut,
            model=str(model),
            params=params,
            param_std=std,
            covariance=cov,
            t=_float(d.get("t", 0.0), f"uuts.{uut}.t"),
            n_samples=n_samples,
            lag_s=None if lag is None else _float(lag, f"uuts.{uut}.lag_s"),
            excitation=exc,
            nis_mean=None if nis is None else _float(nis, f"uuts.{uut}.nis_mean"),
            saved_at=str(d.get("saved_at", "")),
        )
    except (KeyError, AttributeError, TypeError, ValueError) as exc:
        raise StateFormatError(f"uuts.{uut}: malformed ({exc!r})") from None


def parse_state(text: str) -> dict[str, CalibrationState]:
    """Parse state-file text.

    Raises:
        StateFormatError: not YAML, wrong kind/schema, malformed entries.
    """
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise StateFormatError(f"not valid YAML ({exc.__class__.__name__})") from None
    if not isinstance(doc, dict) or doc.get("kind") != KIND:
        raise StateFormatError("not an emlogd state file")
    if doc.get("schema") != SCHEMA:
        raise StateFormatError(f"schema {doc.get('schema')!r}, this emlogd reads {SCHEMA}")
    uuts = doc.get("uuts")
    if not isinstance(uuts, dict):
        raise StateFormatError("missing uuts")
    if doc.get("end") is not True:
        raise StateFormatError("truncated (no end marker)")
    return {str(k): _state(str(k), v) for k, v in uuts.items()}


def dump_state(states: Mapping[str, CalibrationState]) -> str:
    """Serialise states (the end marker comes last, so a truncated file is detected)."""
    doc = {
        "kind": KIND,
        "schema": SCHEMA,
        "uuts": {uut: s.as_dict() for uut, s in states.items()},
        "end": True,
    }
    return (
        "# emlogd frozen calibration (written by the daemon; do not edit while it runs)\n"
        + yaml.safe_dump(doc, sort_keys=False)
    )


class StateStore:
    """The state file and its backup.

    Args:
        path: the state file (its directory must exist or be creatable).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.backup = self.path.with_name(self.path.name + ".bak")

    def load(self) -> tuple[dict[str, CalibrationState], list[str]]:
        """Load the states; returns (states, report lines about problems met).

        A missing file gives no state and no report; a damaged one is reported and
        the backup is tried.
        """
        report: list[str] = []
        for candidate in (self.path, self.backup):
            try:
                text = candidate.read_text(encoding="utf-8")
            except FileNotFoundError:
                if candidate == self.path and self.backup.exists():
                    report.append(f"{candidate} is missing")
                    continue
                if candidate == self.path:
                    return {}, report
                continue
            except (OSError, UnicodeDecodeError) as exc:
                report.append(f"{candidate} cannot be read: {exc}")
                continue
            try:
                states = parse_state(text)
            except StateFormatError as exc:
                report.append(f"{candidate} is damaged: {exc}")
                continue
            if candidate == self.backup:
                report.append(f"using the backup {candidate}")
            return states, report
        report.append("no usable state file: starting uncalibrated")
        return {}, report

    def save(self, states: Mapping[str, CalibrationState]) -> None:
        """Write atomically, keeping the previous good file as ``.bak``.

        Raises:
            StateWriteError: the write failed; the previous file is intact.
        """
        data = dump_state(states).encode("utf-8")
        d = self.path.parent
        tmp = d / f".{self.path.name}.{os.getpid()}.tmp"
        try:
            d.mkdir(parents=True, exist_ok=True)
            _write_synced(tmp, data)
            self._backup_current()
            tmp.replace(self.path)
            self._fsync_dir()
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise StateWriteError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._remove_orphans()

    def _remove_orphans(self) -> None:
        """Delete temporary files left by a writer that was killed (its pid is gone)."""
        orphan = re.compile(rf"\.{re.escape(self.path.name)}(?:\.bak)?\.([0-9]+)\.tmp")
        try:
            entries = list(self.path.parent.iterdir())
        except OSError:
            return
        for entry in entries:
            m = orphan.fullmatch(entry.name)
            if m is not None and int(m[1]) != os.getpid() and not _alive(int(m[1])):
                with contextlib.suppress(OSError):
                    entry.unlink()

    def _backup_current(self) -> None:
        """Make the current file, if valid, the backup; a damaged one is left out.

        The backup is a hard link, or a copy where the file system has none (vfat).
        """
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return
        except (OSError, UnicodeDecodeError):
            return
        try:
            parse_state(text)
        except StateFormatError:
            return  # never back up a damaged file over a good backup
        link = self.path.with_name(f".{self.path.name}.bak.{os.getpid()}.tmp")
        with contextlib.suppress(FileNotFoundError):
            link.unlink()
        try:
            os.link(self.path, link)
        except OSError:  # e.g. vfat: no hard links
            _write_synced(link, text.encode("utf-8"))
        link.replace(self.backup)
        # rename() between two names of one file does nothing: after a writer killed
        # between linking the backup and replacing the file, both are one inode
        with contextlib.suppress(FileNotFoundError):
            link.unlink()

    def _fsync_dir(self) -> None:
        fd = os.open(self.path.parent, os.O_RDONLY | os.O_DIRECTORY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _write_synced(path: Path, data: bytes) -> None:
    """Create or truncate ``path`` (mode 0640), write ``data`` and fsync it."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o640)
    try:
        view = memoryview(data)
        while view:
            n = os.write(fd, view)
            view = view[n:]
        os.fsync(fd)
    finally:
        os.close(fd)


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one owned by another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def now_iso() -> str:
    """Wall-clock time for ``saved_at`` (UTC, seconds)."""
    return datetime.now(UTC).isoformat(timespec="seconds")
