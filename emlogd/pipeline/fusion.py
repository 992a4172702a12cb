"""One speed through the water for the autopilot, from the logs that agree — never a
silent average of logs that do not.

Each UUT's corrected speed comes with its standard deviation (:meth:`UutCalibration.
output_std`): the reading's noise through the calibration's scale, plus what the
calibration's own σ contributes at that speed; a log still uncalibrated counts with a
generous 10 % + 0.1 m/s. The fused speed is the inverse-variance weighted mean of the
latest corrected speed of each *used* log heard within ``max_age_s``, each σᵢ the
larger of its output σ and its own spread (the RMS of its speeds about its short-term
prediction over :data:`SCATTER_S`, steps included: a log alternating between two
values counts for little); the fused σ is ``1/√(Σ 1/σᵢ²)``. A log is left out, with a reason (:attr:`Fused.excluded`), when:

- ``accel``, ``rate``, ``reacquired``: one of its readings was implausible
  (:class:`~emlogd.pipeline.readings.ReadingCheck`: a dropout to 0, a spike, a babble)
  or it re-acquired a new level, within ``hold_s`` — from its first implausible
  sample on, while another log is there;
- ``stuck``: its speed has stayed within the quantum for :data:`FLAT_S` while another
  log's moved, or its :data:`~emlogd.pipeline.integrity.STUCK_BLOCK_S` means have
  spanned less than :data:`~emlogd.pipeline.integrity.STUCK_SPREAD_RATIO` of another
  live log's over :data:`STILL_S` while those moved at least :data:`MOVE_SPAN_MPS`
  without a step or an implausible reading in that time (a
  stuck log with a little noise: the variance rule of
  :class:`~emlogd.pipeline.integrity.UutHealth` with the other log as its reference;
  it stands until its own block means span that ratio of :data:`MOVE_SPAN_MPS`);
- ``still``: it is the one log left and nothing vouches for it — its UUT has no valid
  reference (whose checks would see it stuck), and no other still log was used beside
  it since it became still (two logs steady together vouch for each other) — and it
  is *still*: its block means over :data:`STILL_S` have stayed within
  :data:`STILL_SIGMAS` standard errors of a block mean (from the spread of its speeds
  within the blocks) and a quantum of each other, as a log stuck at one value with or
  without noise reads — or *flat*, within the quantum for :data:`FLAT_S`, and not used
  beside another log while flat that long. The fused output is then invalid: a stuck reading is not told
  from a steady speed by the log alone, and nothing else can tell. Still lasts until
  the block means spread beyond :data:`STILL_RELEASE_SIGMAS`, the log steps, or its
  speeds stop for a block;
- it loses a *dispute*: two logs disagree when their speeds' difference, smoothed over
  :data:`PAIR_SMOOTH_S`, is beyond ``gate_chi2`` in units of their consistency σ (the
  output σ of a calibrated log; the reading's noise and :data:`UNCALIBRATED_SCALE_STD`
  of the speed for an uncalibrated one — no 0.1 m/s floor, which would hide a log
  reading 1.8× at a slow speed). The dispute lasts until they agree for ``rejoin_s``.
  It is decided once, by the first rule that tells the two apart:

  1. ``gnss``: a GNSS speed over ground heard within :data:`GNSS_MAX_AGE_S` lies
     within ``max_current_mps`` (+ 3 × :data:`GNSS_SOG_STD_MPS`) of one log and not
     of the other;
  2. ``break``: one log had an implausible reading or re-acquired a level shortly
     before the dispute began (within ``hold_s`` + :data:`BREAK_MARGIN_S`) and the
     other did not — the log whose own history is unchanged is followed;
  3. ``stuck``: one log's speed has not moved beyond the quantum for :data:`FLAT_S`
     and the other's has;
  4. ``step``: like ``break``, one log *stepped* — a speed beyond :data:`STEP_SIGMA`
     times its own recent scatter from its own short-term prediction (a plausible jump
     all the same: 0.38 → 0.68 m/s at a slow speed) — and the other did not (neither
     being flat for :data:`STEP_GUARD_S`);
  5. ``minority``: one log is in more disputes than the other (three logs or more);
  6. ``uncalibrated``: one log has a validated calibration and the other none.

  Stillness decides no dispute: on a steady leg two healthy logs are both still or
  not by the colour of their noise, which tells nothing about which is right.

  A step resets the smoothed differences of the log's pairs to the present one, so a
  log that steps away from the others is in dispute from its first stepped sample.

  A dispute no rule decides makes the fused output *invalid*: a VHW without a speed
  and ``$PEMLF`` with status ``V`` and every disputed log excluded as ``disagree``.

No I/O, no clock: times come with the data.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from emlogd.pipeline.integrity import QUANTUM_MPS, STUCK_BLOCK_S, STUCK_SPREAD_RATIO

UNCALIBRATED_SCALE_STD = 0.1
"""The consistency σ of an uncalibrated log's speed, as a fraction of it (with the
reading's noise): two healthy logs of the same kind agree within a few per cent."""

