"""The heading behind an offline calibration: refused when wrong, and the cause named
when no sample could be paired.

A GNSS reference (and the current states) needs the heading: the ground speed is
projected on the hull with it. Each :class:`~emlogd.offline.dataset.Recording` carries
the pipeline's heading status (``Pipeline.heading_status``: the variation used and
where it came from, the magnetic headings refused for want of one, the
heading-against-course check of :mod:`emlogd.pipeline.variation`). From it:

- :func:`heading_refusal`: a heading the check flagged (its offset from the course
  through the water beyond what leeway explains) makes the calibration refuse, with
  the figures;
- :func:`why_no_sample`: when no reading has a reference, the cause — no reading of
  the log at all; no reference sample at all (a log without GNSS fixes); no heading; a magnetic heading without a
  variation; a reference too sparse for the alignment — and what helps.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from emlogd.offline.dataset import Recording
from emlogd.pipeline.align import MAX_GAP_CAP_S
from emlogd.pipeline.settings import UutSettings

GNSS_NEEDS = (
    "GNSS fixes with speed and course over ground: RMC, or VTG with GGA or ZDA for the "
    "time (in a CSV export, the Sog and Cog columns)"
)
"""What a GNSS reference is made of, as the error names it when none arrived."""


def needs_heading(settings: UutSettings) -> bool:
    """Whether the reference or the model needs the heading."""
    return settings.current or settings.reference_field == "gnss"


def heading_refusal(recs: Sequence[Recording], settings: UutSettings) -> str | None:
    """Why the heading must not be used (the check flagged it), or None."""
    if not needs_heading(settings):
        return None
    for r in recs:
        check = r.heading_info.get("check")
        if not isinstance(check, dict) or not check.get("flagged"):
            continue
        var = r.heading_info.get("variation_deg")
        source = r.heading_info.get("variation_source")
        used = f"; variation {var:+.1f}° from the {source}" if isinstance(var, float) else ""
        return (
            f"{r.name}: the heading disagrees with the course over ground by "
            f"{check['offset_deg']:+.1f}° on straight legs ({check['samples']} fixes over "
            f"{check['sectors']} heading sectors{used}), more than leeway explains "
            f"({check['max_offset_deg']:g}°): a magnetic heading taken as true (import with "
            "--heading-ref magnetic, or give --variation DEG) or a wrong compass; not calibrated"
        )
    return None


def why_no_sample(recs: Sequence[Recording], settings: UutSettings, lag_s: float) -> str:
    """The cause, and the option that helps, when no reading has a reference at ``lag_s``."""
    field = settings.reference_field
    head = f"no {settings.port} sample has a valid {settings.reference_port} reference"
    if not any(r.raw.size for r in recs):
        return (
            f"{head}: no {settings.uut_source} reading of the log arrived on port "
            f"{settings.port!r} at all (a speed log sends VHW or VBW; VLW's distances alone "
            "give no usable speed: in steps of 0.01 nm or more, a speed from them moves in "
            "steps of 0.3 m/s over a minute; a table needs its speed-through-water column)"
        )
    if field == "gnss" and not any(r.t_ref.size for r in recs):
        return f"{head}: no GNSS fix arrived at all; the calibration needs {GNSS_NEEDS}"
    if needs_heading(settings) and not any(r.heading_info.get("port") for r in recs):
        refused = sum(int(r.heading_info.get("refused_magnetic") or 0) for r in recs)  # type: ignore[call-overload]
        if refused:
            return (
                f"{head}: the heading is magnetic ({refused} headings refused) and no "
                "variation is known — none in the log, none configured, and no GNSS position "
                "and date for the model: pass --variation DEG (east positive)"
            )
        kinds = "HDT, HDG, HDM, THS, $PASHR, VHW, a DVL's"
        if field == "gnss":
            return (
                f"{head}: no heading arrived, and the GNSS reference is projected on the "
                f"hull with one ({kinds}): name its port with --heading PORT; a log without "
                "any heading (course over ground alone) cannot be calibrated against GNSS, "
                "since the current and the leeway are then not told from the log's error"
            )
        return (
            f"{head}: no heading arrived, and --current needs one ({kinds}): "
            "name its port with --heading PORT, or calibrate without --current"
        )
    valid = [r.t_ref[r.ok_ref] for r in recs]
    n = sum(int(v.size) for v in valid)
    if n == 0:
        hint = "" if field == "gnss" else " (a log with RMC fixes: --ref-field gnss)"
        return f"{head}: the reference field {field!r} has no valid sample{hint}"
    gaps = np.concatenate([np.diff(v) for v in valid if v.size > 1] or [np.zeros(0)])
    spacing = float(np.median(gaps)) if gaps.size else float("inf")
    if spacing > MAX_GAP_CAP_S:
        return (
            f"{head} at lag {lag_s:.2f} s: the reference is too sparse — {n} valid samples, "
            f"{spacing:.1f} s apart (median), and the alignment bridges at most "
            f"{MAX_GAP_CAP_S:g} s between a reading and each reference sample"
        )
    return f"{head} at lag {lag_s:.2f} s ({n} valid references, none near a reading)"
