"""The batch tools: captures read through the pipeline, calibrate/evaluate/crossval jobs,
import, replay, simulate, report, tables and the demo."""

from __future__ import annotations

from collections.abc import Callable

ProgressFn = Callable[[str, float], None]
"""A long job's progress: called with (what it is doing, the fraction done)."""
