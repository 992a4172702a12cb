"""The offline commands' reading of captures, each capture read once per test process.

``calibrate``, ``evaluate``, ``crossval`` and ``report`` each stream every capture they are
given through the daemon's pipeline (:func:`emlogd.offline.dataset.record_captures`),
and the tests run them again and again on the same shared trials and example captures.
:class:`ReadOnce` stands in for that function in :mod:`emlogd.offline.jobs` (the
commands' one way in): a capture already read with the same inputs gives a copy of its
:class:`~emlogd.offline.dataset.Recording`; any other is read. The key holds every input
the reading depends on: the path as given, the file's identity and size and modification
time (a capture rewritten is read again), the UUT's settings as the reading uses them
(:func:`~emlogd.offline.dataset.record_capture` reads with ``learn`` off and no lag),
``strict`` and the reorder window. :class:`TwoAxisOnce` does the same for ``--axes 2``'s
reading (:func:`emlogd.offline.twoaxis.record_two_axis`, keyed on the file and the two
ports). The tests of the readings themselves call them directly and are not served
from here.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

from drivers.io.capture import REORDER_WINDOW_S
from emlogd.offline import ProgressFn
from emlogd.offline.dataset import Recording
from emlogd.offline.twoaxis import TwoAxisRecording
from emlogd.pipeline.settings import UutSettings

ReadFn = Callable[..., list[Recording]]
""":func:`emlogd.offline.dataset.record_captures`' signature."""

Key = tuple[str, int, int, int, int, str, bool, float]

TwoAxisKey = tuple[str, int, int, int, int, str, str]


def _file(path: str | Path) -> tuple[str, int, int, int, int]:
    """The path as given, and the file's identity, size and modification time."""
    st = Path(path).stat()
    return (str(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class ReadOnce:
    """``record_captures`` with each capture read once per process.

    Args:
        read: the real ``record_captures``.
    """

    def __init__(self, read: ReadFn) -> None:
        self.read = read
        self.kept: dict[Key, Recording] = {}
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
        workers: int | None = None,
        progress: ProgressFn | None = None,
        strict: bool = False,
        reorder_window_s: float = REORDER_WINDOW_S,
    ) -> list[Recording]:
        """The recordings of ``paths`` in order, as ``record_captures`` gives them."""
        keys = [self.key(p, settings, strict, reorder_window_s) for p in paths]
        missing = [i for i, k in enumerate(keys) if k not in self.kept]
        if missing:
            got = self.read(
                [paths[i] for i in missing],
                settings,
                workers=workers,
                strict=strict,
                reorder_window_s=reorder_window_s,
            )
            self.reads += len(missing)
            for i, rec in zip(missing, got, strict=True):
                self.kept[keys[i]] = rec
        for i, p in enumerate(paths):
            if progress is not None:
                progress(f"read {Path(p).name}", (i + 1) / len(paths))
        return [copy.deepcopy(self.kept[k]) for k in keys]


class TwoAxisOnce:
    """``record_two_axis`` with each capture read once per process for the same ports.

    Args:
        read: the real ``record_two_axis``.
    """

    def __init__(self, read: Callable[[str | Path, str, str], TwoAxisRecording]) -> None:
        self.read = read
        self.kept: dict[TwoAxisKey, TwoAxisRecording] = {}
        self.reads = 0
        """Captures read (not served from :attr:`kept`)."""

    def __call__(self, path: str | Path, uut: str, reference: str) -> TwoAxisRecording:
        """The two-axis recording of ``path``, as ``record_two_axis`` gives it."""
        key = (*_file(path), uut, reference)
        if key not in self.kept:
            self.kept[key] = self.read(path, uut, reference)
            self.reads += 1
        return copy.deepcopy(self.kept[key])
