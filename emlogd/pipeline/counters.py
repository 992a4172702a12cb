"""What one UUT's learner and supervisor count: samples by reason, scores against the reference.

Shared by :mod:`emlogd.pipeline.learner` and :mod:`emlogd.pipeline.supervisor` (each adds
its own reasons) and read by the status, the replay and the dataset commands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from calib.metrics import IMO_BOUND_RTOL, IMO_MEETS_FRACTION, ImoVerdict, imo_bound_one_mps


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
    over_range: int = 0
    """Readings above the configured range passed raw, neither corrected nor learnt
    (:meth:`~emlogd.pipeline.routing.UutRoute.over_range`)."""

    def as_dict(self) -> dict[str, int]:
        """Plain types."""
        return dict(self.__dict__)


@dataclass(slots=True)
class Score:
    """Running sums of squared errors against the reference (replay's RMSE figures), and
    the samples within the IMO A.824(19) bound (:func:`calib.metrics.imo_bound_one_mps`)."""

    n: int = 0
    ss_raw: float = 0.0
    ss_cor: float = 0.0
    imo_n: int = 0
    imo_raw: int = 0
    imo_cor: int = 0

    def add(self, err_raw: float, err_cor: float, ref_mps: float | None = None) -> None:
        """One sample's errors (reading − reference), m/s; with the reference's speed the
        sample counts towards the IMO verdict too."""
        self.n += 1
        self.ss_raw += err_raw * err_raw
        self.ss_cor += err_cor * err_cor
        if ref_mps is not None and math.isfinite(ref_mps):
            bound = imo_bound_one_mps(ref_mps) * (1.0 + IMO_BOUND_RTOL)
            self.imo_n += 1
            self.imo_raw += abs(err_raw) <= bound
            self.imo_cor += abs(err_cor) <= bound

    def imo(self) -> tuple[ImoVerdict, ImoVerdict]:
        """The IMO verdicts of the raw and of the emitted readings so far."""
        n = self.imo_n
        return (
            ImoVerdict(n, self.imo_raw, bool(n) and self.imo_raw >= IMO_MEETS_FRACTION * n),
            ImoVerdict(n, self.imo_cor, bool(n) and self.imo_cor >= IMO_MEETS_FRACTION * n),
        )

    @property
    def rmse_raw(self) -> float | None:
        """RMSE of the raw readings, m/s (None before any sample)."""
        return math.sqrt(self.ss_raw / self.n) if self.n else None

    @property
    def rmse_corrected(self) -> float | None:
        """RMSE of the emitted speeds, m/s."""
        return math.sqrt(self.ss_cor / self.n) if self.n else None
