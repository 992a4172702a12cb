"""What one UUT's learner and supervisor count: samples by reason, scores against the reference.

Shared by :mod:`emlogd.pipeline.learner` and :mod:`emlogd.pipeline.supervisor` (each adds
its own reasons) and read by the status, the replay and the dataset commands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class Counters:
    """Why samples were not learnt from (or not emitted), by reason."""

    learnt: int = 0
    out_of_range: int = 0
    backlog: int = 0
    gated_raw: int = 0
    gated_ref: int = 0
    no_heading: int = 0
    uut_fault: int = 0
    relearn: int = 0
    reacquire: int = 0
    envelope: int = 0
    candidates_rejected: int = 0
    candidates_applied: int = 0
    fallbacks: int = 0
    changes: int = 0
    """The applied calibration withdrawn by change detection."""
    uut_stalled: int = 0
    """Readings far below the speed the reference implies (a stalled wheel): not learnt."""

    def as_dict(self) -> dict[str, int]:
        """Plain types."""
        return dict(self.__dict__)


@dataclass(slots=True)
class Score:
    """Running sums of squared errors against the reference (replay's RMSE figures)."""

    n: int = 0
    ss_raw: float = 0.0
    ss_cor: float = 0.0

    def add(self, err_raw: float, err_cor: float) -> None:
        """One sample's errors (reading − reference), m/s."""
        self.n += 1
        self.ss_raw += err_raw * err_raw
        self.ss_cor += err_cor * err_cor

    @property
    def rmse_raw(self) -> float | None:
        """RMSE of the raw readings, m/s (None before any sample)."""
        return math.sqrt(self.ss_raw / self.n) if self.n else None

    @property
    def rmse_corrected(self) -> float | None:
        """RMSE of the emitted speeds, m/s."""
        return math.sqrt(self.ss_cor / self.n) if self.n else None
