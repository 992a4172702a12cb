"""One speed through the water for the autopilot, from every healthy EMlog.

Each UUT's corrected speed comes with its standard deviation (:meth:`UutCalibration.
output_std`): the reading's noise through the calibration's scale, plus what the
calibration's own σ contributes at that speed; a log still uncalibrated counts with a
generous 10 % + 0.1 m/s. The fused speed is the inverse-variance weighted mean of the
latest corrected speed of each log heard within ``max_age_s``, so a log that falls
silent (a fault silences its output) drops out at once and the others carry on, and a
calibrated log outweighs an uncalibrated one. The fused σ is ``1/√(Σ 1/σᵢ²)``.

No I/O, no clock: times come with the data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class FusionSettings:
    """The fused output (``outputs.fused`` in the config).

    Attributes:
        only: send the fused speed instead of each log's corrected sentences (the
            status sentences and VDR still go out per log).
        talker: talker ID of the fused VHW.
        max_age_s: a log's latest speed counts this long, s.
        min_interval_s: at most one fused sentence this often, s.
    """

    only: bool = True
    talker: str = "II"
    max_age_s: float = 2.0
    min_interval_s: float = 0.1


@dataclass(frozen=True, slots=True)
class Fused:
    """A fused speed.

    Attributes:
        speed_mps: the weighted mean, m/s.
        std_mps: its standard deviation, m/s.
        sources: the logs that contributed, by weight (heaviest first).
    """

    speed_mps: float
    std_mps: float
    sources: tuple[str, ...]


class Fusion:
    """The latest corrected speed of each log and their weighted mean."""

    def __init__(self, settings: FusionSettings) -> None:
        self.s = settings
        self.latest: dict[str, tuple[float, float, float]] = {}
        self.t_last = -math.inf
        self.last: Fused | None = None

    def update(self, port: str, t: float, speed_mps: float, std_mps: float) -> Fused | None:
        """Record a log's corrected speed; the fused speed when one is due, else None."""
        if math.isfinite(speed_mps) and math.isfinite(std_mps) and std_mps > 0.0:
            self.latest[port] = (t, speed_mps, std_mps)
        if t - self.t_last < self.s.min_interval_s:
            return None
        fused = self.fuse(t)
        if fused is not None:
            self.t_last = t
            self.last = fused
        return fused

    def fuse(self, t: float) -> Fused | None:
        """The weighted mean of the speeds heard within ``max_age_s`` of ``t``."""
        live = [
            (1.0 / (std * std), v, port)
            for port, (t0, v, std) in self.latest.items()
            if 0.0 <= t - t0 <= self.s.max_age_s
        ]
        if not live:
            return None
        w = sum(x[0] for x in live)
        speed = sum(wi * v for wi, v, _ in live) / w
        order = tuple(p for _, _, p in sorted(live, key=lambda x: -x[0]))
        return Fused(speed, 1.0 / math.sqrt(w), order)
