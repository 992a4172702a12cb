"""The offline commands' reading of captures, each capture read once per test run.

``calibrate``, ``evaluate``, ``crossval`` and ``report`` each stream every capture they are
given through the daemon's pipeline (:func:`emlogd.offline.dataset.record_captures`),
and the tests run them again and again on the same shared trials and example captures.
:class:`ReadOnce` stands in for that function in :mod:`emlogd.offline.jobs` (the
commands' one way in): a capture already read with the same inputs gives a copy of its
:class:`~emlogd.offline.dataset.Recording`; any other is read. The key holds every input
the reading depends on: the path as given, a digest of the file's bytes (a capture
rewritten is read again), the UUT's settings as the reading uses them
(:func:`~emlogd.offline.dataset.record_capture` reads with ``learn`` off and no lag),
``strict`` and the reorder window. :class:`TwoAxisOnce` does the same for ``--axes 2``'s
reading (:func:`emlogd.offline.twoaxis.record_two_axis`, keyed on the file and the two
ports). Given a folder (:class:`Shelf`), what one process reads the run's other
processes (xdist's workers) load instead of reading it again. The tests of the readings
themselves call them directly and are not served from here.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import os
import pickle
from collections.abc import Callable, Hashable, Sequence
from pathlib import Path
from typing import Any, Generic, TypeVar

from drivers.io.capture import REORDER_WINDOW_S
from emlogd.offline import ProgressFn
from emlogd.offline.dataset import Recording
from emlogd.offline.twoaxis import TwoAxisRecording
from emlogd.pipeline.settings import UutSettings

ReadFn = Callable[..., list[Recording]]
""":func:`emlogd.offline.dataset.record_captures`' signature."""

Key = tuple[str, str, str, bool, float]

TwoAxisKey = tuple[str, str, str, str]

V = TypeVar("V")


class Shelf(Generic[V]):
    """Values by key, in memory and, given ``folder``, in a pickle per key there (written
    whole then renamed: a process reads a value whole or not at all; two processes that
    read the same capture at once both store it, the same).

    Args:
        kind: the values' type (a pickle of another type is refused).
        folder: where the run's processes share what they read (None: this process only).
    """

    def __init__(self, kind: type[V], folder: Path | None = None) -> None:
        self.kind = kind
        self.folder = folder
        self.mem: dict[Hashable, V] = {}

    def _file(self, key: Hashable) -> Path | None:
        if self.folder is None:
            return None
        return self.folder / (hashlib.sha256(repr(key).encode()).hexdigest()[:32] + ".pickle")

    def get(self, key: Hashable) -> V | None:
        """The value kept for ``key``, else None."""
        if key in self.mem:
            return self.mem[key]
        f = self._file(key)
        if f is None or not f.exists():
            return None
        value = pickle.loads(f.read_bytes())
        assert isinstance(value, self.kind), f
        self.mem[key] = value
        return value

    def put(self, key: Hashable, value: V) -> None:
        """Keep ``value`` for ``key``."""
        self.mem[key] = value
        f = self._file(key)
        if f is not None:
            f.parent.mkdir(parents=True, exist_ok=True)
            tmp = f.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(pickle.dumps(value))
            tmp.replace(f)


def _file(path: str | Path) -> tuple[str, str]:
    """The path as given (the recording names it), and a digest of the file's bytes."""
    return (str(path), hashlib.sha256(Path(path).read_bytes()).hexdigest())


class ReadOnce:
    """``record_captures`` with each capture read once per process (once per run given
    a folder).

    Args:
        read: the real ``record_captures``.
        folder: the :class:`Shelf`'s folder shared by the run's processes.
    """

    def __init__(self, read: ReadFn, folder: Path | None = None) -> None:
        self.read = read
        self.kept = Shelf(Recording, folder)
        self.reads = 0
        """Captures read (not served from :attr:`kept`)."""

    @staticmethod
    def key(path: str | Path, settings: UutSettings, strict: bool, reorder_s: float) -> Key:
        """What the reading of ``path`` depends on (see the module's docstring)."""
        used = dataclasses.replace(settings, learn=False, lag_s=0.0)
        return (*_file(path), repr(used), strict, reorder_s)

    def __call__(
        self,
        paths: Sequence[str | Path],
        settings: UutSettings,
        *,
        progress: ProgressFn | None = None,
        **options: Any,
    ) -> list[Recording]:
        """The recordings of ``paths`` in order, as ``record_captures`` gives them
        (``options``: its other keywords, passed on; ``strict`` and
        ``reorder_window_s`` are also keys)."""
        strict = bool(options.get("strict", False))
        reorder_s = float(options.get("reorder_window_s", REORDER_WINDOW_S))
        keys = [self.key(p, settings, strict, reorder_s) for p in paths]
        kept = [self.kept.get(k) for k in keys]
        missing = [i for i, rec in enumerate(kept) if rec is None]
        if missing:
            got = self.read([paths[i] for i in missing], settings, **options)
            self.reads += len(missing)
            for i, rec in zip(missing, got, strict=True):
                self.kept.put(keys[i], rec)
                kept[i] = rec
        for i, p in enumerate(paths):
            if progress is not None:
                progress(f"read {Path(p).name}", (i + 1) / len(paths))
        done = [copy.deepcopy(rec) for rec in kept if rec is not None]
        assert len(done) == len(paths)
        return done


class TwoAxisOnce:
    """``record_two_axis`` with each capture read once per process for the same ports
    (once per run given a folder).

    Args:
        read: the real ``record_two_axis``.
        folder: the :class:`Shelf`'s folder shared by the run's processes.
    """

    def __init__(
        self,
        read: Callable[[str | Path, str, str], TwoAxisRecording],
        folder: Path | None = None,
    ) -> None:
        self.read = read
        self.kept = Shelf(TwoAxisRecording, folder)
        self.reads = 0
        """Captures read (not served from :attr:`kept`)."""

    def __call__(self, path: str | Path, uut: str, reference: str) -> TwoAxisRecording:
        """The two-axis recording of ``path``, as ``record_two_axis`` gives it."""
        key: TwoAxisKey = (*_file(path), uut, reference)
        rec = self.kept.get(key)
        if rec is None:
            rec = self.read(path, uut, reference)
            self.kept.put(key, rec)
            self.reads += 1
        return copy.deepcopy(rec)
