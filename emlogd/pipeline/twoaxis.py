"""A two-axis log's VBW in the hull frame: its frozen installation figures applied.

A log that sends VBW measures on its own axes; turned by a misalignment α from the
bow it puts ``−sin α·u`` of the forward speed into the athwart one (phantom leeway).
The UUT's settings carry the figures ``emlogd calibrate --axes 2`` learns offline
(``misalign_deg``, ``transverse_scale``, ``transverse_bias_mps``): the forward
reading is corrected by the UUT's calibration in use (on the sensor's axis), the
athwart one by its scale and bias, and both are turned back by α
(:meth:`calib.twoaxis.TwoAxisParams.correct`'s rotation). No I/O, no clock.
"""

from __future__ import annotations

import math

from emlogd.pipeline.settings import UutSettings


def configured(s: UutSettings) -> bool:
    """Whether the UUT has two-axis figures (any of them not the aligned ideal's)."""
    return bool(s.misalign_deg or s.transverse_scale or s.transverse_bias_mps)


def hull_frame(s: UutSettings, forward_mps: float, athwart_mps: float) -> tuple[float, float]:
    """The speed through the water along and athwart the hull (+ starboard), m/s.

    Args:
        s: the UUT's settings (its two-axis figures).
        forward_mps: the forward reading corrected by the calibration in use, m/s.
        athwart_mps: the raw athwart reading, m/s.
    """
    ws = (athwart_mps - s.transverse_bias_mps) / (1.0 + s.transverse_scale)
    alpha = math.radians(s.misalign_deg)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return forward_mps * ca - ws * sa, forward_mps * sa + ws * ca
