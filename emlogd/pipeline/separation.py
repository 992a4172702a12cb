"""Whether a window tells raw from a calibration whatever the current: the re-validation
of a calibration withdrawn for cause (:mod:`emlogd.pipeline.supervisor`).

Were the calibration ``p`` right, the log would read ``p.forward(v)`` at the speed
through the water ``v``; were raw right, it would read ``v``. Against a ground
reference ``ref = v + c`` (``c`` the current along the hull, ``−β·(cos ψ, sin ψ)``) raw's
error ``d = raw − ref`` is then ``G + β'·(cos ψ, sin ψ)`` with ``G = p.forward(ref) − ref``
(for a linear model exactly: the current's share of ``p.forward`` is again linear in
the heading's cos and sin), or ``β·(cos ψ, sin ψ)``. Over a window,
:class:`Separation` fits ``d ≈ β·(cos ψ, sin ψ) + w·G`` by least squares with β free
(the ridge of :data:`~emlogd.pipeline.evidence.FIT_CURRENT_PRIOR_MPS`): ``w = 1`` is the
calibration right in some current, ``w = 0`` raw right in some current, and what tells
them apart is the part of ``G`` no current can make (a change of the speed, or a turn
that moves the current's share along the hull). ``G`` is computed from the reference,
not from the reading, so the reading's noise is in ``d`` alone. The reference's own
noise is in both: ``−e`` in ``d`` and about ``m·e`` in ``G`` (``m`` the calibration's
slope), which pulls a per-sample ``w`` towards ``−1/m`` (with a 0.1-m/s GNSS and
m −0.05, a right calibration's ``w`` reads 1.4 and raw's 0.4 where the speed swings by
±0.8 m/s). ``G`` therefore enters as its mean over each block of
:data:`SEPARATION_BLOCK_S`, over which that noise averages down while the changes of
speed and heading slower than a block, which separate the two, stay.
At one heading and one speed the current takes either one's offset and ``w`` is not
determined: the window then gives no verdict, whichever of them a guessed current would
favour.

No I/O, no clock.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from calib.models import Params, forward_array
from emlogd.pipeline.evidence import (
    CURRENT_HALF_LIFE_S,
    CUSUM_MAX_GAP_S,
    FIT_CURRENT_PRIOR_MPS,
    FIT_NOISE_MPS,
    SeaMemory,
)

SEPARATION_SIGMAS = 3.0
"""A window's verdict: the calibration is the better one when ``w`` is above ½ (the
reading nearer what it predicts than what raw does) by this many standard errors of
``w``; raw is the better one when ``w`` is below ½ by as many. Between, the window does
not tell them apart."""

SEPARATION_PLAUSIBLE = 0.5
"""A window does not re-apply the calibration when ``w`` is more than this above 1: its
errors are then neither raw's nor the calibration's in one current (a current that
changed over the window, a reference with errors of its own, a calibration too near raw
for its ``G`` to stand out), and ``w`` measures that, not that the calibration is right.
A ``w`` below ½ by :data:`SEPARATION_SIGMAS` refuses it however far below 0 (raw is then
the safe one). A ``w`` below 1 by as many (:meth:`Separation.partial`) says the window's
errors are a fraction of what the calibration predicts in any current: a part of the
log's error is neither (a bias in turns, which a current takes on a figure-8's headings,
with the speed dipping in each turn), and the RMSEs after currents fitted to that
window, which take that part, re-apply nothing."""

SEPARATION_SAMPLE_S = 1.0
"""A window counts at most one independent sample per this long, s, in the standard
error of ``w`` (a 5–10 Hz log's errors are correlated over about a second)."""

SEPARATION_BLOCK_S = 20.0
"""The standard error of ``w`` is also taken from the fit's residuals summed over blocks
of this long, s (the cluster-robust, "sandwich" variance with one cluster a block), and
the larger of the two counts: a GNSS reference's errors are correlated over about 20 s,
so that one sample a second overstates what a window knows many times over, while the
blocks' scatter measures it whatever the correlation within a block. ``G`` enters the
fit as its mean over each block (the module's docstring: the reference's noise in it)."""

SEPARATION_MIN_BLOCKS = 4
"""The blocks' standard error counts once the window holds this many blocks
(:data:`SEPARATION_BLOCK_S`): fewer give no estimate of their own scatter."""

SEPARATION_MEMORY_S = CURRENT_HALF_LIFE_S
"""A calibration the change detector withdrew where the log did not jump is judged on
the sea memory's samples of this long before the alarm as well, s (the same sensor: the
speeds and headings before it tell it from raw as well as those after; the current is
taken as one over it, as its own current is over :data:`CURRENT_HALF_LIFE_S`)."""

_RIDGE = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2


class Separation:
    """The least-squares fit ``d ≈ β·(cos ψ, sin ψ) + w·G`` over a window, by its sums
    per block of :data:`SEPARATION_BLOCK_S` (from which :meth:`_normal` builds each one's 3×3
    normal equations; a window holds as many blocks as it spans)."""

    __slots__ = ("_blocks", "_yy", "n", "t0", "t1")

    def __init__(self) -> None:
        self._blocks: dict[int, list[float]] = {}
        """Per block: its count and the sums of cos ψ, sin ψ, g and d, then of cc, cs, ss,
        cd and sd (:meth:`_normal` builds the block's normal equations over its mean g)."""
        self._yy = 0.0
        self.n = 0
        self.t0 = math.inf
        self.t1 = -math.inf

    def add(self, t: float, d: float, g: float, cs: tuple[float, float]) -> None:
        """One sample: raw's error against the reference and ``G``, m/s, and the
        heading's (cos, sin)."""
        if not (math.isfinite(d) and math.isfinite(g) and math.isfinite(t)):
            return
        c, s = cs
        key = math.floor(t / SEPARATION_BLOCK_S)
        a = self._blocks.get(key)
        if a is None:
            a = self._blocks[key] = [0.0] * 10
        a[0] += 1.0
        a[1] += c
        a[2] += s
        a[3] += g
        a[4] += d
        a[5] += c * c
        a[6] += c * s
        a[7] += s * s
        a[8] += c * d
        a[9] += s * d
        self._yy += d * d
        self.n += 1
        self.t0 = min(self.t0, t)
        self.t1 = max(self.t1, t)

    def _normal(self) -> npt.NDArray[np.float64]:
        """Per block the normal equations' sums over (cos ψ, sin ψ, Ḡ) (cc, cs, cg, ss,
        sg, gg), then the right-hand side (cd, sd, gd), with Ḡ the block's mean ``G``
        (:data:`SEPARATION_BLOCK_S`)."""
        b = np.array(list(self._blocks.values()))
        n, sc, ss_, sg, sd = b[:, 0], b[:, 1], b[:, 2], b[:, 3], b[:, 4]
        g = sg / n
        return np.column_stack(
            (b[:, 5], b[:, 6], g * sc, b[:, 7], g * ss_, g * g * n, b[:, 8], b[:, 9], g * sd)
        )

    def w(self) -> tuple[float, float]:
        """``w`` and its standard error (nan, inf when the window cannot give one)."""
        if self.n < 4:
            return math.nan, math.inf
        blocks = self._normal()
        cc, cs_, cg, ss, sg, gg, b0, b1, b2 = blocks.sum(axis=0).tolist()
        cc += _RIDGE
        ss += _RIDGE
        # the inverse of the symmetric 3×3 matrix by cofactors
        m00 = ss * gg - sg * sg
        m01 = cg * sg - cs_ * gg
        m02 = cs_ * sg - cg * ss
        det = cc * m00 + cs_ * m01 + cg * m02
        if not det > 0.0:
            return math.nan, math.inf
        m11 = cc * gg - cg * cg
        m12 = cg * cs_ - cc * sg
        m22 = cc * ss - cs_ * cs_
        beta_c = (m00 * b0 + m01 * b1 + m02 * b2) / det
        beta_s = (m01 * b0 + m11 * b1 + m12 * b2) / det
        w = (m02 * b0 + m12 * b1 + m22 * b2) / det
        rss = max(self._yy - (beta_c * b0 + beta_s * b1 + w * b2), 0.0)
        var = rss / (self.n - 3)
        n_eff = min(float(self.n), max((self.t1 - self.t0) / SEPARATION_SAMPLE_S, 1.0))
        se = math.sqrt(var * (m22 / det) * self.n / n_eff)
        n_blocks = blocks.shape[0]
        if n_blocks >= SEPARATION_MIN_BLOCKS:
            # each block's score (its residuals times the regressors) at the fit, and
            # their scatter through w's row of the inverse
            theta = (beta_c, beta_s, w)
            a = blocks[:, (0, 1, 2, 1, 3, 4, 2, 4, 5)].reshape(n_blocks, 3, 3)
            score = blocks[:, 6:9] - a @ np.asarray(theta)
            row = np.array((m02, m12, m22)) / det
            var_blocks = float(np.sum((score @ row) ** 2)) * n_blocks / (n_blocks - 1)
            se = max(se, math.sqrt(var_blocks))
        return w, se

    def verdict(self, detail: dict[str, object] | None = None) -> bool | None:
        """True: the calibration is the better one; False: raw is; None: the window does
        not tell them apart (:data:`SEPARATION_SIGMAS`). ``detail`` gets ``w`` and its
        standard error."""
        w, se = self.w()
        if detail is not None and math.isfinite(w):
            detail["separation_w"] = round(w, 3)
            detail["separation_se"] = round(se, 3)
        if not math.isfinite(se):
            return None
        if w + SEPARATION_SIGMAS * se <= 0.5:
            return False
        if w - SEPARATION_SIGMAS * se >= 0.5 and w <= 1.0 + SEPARATION_PLAUSIBLE:
            return True
        return None

    def partial(self) -> bool:
        """The window's ``w`` is below 1 by :data:`SEPARATION_SIGMAS` standard errors (see
        :data:`SEPARATION_PLAUSIBLE`)."""
        w, se = self.w()
        return math.isfinite(se) and w + SEPARATION_SIGMAS * se < 1.0

    def add_memory(self, mem: SeaMemory, p: Params, now: float) -> None:
        """The memory's samples of the last :data:`SEPARATION_MEMORY_S` up to ``now``, back
        to the first silence longer than :data:`~emlogd.pipeline.evidence.CUSUM_MAX_GAP_S`
        (another sea's beyond it)."""
        data = mem.data[:, : mem.n] if mem.n < mem.data.shape[1] else mem.data
        t, raw, ref, c, s = data[:, np.argsort(data[0])]
        keep = (t >= now - SEPARATION_MEMORY_S) & (t <= now)
        gaps = np.flatnonzero(np.diff(t) > CUSUM_MAX_GAP_S)
        if gaps.size:
            keep[: gaps[-1] + 1] = False
        g = forward_array(p, ref[keep]) - ref[keep]
        d = raw[keep] - ref[keep]
        for ti, di, gi, ci, si in zip(t[keep], d, g, c[keep], s[keep], strict=True):
            self.add(float(ti), float(di), float(gi), (float(ci), float(si)))
