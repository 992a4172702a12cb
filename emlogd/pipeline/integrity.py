"""Integrity monitoring: what may reach the autopilot, and what may be learnt.

The calibration is an integrity monitor as much as a filter. This module holds the
pieces, each with a reason a person understands (the per-UUT supervisor in
:mod:`emlogd.pipeline.uut` turns them into decisions, counters and status):

- :class:`Envelope` — the physical envelope of a calibration and of a corrected
  speed. A calibration outside it is never applied, persisted or loaded; a reading
  outside the sensor's range is refused; a corrected speed is clamped to it;
- :class:`UutHealth` — the speed log's own faults: a reading *stuck* (no change
  beyond quantisation for ``stuck_s`` while the reference moves, or block means that
  stay within a fraction of the reference's swing however noisy each reading is),
  *zero* while the reference says the vessel moves, or *stalled* (far below the
  reference at speed: gated from its first sample);
- :class:`JumpFilter` — a reference or heading sample that would need a physically
  impossible acceleration or turn rate since the last accepted one is a glitch; a
  new level held for ``confirm_s`` is accepted (after an outage the vessel may
  really be elsewhere);
- :class:`PairedWindow` — the RMS errors of the raw reading, the applied calibration
  and the previous one against the reference, over one forgetting window of the
  same samples: the figures behind "never worse than raw";
- :func:`emitted_speed` — the policy at low and out-of-range speeds;
- a log's reading at the output (:mod:`emlogd.pipeline.readings`): one that implies
  an acceleration no vessel makes, or that arrives faster than the log's own rate, is
  neither emitted nor learnt.

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

from calib.models import Params
from emlogd.pipeline.keys import key, number

QUANTUM_MPS = 0.006
"""A change of a reading smaller than this is quantisation, not motion (0.01 kn is
0.005 m/s: the two-decimal knots field of VHW/VBW)."""

STUCK_BLOCK_S = 10.0
"""The variance rule of :class:`UutHealth` compares means over blocks this long, s."""

STUCK_SPREAD_RATIO = 0.25
"""A reading whose block means span less than this fraction of the span of the
reference's block means over ``stuck_s`` is stuck (a working log follows the reference
with a gain of at least 0.5: the envelope's scale), however noisy each reading is. The
reading's span is taken one resolution wider than it is: a log that reads in tenths of a
knot and repeats its reading can hide a change of up to one step in its block means (a
yacht holding 5.8 kn reads 5.8 and 5.9 while the GNSS speed's 10-s means span 0.33 m/s
of noise), so a span of one step is no evidence of a stuck log."""

STUCK_MAX_TURN_DEG = 15.0
"""The variance rule needs the heading steady within this over ``stuck_s``, °: in a
turn the current's projection moves the reference while the speed through the water
stays put."""

STALL_FRACTION = 0.5
"""A reading below this fraction of the reference speed is stalled (a paddle wheel that
stopped turning): neither learnt from nor validated, from its first sample. A following
current faster than the water speed also gives it; such samples are then only skipped."""

STALL_MIN_REF_MPS = 0.5
"""The stall rule applies while the reference is at least this fast, m/s."""

ZERO_MPS = 2.0 * QUANTUM_MPS
"""A reading within this of zero is a log reading zero (:meth:`UutHealth.stalled`): below
its threshold a log reads 0.00 (a dead band), which says that it does not measure, not
that the water is still. Against a reference that shows the vessel moving such a
reading is neither learnt from nor validated, from its first sample, at any speed the
learner learns at: a dead band of 0.5 m/s left the readings between the learning speed
and :data:`STALL_MIN_REF_MPS` in the fit, each 0.3–0.5 m/s off, every time a vessel
stopping and starting crossed it."""


@dataclass(frozen=True, slots=True)
class Envelope:
    """The physical envelope of a calibration and of the speeds it produces.

    Attributes:
        max_abs_m: largest |m| (a log reading 50 % off is broken, not calibrated).
        max_abs_b_mps: largest |b|, m/s: where the scale is held (not determined), the
            bias also takes the scale's error at the speeds seen, so the bound is the
            scale's at a typical speed (0.5 at 2 m/s).
        max_abs_a_spm: largest |a|, s/m.
        max_current_mps: largest current magnitude, m/s.
        max_speed_mps: the sensor's range: a reading above it goes out raw, neither
            corrected nor learnt (refused beyond twice it: ``routing.OVER_RANGE_FACTOR``),
            a corrected speed is clamped to it, and the inverse model must be monotonic without
            saturating over ``[0, max_speed_mps]``.
    """

    max_abs_m: float = 0.5
    max_abs_b_mps: float = 1.0
    max_abs_a_spm: float = 0.1
    max_current_mps: float = 3.0
    max_speed_mps: float = key(
        8.0,
        check=number(0.0, 50.0, lo_open=True),
        unit="m/s",
        doc=(
            "The sensor's range: a reading above it goes out raw, not corrected nor learnt "
            "(refused beyond twice it), a corrected speed clamped."
        ),
    )

    def check(self, params: Params, current_mps: tuple[float, float] | None = None) -> str:
        """``""`` when the calibration is inside the envelope, else why not."""
        return self.check_values(params.a_spm, params.m, params.b_mps, current_mps)

    def check_values(
        self, a: float, m: float, b: float, current_mps: tuple[float, float] | None = None
    ) -> str:
        """:meth:`check` on the parameters' values (a filter's state, unbuilt)."""
        if not (math.isfinite(a) and math.isfinite(m) and math.isfinite(b)):
            return "parameters not finite"
        if abs(m) > self.max_abs_m:
            return f"scale m={m:+.3f} outside ±{self.max_abs_m:g}"
        if abs(b) > self.max_abs_b_mps:
            return f"bias b={b:+.3f} m/s outside ±{self.max_abs_b_mps:g} m/s"
        if abs(a) > self.max_abs_a_spm:
            return f"curvature a={a:+.4f} s/m outside ±{self.max_abs_a_spm:g} s/m"
        g = 1.0 + m
        vmax = self.max_speed_mps
        if g + 2.0 * a * vmax <= 0.0:
            return f"model not monotonic up to {vmax:g} m/s"
        if a < 0.0 and b - g * g / (4.0 * a) < vmax:
            return f"inverse model saturates below {vmax:g} m/s"
        if current_mps is not None:
            c = math.hypot(*current_mps)
            if not math.isfinite(c) or c > self.max_current_mps:
                return f"current {c:.2f} m/s above {self.max_current_mps:g} m/s"
        return ""


def emitted_speed(
    corrected_mps: float, raw_mps: float, low_speed_mps: float, max_mps: float
) -> float:
    """The speed sent to the autopilot for a corrected reading (the low-speed policy).

    Below ``low_speed_mps`` of raw reading the output follows the sensor: it blends
    from the raw reading (at half the threshold and below) to the corrected one (at
    the threshold), so a bias never turns a log at rest into phantom sternway or
    headway. The result is never above ``max_mps``, nor negative unless raw is (the
    sternway a log reads goes out as read).

    Args:
        corrected_mps: the corrected speed, m/s.
        raw_mps: the raw reading, m/s.
        low_speed_mps: the threshold, m/s (0 disables the blend).
        max_mps: the sensor's range, m/s.
    """
    out = corrected_mps
    if low_speed_mps > 0.0 and raw_mps < low_speed_mps:
        w = min(max((raw_mps - 0.5 * low_speed_mps) / (0.5 * low_speed_mps), 0.0), 1.0)
        out = w * corrected_mps + (1.0 - w) * raw_mps
    if not math.isfinite(out):
        return math.nan
    return min(max(out, min(raw_mps, 0.0)), max_mps)


class UutHealth:
    """A speed log's faults: stuck, or zero while the reference moves.

    A reading is *unchanged* while it stays within half the log's resolution of the
    value it had when it last moved (the resolution is learnt: the smallest non-zero
    step between consecutive readings, at least :data:`QUANTUM_MPS` — a log that reads
    in tenths of a knot steps by 0.05 m/s). The reference has *moved* when
    its smoothed value (10 s time constant, so that waves and GNSS noise do not count)
    has spanned ``ref_move_mps`` since then.

    Args:
        stuck_s: a reading unchanged this long while the reference moved is stuck, s.
        zero_s: a reading at zero this long while the reference is above
            ``moving_mps`` is a dead log, s. The fault lapses once no reference has
            shown the vessel moving for as long (a log at rest reads zero, and a GNSS
            speed below its minimum gives no reference at all).
        ref_move_mps: least change of the smoothed reference that proves motion, m/s.
        moving_mps: reference speed above which the vessel moves, m/s.
    """

    __slots__ = (
        "_anchor",
        "_blk",
        "_blocks",
        "_last",
        "_min_step",
        "_ref_hi",
        "_ref_lo",
        "_ref_s",
        "_t_anchor",
        "_t_moving",
        "_t_ref",
        "_t_zero",
        "_var_stuck",
        "fault",
        "moving_mps",
        "ref_move_mps",
        "resolution_mps",
        "stuck_s",
        "zero_s",
    )

    SMOOTH_S = 10.0

    def __init__(
        self,
        stuck_s: float = 60.0,
        zero_s: float = 10.0,
        ref_move_mps: float = 0.3,
        moving_mps: float = 0.5,
    ) -> None:
        self.stuck_s = stuck_s
        self.zero_s = zero_s
        self.ref_move_mps = ref_move_mps
        self.moving_mps = moving_mps
        self.resolution_mps = QUANTUM_MPS
        self._last = math.nan
        self._min_step = math.inf
        self._anchor = math.nan
        self._t_anchor = 0.0
        self._ref_s = math.nan
        self._t_ref = 0.0
        self._ref_lo = math.inf
        self._ref_hi = -math.inf
        self._t_zero: float | None = None
        self._t_moving = -math.inf
        self._blk = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        """The block being summed: start time, n, Σ raw, n with a reference, Σ reference,
        n with a heading, Σ cos, Σ sin."""
        self._blocks: deque[tuple[float, float, float]] = deque(
            maxlen=max(2, math.ceil(stuck_s / STUCK_BLOCK_S))
        )
        self._var_stuck = False
        self.fault = ""
        """The current fault: ``""``, ``"uut_stuck"`` or ``"uut_zero"``."""

    def update(
        self, t: float, raw_mps: float, ref_mps: float | None, heading_deg: float | None = None
    ) -> str:
        """Add one reading (and the reference and heading at its time, if valid); return
        the fault."""
        d = abs(raw_mps - self._last)
        if d > 1e-6:
            self._min_step = min(self._min_step, d)
            self.resolution_mps = max(QUANTUM_MPS, self._min_step)
        self._last = raw_mps
        if not abs(raw_mps - self._anchor) < 0.5 * self.resolution_mps:
            self._anchor = raw_mps
            self._t_anchor = t
            self._ref_lo, self._ref_hi = math.inf, -math.inf
        if ref_mps is not None:
            if math.isnan(self._ref_s):
                self._ref_s = ref_mps
            else:
                a = min(max(t - self._t_ref, 0.0) / self.SMOOTH_S, 1.0)
                self._ref_s += a * (ref_mps - self._ref_s)
            self._t_ref = t
            self._ref_lo = min(self._ref_lo, self._ref_s)
            self._ref_hi = max(self._ref_hi, self._ref_s)
        self._variance(t, raw_mps, ref_mps, heading_deg)
        at_zero = abs(raw_mps) <= ZERO_MPS
        if ref_mps is not None and ref_mps > self.moving_mps:
            self._t_moving = t
        if (
            not at_zero
            or (ref_mps is not None and ref_mps <= self.moving_mps)
            or t - self._t_moving > self.zero_s
        ):
            # a zero reading is evidence only while a reference shows the vessel moving
            self._t_zero = None
        elif ref_mps is not None and self._t_zero is None:
            self._t_zero = t
        if self._t_zero is not None and t - self._t_zero >= self.zero_s:
            self.fault = "uut_zero"
        elif (
            t - self._t_anchor >= self.stuck_s and self._ref_hi - self._ref_lo >= self.ref_move_mps
        ) or self._var_stuck:
            self.fault = "uut_stuck"
        elif self.fault == "uut_stuck" and t > self._t_anchor:
            pass  # unchanged since the fault was declared: it stands until the reading moves
        else:
            self.fault = ""
        return self.fault

    def _variance(
        self, t: float, raw_mps: float, ref_mps: float | None, heading_deg: float | None
    ) -> None:
        """The variance rule: block means of the reading against the reference's."""
        b = self._blk
        if b[1] and t - b[0] >= STUCK_BLOCK_S:
            if b[3] >= 0.5 * b[1]:
                hdg = math.degrees(math.atan2(b[7], b[6])) if b[5] >= 0.5 * b[1] else math.nan
                self._blocks.append((b[2] / b[1], b[4] / b[3], hdg))
            else:
                self._blocks.clear()  # a stuck log must be seen against a moving reference
            b[:] = [t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            self._var_stuck = self._judge_spread()
        if not b[1]:
            b[0] = t
        b[1] += 1.0
        b[2] += raw_mps
        if ref_mps is not None:
            b[3] += 1.0
            b[4] += ref_mps
        if heading_deg is not None:
            psi = math.radians(heading_deg)
            b[5] += 1.0
            b[6] += math.cos(psi)
            b[7] += math.sin(psi)

    def _judge_spread(self) -> bool:
        blocks = self._blocks
        if len(blocks) < (blocks.maxlen or 0):
            return False
        h0 = blocks[0][2]
        for _, _, h in blocks:
            if math.isnan(h) != math.isnan(h0):
                return False
            if not math.isnan(h) and abs((h - h0 + 180.0) % 360.0 - 180.0) > STUCK_MAX_TURN_DEG:
                return False
        raws = [r for r, _, _ in blocks]
        refs = [v for _, v, _ in blocks]
        ref_span = max(refs) - min(refs)
        return ref_span >= self.ref_move_mps and max(raws) - min(raws) + self.resolution_mps < (
            STUCK_SPREAD_RATIO * ref_span
        )

    @staticmethod
    def stalled(raw_mps: float, ref_mps: float | None) -> bool:
        """A reading far below the reference at speed (:data:`STALL_FRACTION`), or at
        zero while the reference moves (:data:`ZERO_MPS`; the caller gives a reference
        only where it is valid, at or above the learning speed)."""
        if ref_mps is None:
            return False
        if abs(raw_mps) <= ZERO_MPS:
            return abs(ref_mps) > 2.0 * ZERO_MPS
        return ref_mps >= STALL_MIN_REF_MPS and raw_mps < STALL_FRACTION * ref_mps


class JumpFilter:
    """Refuses samples that would need an impossible rate of change; re-acquires a new level.

    Args:
        max_rate: the largest physical rate of change (m/s² for speeds, °/s for
            headings).
        margin: a change always allowed (noise, quantisation), in the series' unit.
        confirm_s: a new level that repeats for this long is accepted, s.
        angular: the series is an angle in degrees.
    """

    __slots__ = ("_last", "_pending", "angular", "confirm_s", "margin", "max_rate", "rejected")

    def __init__(
        self, max_rate: float, margin: float, confirm_s: float = 3.0, *, angular: bool = False
    ) -> None:
        self.max_rate = max_rate
        self.margin = margin
        self.confirm_s = confirm_s
        self.angular = angular
        self._last: tuple[float, float] | None = None
        self._pending: tuple[float, float, float] | None = None
        self.rejected = 0
        """Samples refused so far."""

    def _diff(self, a: float, b: float) -> float:
        d = a - b
        return abs((d + 180.0) % 360.0 - 180.0) if self.angular else abs(d)

    def accept(self, t: float, value: float) -> bool:
        """True when the sample is plausible (and becomes the last accepted one)."""
        last = self._last
        if last is None:
            self._last = (t, value)
            return True
        dt = t - last[0]
        d = value - last[1]
        if self.angular:
            d = (d + 180.0) % 360.0 - 180.0
        if abs(d) <= self.margin + self.max_rate * (0.0 if dt < 0.0 else dt):  # _diff, inline
            self._last = (t, value)
            self._pending = None
            return True
        pend = self._pending
        if pend is not None and self._diff(value, pend[2]) <= self.margin + self.max_rate * (
            t - pend[1]
        ):
            if t - pend[0] >= self.confirm_s:
                self._last = (t, value)
                self._pending = None
                return True
            self._pending = (pend[0], t, value)
        else:
            self._pending = (t, t, value)
        self.rejected += 1
        return False

    def reset(self) -> None:
        """Forget the last accepted sample (after an outage longer than any physics bound)."""
        self._last = None
        self._pending = None


class PairedWindow:
    """RMS errors of raw, applied and previous over the same samples, forgetting in time.

    Fixed memory: three forgotten sums of squares and one forgotten count, so the
    three figures are always compared on exactly the same samples.

    Args:
        half_life_s: time after which a sample's weight has halved, s.
    """

    __slots__ = ("_n", "_ss", "_t", "half_life_s")

    def __init__(self, half_life_s: float) -> None:
        self.half_life_s = half_life_s
        self._t: float | None = None
        self._ss = [0.0, 0.0, 0.0]
        self._n = 0.0

    def add(self, t: float, e_raw: float, e_applied: float, e_previous: float) -> None:
        """Add one sample's three errors at time ``t``, m/s."""
        if self._t is not None and t > self._t:
            lam = 0.5 ** ((t - self._t) / self.half_life_s)
            self._ss = [x * lam for x in self._ss]
            self._n *= lam
        self._t = t if self._t is None else max(t, self._t)
        ss = self._ss
        ss[0] += e_raw * e_raw
        ss[1] += e_applied * e_applied
        ss[2] += e_previous * e_previous
        self._n += 1.0

    @property
    def n_effective(self) -> float:
        """Effective number of samples in the window."""
        return self._n

    def rmse(self) -> tuple[float, float, float]:
        """(raw, applied, previous) RMS errors, m/s (nan when empty)."""
        if self._n <= 0.0:
            return math.nan, math.nan, math.nan
        r0, r1, r2 = (math.sqrt(x / self._n) for x in self._ss)
        return r0, r1, r2

    def reset(self) -> None:
        """Empty the window (the applied or previous calibration changed)."""
        self._t = None
        self._ss = [0.0, 0.0, 0.0]
        self._n = 0.0


def output_std(
    p: Params | None, std: Mapping[str, float | None], r_raw_mps2: float, speed_mps: float
) -> float:
    """The standard deviation of an emitted speed, m/s: the reading's noise
    (``r_raw_mps2``) through the scale of the applied calibration ``p``, plus its own σ
    ``std`` at that speed; raw passed through (``p`` None) counts with 10 % + 0.1 m/s.
    """
    if p is None:
        return math.sqrt(r_raw_mps2 + (0.1 * speed_mps) ** 2 + 0.01)
    u = abs(speed_mps)
    gain = p.a_spm * 2.0 * u + 1.0 + p.m
    var = r_raw_mps2 / max(gain * gain, 0.25)
    for name, x in (("a", u * u), ("m", u), ("b", 1.0)):
        sd = std.get(name)
        if sd is not None and math.isfinite(sd):
            var += (sd * x) ** 2 / max(gain * gain, 0.25)
    return math.sqrt(var)