PAIR_SMOOTH_S = 5.0
"""Time constant of the smoothed difference between two logs, s: the readings' noise
averages out (a few per cent of its variance stays), a persistent difference does not."""

GNSS_SOG_STD_MPS = 0.3
"""1σ noise of a GNSS speed over ground at a reading's time, m/s."""

GNSS_MAX_AGE_S = 3.0
"""A GNSS speed over ground arbitrates this long after it was heard, s."""

BREAK_MARGIN_S = 5.0
"""A log's break counts against it in a dispute that began within ``hold_s`` + this, s."""

FLAT_S = 10.0
"""A log whose speed stays within the quantum this long while another log's moves is
stuck, s: left out of the fused speed (and the loser of a dispute)."""

STEP_GUARD_S = 5.0
"""A step decides no dispute when either log has been flat this long, s: a log stuck for
less than :data:`FLAT_S` must not make the other's real change look like its fault."""

SELF_SMOOTH_S = 3.0
"""Time constant of a log's short-term prediction of its own speed (its smoothed speed), s."""

SCATTER_S = 60.0
"""Time constant of a log's scatter about its own prediction (the RMS residual), s."""

STEP_SIGMA = 4.0
"""A speed this many times the log's scatter from its own prediction is a step."""

STEP_FLOOR_MPS = 0.02
"""The least scatter a step is measured against, m/s (a flat log's scatter is nought)."""

STEP_WARMUP = 10
"""Speeds a log needs before its steps are judged."""

STILL_S = 60.0
"""A log's block means are judged for stillness over this long, s (the default
``stuck_s`` of a UUT's own stuck check)."""

STILL_SIGMAS = 5.0
"""A log whose block means span at most this many standard errors of a block mean
(plus a quantum) over :data:`STILL_S` is still: the span of six means of white noise
exceeds it about once in a hundred windows."""

STILL_RELEASE_SIGMAS = 8.0
"""A still log is still until its block means span more than this many standard errors
(plus a quantum): a stuck log's noise does not free it."""

MOVE_SPAN_MPS = 0.3
"""A log's block means spanning this much over :data:`STILL_S` show the vessel's speed
moved (the ``ref_move_mps`` of a UUT's own stuck check), m/s."""


@dataclass(frozen=True, slots=True)
class FusionSettings:
    """The fused output (``outputs.fused`` and ``outputs.fused_*`` in the config).

    Attributes:
        only: send the fused speed instead of each log's corrected sentences (the
            status sentences and VDR still go out per log).
        talker: talker ID of the fused VHW.
        max_age_s: a log's latest speed counts this long, s.
        min_interval_s: at most one fused sentence this often, s.
        gate_chi2: two logs whose smoothed difference, squared over the sum of their
            consistency variances, exceeds this disagree (6.63: 1 % for one degree of
            freedom).
        hold_s: a log with an implausible reading stays out this long, s.
        rejoin_s: two disputing logs agree again after agreeing this long, s.
        max_current_mps: the largest current: a log further than this (and the GNSS
            noise) from the speed over ground loses a dispute, m/s.
    """

    only: bool = True
    talker: str = "II"
    max_age_s: float = 2.0
    min_interval_s: float = 0.1
    gate_chi2: float = 6.63
    hold_s: float = 10.0
    rejoin_s: float = 30.0
    max_current_mps: float = 1.5


