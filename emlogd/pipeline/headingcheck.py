"""Is a UUT's heading consistent with the GNSS course over ground?

With a heading ψ, a speed through the water ``u`` (the log's) and a ground velocity ``V``
(GNSS speed and course), the current the heading implies is ``V − u·(cos ψ, sin ψ)``.
Leeway and a real current explain a few tenths of a m/s up to the envelope's
``max_current_mps``; a heading 180° wrong implies about twice the speed through the
water, and one 90° wrong about √2 times it — turning with the boat, which a current
never does. A heading whose implied current exceeds ``max_current_mps`` + 3σ of the
GNSS speed in most of the GNSS samples over :data:`WINDOW_S` is *suspect*: the pipeline
then does not use it for the water frame (no current is learnt with it, no GNSS
speed is projected with it) and says so in the UUT's status, until the samples over
a window agree again.

No I/O, no clock: times come with the data.
"""

from __future__ import annotations

import math
from collections import deque

WINDOW_S = 120.0
"""The window the heading is judged over, s ("for minutes")."""

MIN_SAMPLES = 30
"""GNSS samples a window needs before it is judged."""

BAD_FRACTION = 0.8
"""A heading is suspect when this fraction of a window's samples imply too strong a
current (and consistent again below half of it)."""

GNSS_SPEED_STD_MPS = 0.3
"""1σ noise of a GNSS ground velocity sample, m/s (as the fusion's)."""

MIN_STW_MPS = 0.5
"""Below this speed through the water a wrong heading implies no telling current."""


class HeadingCheck:
    """The consistency of one UUT's heading with the course over ground.

    Args:
        max_current_mps: the largest current (the envelope's), m/s.
    """

    __slots__ = ("_bad", "_samples", "bound_mps", "implied_mps", "suspect")

    def __init__(self, max_current_mps: float) -> None:
        self.bound_mps = max_current_mps + 3.0 * GNSS_SPEED_STD_MPS
        self._samples: deque[tuple[float, bool]] = deque()
        self._bad = 0
        """How many of :attr:`_samples` imply too strong a current (kept as they come and
        go: a GNSS flooding fixes makes the window long, and counting it per fix made
        each fix cost the whole window)."""
        self.suspect = False
        self.implied_mps: float | None = None
        """The current the last sample's heading implied, m/s."""

    def add(
        self, t: float, heading_deg: float, stw_mps: float, sog_mps: float, cog_deg: float
    ) -> None:
        """One GNSS fix with the heading and the log's speed through the water at its time."""
        if not all(math.isfinite(x) for x in (heading_deg, stw_mps, sog_mps, cog_deg)):
            return
        if stw_mps < MIN_STW_MPS:
            return
        psi, cog = math.radians(heading_deg), math.radians(cog_deg)
        cn = sog_mps * math.cos(cog) - stw_mps * math.cos(psi)
        ce = sog_mps * math.sin(cog) - stw_mps * math.sin(psi)
        self.implied_mps = math.hypot(cn, ce)
        s = self._samples
        too_strong = self.implied_mps > self.bound_mps
        s.append((t, too_strong))
        self._bad += too_strong
        while s and t - s[0][0] > WINDOW_S:
            self._bad -= s.popleft()[1]
        if len(s) < MIN_SAMPLES or t - s[0][0] < 0.5 * WINDOW_S:
            return
        bad = self._bad / len(s)
        if bad >= BAD_FRACTION:
            self.suspect = True
        elif bad < 0.5 * BAD_FRACTION:
            self.suspect = False

    def reason(self) -> str:
        """Why the heading is not used, or ``""``."""
        if not self.suspect:
            return ""
        implied = "" if self.implied_mps is None else f" (implies {self.implied_mps:.1f} m/s)"
        return (
            f"heading disagrees with the course over ground{implied}: beyond a current of "
            f"{self.bound_mps:.1f} m/s for {WINDOW_S:g} s"
        )
