"""How far a change of the readings re-opens the learner's parameters.

When the supervisor's change detector withdraws a calibration
(:mod:`emlogd.pipeline.detector`), the learner (:mod:`emlogd.pipeline.learner`) re-opens
its parameters by the size of the change, as far as its own recent raw innovations
measure it (:class:`ChangeWindow`), and by no more (:func:`widen`):

- Learning sample by sample (a DVL), the change ``δ`` is the mean raw innovation over
  :data:`CHANGE_WINDOW_S` against the learner's estimate and current (which fitted the
  readings before): what a changed sensor would have to explain at the speed ``v``. Each
  parameter's variance grows by that change alone (``δ²`` for the bias, ``(δ/v)²`` for
  the scale, ``(δ/v²)²`` for the quadratic term), up to its prior: a 35 % gain step at
  2 m/s re-opens the scale to σ 0.3, an alarm the sea raised leaves hours of learning as
  they were. Without :data:`CHANGE_MIN_SAMPLES` innovations the parameters re-open to
  their prior.
- Learning from block means (a noisy reference: a block's innovation is one draw of a
  noise of 0.3 m/s correlated over tens of seconds), the change is the largest mean raw
  innovation over the last ``k`` blocks (``k`` = 1 … :data:`CHANGE_BLOCKS`, a step inside
  them shows in the blocks since it), its square taken with the variance of that mean
  added (``δ_k² + S̄/k``): the noise can hide a change that large. The learner's filter
  widens by that much, so its σ and NIS still say what the readings before the change
  taught (an alarm the sea raised on a 20-s mean is common); a shadow filter re-opened to
  the prior (:attr:`emlogd.pipeline.learner.Learner.shadow`) holds the offer until
  readings after the change determine the parameters again.

Nothing here reads a clock or does I/O; it must not import the learner or the supervisor.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

from calib.kalman import KfCalibrator

CHANGE_WINDOW_S = 10.0
"""A change of the readings is measured over the learner's raw innovations of this last
span, s: the supervisor's change detector alarms within a few samples of a step (3 on a
35 % gain step), and at 1 Hz ten samples hold the new level against the reference's noise."""

CHANGE_MIN_SAMPLES = 3
"""Fewer raw innovations than this in :data:`CHANGE_WINDOW_S`: the change cannot be
measured, and the parameters re-open to their prior."""

CHANGE_BLOCKS = 6
"""Learning from block means, a change is measured on the raw innovations of at most
this many last blocks (two minutes of 20-s means): a step inside them shows in the
mean of the blocks since it."""

CHANGE_BLOCKS_S = 300.0
"""Blocks older than this, s, do not measure a change (a sparse reference's blocks)."""


class ChangeWindow:
    """The learner's last raw innovations, what a change of the readings is measured on
    (module docstring)."""

    def __init__(self) -> None:
        self.recent: deque[tuple[float, float, float]] = deque()
        """(time, raw innovation, speed) of the last :data:`CHANGE_WINDOW_S` of readings
        with a valid reference."""
        self.blocks: deque[tuple[float, float, float, float]] = deque(maxlen=CHANGE_BLOCKS)
        """(time, raw innovation, its variance S, speed) of the last learnt blocks: what a
        change is measured on when learning from block means."""

    def add_sample(self, t: float, y: float, v: float) -> None:
        """One reading's raw innovation ``y`` (m/s) at the reference speed ``v`` (m/s)."""
        q = self.recent
        q.append((t, y, v))
        while q and t - q[0][0] > CHANGE_WINDOW_S:
            q.popleft()

    def add_block(self, t: float, y: float, s: float, v: float) -> None:
        """One block's raw innovation ``y`` (m/s), its variance ``s`` (m²/s²), at the
        block's mean speed ``v`` (m/s)."""
        q = self.blocks
        q.append((t, y, s, v))
        while q and t - q[0][0] > CHANGE_BLOCKS_S:
            q.popleft()

    def sample_change(self) -> tuple[float, float] | None:
        """The change ``δ`` and the speed it was measured at (m/s), learning sample by
        sample; the samples are used up. None (kept) when fewer than
        :data:`CHANGE_MIN_SAMPLES`: the parameters re-open to their prior."""
        q = self.recent
        if len(q) < CHANGE_MIN_SAMPLES:
            return None
        change = abs(sum(y for _, y, _ in q) / len(q)), sum(abs(x) for _, _, x in q) / len(q)
        q.clear()
        return change

    def block_change(self) -> tuple[float, float] | None:
        """The change ``δ`` and the speed it was measured at (m/s), learning from block
        means; the blocks are used up. None when there are none."""
        q = list(self.blocks)
        self.blocks.clear()
        if not q:
            return None
        worst, v_worst = 0.0, 0.0
        for k in range(1, len(q) + 1):
            last = q[-k:]
            mean = sum(y for _, y, _, _ in last) / k
            var = mean * mean + sum(s for _, _, s, _ in last) / (k * k)
            if var > worst:
                worst, v_worst = var, sum(v for _, _, _, v in last) / k
        return math.sqrt(worst), v_worst


def widen(kf: KfCalibrator, params: Sequence[str], delta: float, v: float) -> None:
    """Each parameter's variance grows by what a change ``delta`` (m/s) at ``v`` (m/s, at
    least the learner's minimum reference speed) would take of it alone."""
    per = {"b": delta * delta, "m": (delta / v) ** 2, "a": (delta / (v * v)) ** 2}
    kf.widen({name: per[name] for name in params})