@dataclass(frozen=True, slots=True)
class Fused:
    """A fused speed.

    Attributes:
        speed_mps: the weighted mean, m/s (nan when invalid).
        std_mps: its standard deviation, m/s (nan when invalid).
        sources: the logs used, by weight (heaviest first); empty: invalid.
        excluded: the logs heard but left out, each with its reason.
    """

    speed_mps: float
    std_mps: float
    sources: tuple[str, ...]
    excluded: tuple[tuple[str, str], ...] = ()

    @property
    def valid(self) -> bool:
        """A speed was fused (some log is used)."""
        return bool(self.sources)


def consistency_std(std_mps: float, r_raw_mps: float, speed_mps: float, calibrated: bool) -> float:
    """The σ a log's speed is checked for consistency with: its output σ when calibrated,
    else the reading's noise and :data:`UNCALIBRATED_SCALE_STD` of the speed, m/s."""
    if calibrated:
        return std_mps
    return math.hypot(r_raw_mps, UNCALIBRATED_SCALE_STD * speed_mps)


class _Log:
    __slots__ = (
        "anchor",
        "blk",
        "blocks",
        "calibrated",
        "cstd",
        "level",
        "n",
        "referenced",
        "scatter2",
        "span",
        "spread2",
        "std",
        "still",
        "stuck",
        "t",
        "t_anchor",
        "t_break",
        "t_company",
        "t_step",
        "t_still",
        "t_vouched",
        "v",
        "why",
    )

    def __init__(self) -> None:
        self.t = -math.inf
        self.v = math.nan
        self.std = math.nan
        self.cstd = math.nan
        self.calibrated = False
        self.t_break = -math.inf
        self.why = ""
        self.anchor = math.nan
        self.t_anchor = -math.inf
        self.level = math.nan
        self.scatter2 = 0.0
        self.spread2 = 0.0
        """Mean square of every speed about the prediction, steps included."""
        self.n = 0
        self.t_step = -math.inf
        self.referenced = False
        self.blk = [0.0, 0.0, 0.0, 0.0]
        """The block being summed: start time, n, Σ speed, Σ speed²."""
        self.blocks: deque[tuple[float, float, float]] = deque(
            maxlen=math.ceil(STILL_S / STUCK_BLOCK_S)
        )
        """The closed blocks over :data:`STILL_S`: (mean, variance within, n)."""
        self.still = False
        self.stuck = False
        """Its block means stopped following another log's (the variance rule): it stands
        until they span :data:`STUCK_SPREAD_RATIO` of :data:`MOVE_SPAN_MPS`."""
        self.t_still = -math.inf
        """When the log last became still."""
        self.t_company = -math.inf
        """When the log was last used beside another log."""
        self.t_vouched = -math.inf
        """When the log was last used beside another still log (they vouch for each other)."""
        self.span = math.nan
        """The span of the block means over :data:`STILL_S` (nan until they are full), m/s."""

    def block(self, t: float, v: float) -> None:
        """Add a speed to the block means behind :attr:`still` and :attr:`span`; a gap of
        a block or more starts them afresh."""
        b = self.blk
        if b[1] and (t - self.t >= STUCK_BLOCK_S or t == self.t_step):
            self.blocks.clear()
            self.still, self.span = False, math.nan
            b[1] = 0.0
        elif b[1] and t - b[0] >= STUCK_BLOCK_S:
            mean = b[2] / b[1]
            self.blocks.append((mean, max(b[3] / b[1] - mean * mean, 0.0), b[1]))
            b[1] = 0.0
            self._judge(t)
        if not b[1]:
            b[:] = [t, 0.0, 0.0, 0.0]
        b[1] += 1.0
        b[2] += v
        b[3] += v * v

    def _judge(self, t: float) -> None:
        blocks = self.blocks
        if len(blocks) < (blocks.maxlen or 0):
            self.still, self.span = False, math.nan
            return
        means = [m for m, _, _ in blocks]
        self.span = max(means) - min(means)
        if self.span + QUANTUM_MPS >= STUCK_SPREAD_RATIO * MOVE_SPAN_MPS:
            self.stuck = False
        var = sum(w for _, w, _ in blocks) / len(blocks)
        se = math.sqrt(var / min(n for _, _, n in blocks))
        was = self.still
        self.still = self.span <= (STILL_RELEASE_SIGMAS if was else STILL_SIGMAS) * se + QUANTUM_MPS
        if self.still and not was:
            self.t_still = t

    def predict(self, t: float, v: float) -> bool:
        """Add a speed to the log's own prediction; True when it is a step."""
        if self.n == 0:
            self.level, self.n = v, 1
            return False
        r = v - self.level
        scatter = max(math.sqrt(self.scatter2), STEP_FLOOR_MPS)
        dt = max(t - self.t, 0.0)
        self.n += 1
        self.spread2 += max(min(dt / SCATTER_S, 1.0), 1.0 / self.n) * (r * r - self.spread2)
        if self.n > STEP_WARMUP and abs(r) > STEP_SIGMA * scatter:
            self.level = v
            self.t_step = t
            return True
        # a running mean until SCATTER_S worth of speeds, then forgetting
        self.scatter2 += max(min(dt / SCATTER_S, 1.0), 1.0 / self.n) * (r * r - self.scatter2)
        self.level += min(dt / SELF_SMOOTH_S, 1.0) * r
        return False

    def weight_std(self) -> float:
        """The σ the log's speed is weighted with: its output σ, or its own spread about
        its prediction when that is larger (a log alternating between two values)."""
        return max(self.std, math.sqrt(self.spread2))


class _Dispute:
    __slots__ = ("diff", "loser", "t", "t_agree", "t_onset", "why")

    def __init__(self, t: float, diff: float) -> None:
        self.t = t
        self.diff = diff
        self.t_onset: float | None = None
        self.t_agree: float | None = None
        self.loser: str | None = None
        self.why = ""


class Fusion:
    """The latest corrected speed of each log, their disputes, and the fused speed."""

    def __init__(self, settings: FusionSettings) -> None:
        self.s = settings
        self.logs: dict[str, _Log] = {}
        self.pairs: dict[tuple[str, str], _Dispute] = {}
        self.sog: tuple[float, float] | None = None
        self._stepped: set[str] = set()
        self.t_last = -math.inf
        self.last: Fused | None = None

    @property
    def latest(self) -> dict[str, tuple[float, float, float]]:
        """Each log's latest (time, speed, σ)."""
        return {p: (lg.t, lg.v, lg.std) for p, lg in self.logs.items() if lg.t > -math.inf}

    def adopt(self, old: Fusion) -> None:
        """Take over the logs, disputes and speed over ground of ``old`` (a reload)."""
        self.logs, self.pairs, self.sog = old.logs, old.pairs, old.sog

    def _log(self, port: str) -> _Log:
        lg = self.logs.get(port)
        if lg is None:
            lg = self.logs[port] = _Log()
        return lg

    def update(
        self,
        port: str,
        t: float,
        speed_mps: float,
        std_mps: float,
        *,
        cstd_mps: float | None = None,
        calibrated: bool = False,
        referenced: bool = False,
    ) -> Fused | None:
        """Record a log's corrected speed; the fused speed when one is due, else None.

        ``cstd_mps`` is its consistency σ (:func:`consistency_std`; default ``std_mps``);
        ``referenced``: its UUT has a valid reference now (which checks it is not stuck).
        """
        if math.isfinite(speed_mps) and math.isfinite(std_mps) and std_mps > 0.0:
            lg = self._log(port)
            if lg.predict(t, speed_mps):
                self._stepped.add(port)
            lg.block(t, speed_mps)
            lg.t, lg.v, lg.std = t, speed_mps, std_mps
            lg.cstd = cstd_mps if cstd_mps is not None and cstd_mps > 0.0 else std_mps
            lg.calibrated = calibrated
            lg.referenced = referenced
            if not abs(speed_mps - lg.anchor) <= QUANTUM_MPS:
                lg.anchor, lg.t_anchor = speed_mps, t
        if t - self.t_last < self.s.min_interval_s:
            return None
        fused = self.fuse(t)
        if fused is not None:
            self.t_last = t
            self.last = fused
        return fused

    def refuse(self, port: str, t: float, why: str) -> None:
        """A log's reading was implausible (or re-acquired a level): out for ``hold_s``."""
        lg = self._log(port)
        lg.t_break, lg.why = t, why

    def ground(self, t: float, sog_mps: float) -> None:
        """A valid GNSS speed over ground."""
        if math.isfinite(sog_mps):
            self.sog = (t, sog_mps)

    def fuse(self, t: float) -> Fused | None:
        """The fused speed at ``t`` from the logs heard within ``max_age_s``."""
        s = self.s
        live = {p: lg for p, lg in self.logs.items() if 0.0 <= t - lg.t <= s.max_age_s}
        if not live:
            return None
        out = {p: lg.why for p, lg in live.items() if t - lg.t_break < s.hold_s}
        stuck = self._stuck(t, live)
        out = {**stuck, **out}
        cand = sorted(p for p in live if p not in out)
        if not cand:  # every log had a recent implausible reading: the plausible ones
            out = {p: why for p, why in out.items() if p in stuck}
            cand = sorted(p for p in live if p not in stuck)
        if not cand:
            return Fused(math.nan, math.nan, (), tuple(sorted(out.items())))
        self._disputes(t, live, cand)
        losers: dict[str, str] = {}
        undecided: set[str] = set()
        for (a, b), d in self.pairs.items():
            if d.t_onset is None or a not in cand or b not in cand:
                continue
            if d.loser is None:
                d.loser, d.why = self._verdict(t, a, b, d.t_onset)
            if d.loser is None:
                undecided.update((a, b))
            else:
                losers[d.loser] = d.why
        if undecided:
            excluded = {**out, **dict.fromkeys(undecided, "disagree"), **losers}
            return Fused(math.nan, math.nan, (), tuple(sorted(excluded.items())))
        used = [(live[p].weight_std() ** -2, live[p].v, p) for p in cand if p not in losers]
        if not self._vouched(t, [live[p] for _, _, p in used]):
            out = {**out, **losers, used[0][2]: "still"}
            return Fused(math.nan, math.nan, (), tuple(sorted(out.items())))
        w = sum(x[0] for x in used)
        speed = sum(wi * v for wi, v, _ in used) / w
        order = tuple(p for _, _, p in sorted(used, key=lambda x: -x[0]))
        return Fused(speed, 1.0 / math.sqrt(w), order, tuple(sorted({**out, **losers}.items())))

    @staticmethod
    def _stuck(t: float, live: dict[str, _Log]) -> dict[str, str]:
        """The live logs left out as stuck: flat while another moves, or (the variance
        rule) block means that stopped following another's moving ones."""
        moving = [p for p, lg in live.items() if t - lg.t_anchor < FLAT_S]
        span = max(
            (
                lg.span
                for lg in live.values()
                if math.isfinite(lg.span) and t - max(lg.t_step, lg.t_break) > STILL_S
            ),
            default=0.0,
        )
        stuck: dict[str, str] = {}
        for p, lg in live.items():
            if t - lg.t_anchor >= FLAT_S and any(q != p for q in moving):
                stuck[p] = "stuck"
            elif lg.stuck or (
                span >= MOVE_SPAN_MPS and lg.span + QUANTUM_MPS < STUCK_SPREAD_RATIO * span
            ):
                lg.stuck = True
                stuck[p] = "stuck"
        return stuck

    @staticmethod
    def _vouched(t: float, used: list[_Log]) -> bool:
        """Whether the logs about to be fused may be: False for one log that nothing
        vouches for, still or flat since it was last used beside another; two or more
        still logs used together vouch for each other."""
        if len(used) == 1:
            lg = used[0]
            still = lg.still and lg.t_vouched < lg.t_still
            flat = t - lg.t_anchor >= FLAT_S and lg.t_company < lg.t_anchor + FLAT_S
            return lg.referenced or not (still or flat)
        for lg in used:
            lg.t_company = t
        if sum(1 for lg in used if lg.still) >= 2:
            for lg in used:
                if lg.still:
                    lg.t_vouched = t
        return True

    def _disputes(self, t: float, live: dict[str, _Log], cand: list[str]) -> None:
        """Update each candidate pair's smoothed difference and dispute state."""
        s = self.s
        for key in [k for k in self.pairs if k[0] not in live or k[1] not in live]:
            del self.pairs[key]
        for i, a in enumerate(cand):
            for b in cand[i + 1 :]:
                la, lb = live[a], live[b]
                diff = la.v - lb.v
                d = self.pairs.get((a, b))
                if d is None:
                    d = self.pairs[(a, b)] = _Dispute(t, diff)
                elif a in self._stepped or b in self._stepped:
                    d.diff, d.t = diff, t
                else:
                    k = min(max(t - d.t, 0.0) / PAIR_SMOOTH_S, 1.0)
                    d.diff += k * (diff - d.diff)
                    d.t = t
                z2 = d.diff**2 / (la.cstd**2 + lb.cstd**2)
                if z2 > s.gate_chi2:
                    if d.t_onset is None:
                        d.t_onset, d.loser, d.why = t, None, ""
                    d.t_agree = None
                elif d.t_onset is not None:
                    if d.t_agree is None:
                        d.t_agree = t
                    elif t - d.t_agree >= s.rejoin_s:
                        d.t_onset = d.t_agree = None
                        d.loser, d.why = None, ""
        self._stepped.clear()

    def _verdict(self, t: float, a: str, b: str, t_onset: float) -> tuple[str | None, str]:
        """Which of two disputing logs to leave out, and why (None: no rule decides)."""
        s = self.s
        la, lb = self.logs[a], self.logs[b]
        sog = self.sog
        if sog is not None and 0.0 <= t - sog[0] <= GNSS_MAX_AGE_S:
            bound = s.max_current_mps + 3.0 * GNSS_SOG_STD_MPS
            oa, ob = abs(la.v - sog[1]) > bound, abs(lb.v - sog[1]) > bound
            if oa != ob:
                return (a if oa else b), "gnss"
        since = t_onset - s.hold_s - BREAK_MARGIN_S
        ba, bb = since <= la.t_break <= t_onset, since <= lb.t_break <= t_onset
        if ba != bb:
            return (a if ba else b), "break"
        fa, fb = t - la.t_anchor >= FLAT_S, t - lb.t_anchor >= FLAT_S
        if fa != fb:
            return (a if fa else b), "stuck"
        sa, sb = since <= la.t_step <= t_onset, since <= lb.t_step <= t_onset
        both_moving = max(t - la.t_anchor, t - lb.t_anchor) < STEP_GUARD_S
        if sa != sb and both_moving:
            return (a if sa else b), "step"
        na = sum(1 for k, d in self.pairs.items() if a in k and d.t_onset is not None)
        nb = sum(1 for k, d in self.pairs.items() if b in k and d.t_onset is not None)
        if na != nb:
            return (a if na > nb else b), "minority"
        if la.calibrated != lb.calibrated:
            return (b if la.calibrated else a), "uncalibrated"
        return None, ""
