"""The supervisor's own evidence: each calibration's current, the change detector, drift.

:mod:`emlogd.pipeline.supervisor` judges calibrations with these, never with the
learner's current:

- :class:`SeaMemory` — the last :data:`CURRENT_MEMORY_S` of scored samples, from which
  any calibration's own current is fitted (long memory: the current determined in the
  last turns carries through a straight leg);
- :class:`FitWindow` — squared errors of several calibrations, each after its own
  current (or mean error without current states) over a forgetting window, with the
  prediction and its leverage for a new sample;
- :class:`Cusum` — a two-sided CUSUM of normalised innovations, with the evidence an
  alarm is judged on; :class:`Course` and :func:`sea_jumped` — which series jumped at
  an alarm (the log, or the reference: the sea);
- :class:`Drift` — a log that drifts against a steady reference on a straight leg.

Must not import: serial, os, time, threading, socket (pure module).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calib.models import HeadingCS, Params, correct_array

FIT_CURRENT_PRIOR_MPS = 0.5
FIT_NOISE_MPS = 0.05
"""The current fit's prior: each component within about 0.5 m/s, against a sample's
error of about 0.05 m/s. It makes the fit's ridge, (0.05/0.5)² of one sample: a
component the headings seen do not determine stays near zero, and its uncertainty
widens the change detector's allowance when a turn reveals it."""

CURRENT_HALF_LIFE_S = 600.0
"""The half-life of the samples each calibration's own current is fitted on, s: long
enough to carry the current determined in the last turns through a straight leg (where
a current and an offset cannot be told apart), short enough to follow a tide."""

CURRENT_MEMORY_S = 3.0 * CURRENT_HALF_LIFE_S
"""The samples kept for those fits, s (older ones weigh less than 1/8)."""

MEMORY_INTERVAL_S = 0.5
"""The memory keeps at most one sample this often, s: a current fitted over half an
hour needs no more (a 10 Hz log would otherwise make each fit 20 times dearer for the
same answer: its samples' errors are correlated over seconds)."""

CUSUM_K = 1.5
"""The CUSUM's allowance, in innovation standard deviations per sample: a bias of the
innovation below it (a current the fit has not caught up with) never accumulates."""

CUSUM_H = 12.0
"""The CUSUM's alarm threshold, in innovation standard deviations: with
:data:`CUSUM_CLIP` a single outlier cannot reach it; a 10σ step does in three samples."""

CUSUM_CLIP = 7.0
"""A normalised innovation counts at most this much (one glitch is not a change)."""


CUSUM_MIN_SPAN_S = 10.0
"""The change detector's baseline (a :class:`FitWindow`) is judged on once it spans
this long, s, since it was last emptied (an alarm, a calibration applied or withdrawn).
Ten samples of a 5–10 Hz log are a second or two of errors correlated over seconds at
one heading: their spread understates the innovations' and the current fitted on them
is that moment's offset. In a turn in a current (its share along the hull changes by
up to 0.013 m/s a second at 3°/s in 0.25 m/s) such a baseline alarms again within
seconds, each alarm empties it, and an alarm of that cascade, judged against raw on a
run of a few samples, holds or withdraws a healthy calibration. Ten seconds is ten
samples of a 1 Hz log and 30° of a 3°/s turn."""


CUSUM_MAX_GAP_S = 60.0
"""After the scored samples (readings with their reference) fell silent for longer than
this, s (the reference or the log lost, captures minutes apart), the change detector
starts afresh: its baseline is another sea's (a current that moved 0.2 m/s over five
minutes is an innovation at once, and on a straight leg it cannot be told from an
offset of the log)."""


HOLD_SIGMAS = CUSUM_CLIP
"""An innovation of the applied calibration this many standard deviations out (the
CUSUM's clip: no single glitch counts for more) where the log jumped and the reference
did not (:meth:`Course.log_jumped`) holds it: raw passes through until the CUSUM run
it opened ends (back to zero: the calibration is emitted again) or its alarm is
decided (withdrawn, or the sea changed). A 20 % step of the log is such an innovation
at once, and the two samples the CUSUM needs to alarm on it go out raw, not corrected
for a sensor that is no longer there; a turn or a change of the sea moves the
reference and holds nothing (raw is the worse there)."""

SEA_STEP_SIGMAS = 7.0
"""At an alarm, a jump of the reference (where the innovation jumped, the log's own
less than it, :class:`Course`) of at least this many
innovation standard deviations is a change of the sea: the learner's current re-opens,
so that the jump goes into the current and not into the parameters. Smaller alarms
(a turn the detector's 60-s current has not caught up with) leave the learner as it
is."""

STEP_BEFORE_S = 5.0
"""The course of the corrected reading and of the reference before a CUSUM run is their
slope over this long, s (:func:`steps`)."""

STEP_SIGMAS = 4.0
"""A reading whose innovation is beyond :data:`HOLD_SIGMAS` holds the calibration when,
where the innovation jumped, the corrected reading's change is larger than the
reference's and more than this many times its own sample-to-sample scatter
(:meth:`Course.log_jumped`: one sample, all there is at a step's first reading)."""

SHIFT_WINDOW_S = 3.0
"""At an alarm, the means of the corrected reading, the reference and their difference
are compared over this long, s, each side of a split of the CUSUM run
(:func:`shift`): a sensor that changes shifts the mean of its error at once, a change
of the vessel's speed moves both series over seconds (the hull's response), and one
noisy sample of a 5–10 Hz log moves a mean little. A slower log's windows hold
:data:`SHIFT_MIN_SAMPLES` at its cadence (the run's median interval): 3 s holds one
reading of a 0.2–0.5 Hz log, and a step of it would never be seen as the sensor's."""

SHIFT_MIN_SAMPLES = 2
"""Each side of a split holds at least this many samples (one sample has no spread)."""

SHIFT_SIGMAS = 4.0
"""On an alarm that withdraws the calibration, the log jumped (the sensor changed, the
sea did not) when the mean of (corrected reading − reference) shifted at a split of the
run by at least this many standard errors of the difference of the two means, and the
reference's own mean moved by at most :data:`SHIFT_REFERENCE_SHARE` of the reading's
(:class:`Shift`); the calibration then re-validates in the sea as it stood before the
change. A shift within the error's scatter (a spike of the log, whose window's spread
it widens) tells nothing, and the calibration re-validates as any withdrawn one."""

SHIFT_REFERENCE_SHARE = 0.5
"""... the reference's mean step (less the vessel's acceleration before the run) at most
this share of the corrected reading's: a change of the speed moves both."""

STEP_MAX_GAP_S = 5.0
"""Consecutive samples further apart than this, s, do not count in the scatter."""

STEP_RUN_MAX = 1200
"""A CUSUM run keeps at most this many samples for :func:`steps` (two minutes at 10 Hz)."""


def sea_jumped(step_log: float, step_ref: float, sigma: float) -> bool:
    """At an alarm, the reference jumped (:func:`steps`) more than the log and by at
    least :data:`SEA_STEP_SIGMAS` innovation standard deviations ``sigma``: the sea
    changed at once."""
    return abs(step_ref) > abs(step_log) and abs(step_ref) >= SEA_STEP_SIGMAS * sigma


def steps(seq: Sequence[tuple[float, float, float]], first: int) -> tuple[float, float]:
    """Which series jumped where the innovation did, m/s: over the samples (time,
    corrected reading, reference) from ``first`` on (a CUSUM run; those before it, its
    course), the change of the corrected reading and of the reference between the two
    consecutive samples across which their difference changed most, each less its own
    slope over the samples before (the vessel's acceleration moves both alike).

    A sensor that changes moves the reading and leaves the reference; a current that
    changes, or a reference that jumps, moves the reference and leaves the reading.
    Zero for both when no sample of the run has one before it.
    """
    first = max(first, 1)
    if len(seq) <= first:
        return 0.0, 0.0
    a = np.asarray(seq, dtype=np.float64)
    t, corr, ref = a[:, 0], a[:, 1], a[:, 2]
    k = first + int(np.argmax(np.abs(np.diff(corr - ref)[first - 1 :])))
    dt = t[k] - t[k - 1]
    slope = _slopes(t, corr, ref, first)
    return (
        float(corr[k] - corr[k - 1] - slope[0] * dt),
        float(ref[k] - ref[k - 1] - slope[1] * dt),
    )


@dataclass(frozen=True)
class Shift:
    """The step of the window means at the split of a CUSUM run where (corrected reading
    − reference) shifted most (:func:`shift`), m/s; zero, with an infinite standard
    error, when the run has no split with :data:`SHIFT_MIN_SAMPLES` each side."""

    log_mps: float = 0.0
    """The corrected reading's mean step, less the vessel's acceleration before the run."""
    reference_mps: float = 0.0
    """The reference's, alike."""
    se_mps: float = math.inf
    """The standard error of the step of their difference."""

    @property
    def log_jumped(self) -> bool:
        """The sensor changed (:data:`SHIFT_SIGMAS`, :data:`SHIFT_REFERENCE_SHARE`)."""
        step = abs(self.log_mps - self.reference_mps)
        ref_small = abs(self.reference_mps) <= SHIFT_REFERENCE_SHARE * abs(self.log_mps)
        return step >= SHIFT_SIGMAS * self.se_mps and ref_small

    def detail(self, step_log: float, step_ref: float) -> dict[str, object]:
        """An alarm's log detail: the one-sample steps (:func:`steps`) and this shift."""
        return {
            "step_log_mps": round(step_log, 4),
            "step_reference_mps": round(step_ref, 4),
            "shift_log_mps": round(self.log_mps, 4),
            "shift_reference_mps": round(self.reference_mps, 4),
            "shift_se_mps": round(self.se_mps, 4) if math.isfinite(self.se_mps) else None,
        }


def _slopes(t: np.ndarray, corr: np.ndarray, ref: np.ndarray, first: int) -> tuple[float, float]:
    """The corrected reading's and the reference's slopes over the samples before the
    run (the vessel's acceleration), m/s²; zero with fewer than three."""
    if first >= 3 and t[first - 1] > t[0]:
        return (
            float(np.polyfit(t[:first], corr[:first], 1)[0]),
            float(np.polyfit(t[:first], ref[:first], 1)[0]),
        )
    return 0.0, 0.0


def shift(seq: Sequence[tuple[float, float, float]], first: int) -> Shift:
    """Where the mean of (corrected reading − reference) shifted most in a CUSUM run:
    over the samples (time, corrected reading, reference) from ``first`` on (those
    before it, its course), each split of the run between :data:`SHIFT_WINDOW_S` (or
    :data:`SHIFT_MIN_SAMPLES` median intervals, when longer) of
    samples before it and as long after it (at least :data:`SHIFT_MIN_SAMPLES` each);
    at the split whose difference's mean moved most, each series' step of its mean less
    its slope over the samples before the run times the windows' distance in time, and
    the standard error of the difference's step (the larger window's variance of the
    two over both counts: a spike in the few samples after a split widens it).
    """
    n = len(seq)
    if n < 2 * SHIFT_MIN_SAMPLES:
        return Shift()
    a = np.asarray(seq, dtype=np.float64)
    t, corr, ref = a[:, 0] - a[0, 0], a[:, 1], a[:, 2]
    d = corr - ref
    d = d - d[0]
    k = np.arange(max(first, SHIFT_MIN_SAMPLES), n - SHIFT_MIN_SAMPLES + 1)
    if not k.size:
        return Shift()
    span = max(SHIFT_WINDOW_S, SHIFT_MIN_SAMPLES * float(np.median(np.diff(t))))
    lo = np.searchsorted(t, t[k] - span, side="left")
    hi = np.searchsorted(t, t[k] + span, side="right")
    nb, na = k - lo, hi - k
    ok = (nb >= SHIFT_MIN_SAMPLES) & (na >= SHIFT_MIN_SAMPLES)
    if not ok.any():
        return Shift()
    k, lo, hi, nb, na = k[ok], lo[ok], hi[ok], nb[ok], na[ok]
    zero = np.zeros(1)
    cums = [np.concatenate((zero, np.cumsum(x))) for x in (t, corr, ref, d, d * d)]
    before = [(c[k] - c[lo]) / nb for c in cums]
    after = [(c[hi] - c[k]) / na for c in cums]
    sc, sr = _slopes(t, corr, ref, first)
    dt = after[0] - before[0]
    step_c = after[1] - before[1] - sc * dt
    step_r = after[2] - before[2] - sr * dt
    j = int(np.argmax(np.abs(step_c - step_r)))
    var_b = max(before[4][j] - before[3][j] ** 2, 0.0) * nb[j] / (nb[j] - 1)
    var_a = max(after[4][j] - after[3][j] ** 2, 0.0) * na[j] / (na[j] - 1)
    se = math.sqrt(max(var_b, var_a) * (1.0 / nb[j] + 1.0 / na[j]))
    return Shift(float(step_c[j]), float(step_r[j]), se)


class Course:
    """The applied calibration's corrected readings and references, the last
    :data:`STEP_BEFORE_S` before a CUSUM run and the run's, and the reading's
    sample-to-sample scatter (forgotten with ``half_life_s``): which series jumped at
    a reading (:func:`steps`, :meth:`log_jumped`) and at an alarm (:meth:`shift`)."""

    def __init__(self, half_life_s: float) -> None:
        self.half_life_s = half_life_s
        self.series: deque[tuple[float, float, float]] = deque()
        self.run_start = 0
        self.jitter = 0.0
        """The mean square of the corrected reading's change from one sample to the
        next, m²/s²: its noise and the vessel's motion."""

    def add(self, t: float, corr: float, ref: float, quiet: bool) -> None:
        """One sample; ``quiet``: the CUSUM stands at zero (no run)."""
        q = self.series
        if q:
            gap = t - q[-1][0]
            if 0.0 < gap <= STEP_MAX_GAP_S:
                lam = 0.5 ** (gap / self.half_life_s)
                d = corr - q[-1][1]
                self.jitter = lam * self.jitter + (1.0 - lam) * d * d
        q.append((t, corr, ref))
        if quiet:
            while q and q[0][0] < t - STEP_BEFORE_S:
                q.popleft()
            self.run_start = len(q)
        elif len(q) - self.run_start > STEP_RUN_MAX:
            q.popleft()
            self.run_start = max(self.run_start - 1, 0)

    def steps(self) -> tuple[float, float]:
        """The reading's and the reference's jump in the current run (:func:`steps`)."""
        return steps(self.series, self.run_start)

    def shift(self) -> Shift:
        """The means' step in the current run (:func:`shift`)."""
        return shift(self.series, self.run_start)

    def log_jumped(self, step_log: float, step_ref: float) -> bool:
        """The reading jumped more than the reference and beyond its own scatter
        (:data:`STEP_SIGMAS`)."""
        return abs(step_log) > abs(step_ref) and step_log**2 > STEP_SIGMAS**2 * self.jitter

    def reset(self) -> None:
        """Forget the samples (the scatter is the log's and stays)."""
        self.series.clear()
        self.run_start = 0


DRIFT_WINDOW_S = 120.0
"""The log's drift is judged over the last this long, s, of an unbroken run (a gap of
more than :data:`STEP_MAX_GAP_S` starts it again)."""

DRIFT_INTERVAL_S = 1.0
"""The drift window keeps at most one sample this often, s."""

DRIFT_MIN_MPS = 0.03
"""A drift counts when the reading changed by at least this over :data:`DRIFT_WINDOW_S`,
m/s, and its error against the reference too (the reading through the applied
calibration, in speed through water, so that a change of the vessel's speed moves it
with the reference and not by the log's gain times it; raw without one) ..."""

DRIFT_SIGMAS = 5.0
"""... each trend this many standard errors from zero (the scatter about it) ..."""

DRIFT_STEADY_MPS = 0.03
"""... while the reference changed by at most this, m/s, and by this much less than
the reading did ..."""

DRIFT_MAX_HEADING_SPREAD = 0.01
"""... on a straight leg: the heading's spread over the window (one minus the mean
resultant length of its unit vector) at most this (about ±8°). The vessel held its
speed and heading, so the current along the hull held too, and the log moved: a
fouling log on a straight run at constant speed, where no current the data determine
can tell a calibration learnt before the drift from raw (the current along the hull
takes any offset). A change of the speed moves the reference with the reading, one of
the current or of the heading in a current moves the reference alone. Once on, the
verdict stands while the error keeps its trend on the straight leg (the vessel may then
change its speed) and, after a gap, until a full window judges again."""


DRIFT_CONFIRM_S = 30.0
"""A drift withdraws the applied calibration once its verdict has held this long, s
(a quarter of :data:`DRIFT_WINDOW_S`: its trend held while a quarter of the window's
samples were replaced by new ones). On a straight leg one window cannot tell a log
that drifts from a vessel that slows in the water while the current along the hull
rises (the ground reference holds, the log follows the water): with the reading's
scatter such a window passes every test for a few seconds, while a fouling log's
trend goes on. While the verdict waits, candidates are kept out."""

DRIFT_ROWS = int(DRIFT_WINDOW_S / DRIFT_INTERVAL_S) + 1
"""The most samples a drift window holds (one each :data:`DRIFT_INTERVAL_S` at most)."""


class Drift:
    """The reading's and the reference's trends over :data:`DRIFT_WINDOW_S`: a log
    that drifts against a steady reference on a straight leg (:attr:`on`), for at least
    :data:`DRIFT_CONFIRM_S` (:attr:`sustained`).

    The window's samples (time, raw, reference, cos, sin) are rows of one array, read
    in place when judged; their times are also kept as floats, for the window's bounds.
    """

    def __init__(self) -> None:
        self.times: deque[float] = deque()
        """The times of the samples in the window, s."""
        self._rows = np.empty((2 * DRIFT_ROWS, 5))
        self._lo = 0
        self.on = False
        """The log drifts (the last window's verdict)."""
        self.change_mps = 0.0
        """The reading's error's change over the last window judged, m/s (through the
        calibration it was judged with)."""
        self.since = math.inf
        """The time the verdict came on, s (inf while off)."""
        self.sustained = False
        """The verdict has held :data:`DRIFT_CONFIRM_S` (the calibration is withdrawn)."""

    def add(self, t: float, raw: float, ref: float, cs: HeadingCS, p: Params | None = None) -> None:
        """One sample (kept when :data:`DRIFT_INTERVAL_S` after the last one kept);
        ``cs``: the heading (:data:`~calib.models.HeadingCS`); ``p``:
        the calibration applied, through which the window's readings are judged (None:
        the raw readings)."""
        q = self.times
        if q and t - q[-1] < DRIFT_INTERVAL_S:
            return
        if q and t - q[-1] > STEP_MAX_GAP_S:
            self.reset_window()  # the verdict stands until a full window after the gap judges again
        c, s = cs if cs is not None else (math.nan, math.nan)
        rows, n = self._rows, len(q)
        if self._lo + n == len(rows):  # the array's end: the window back to its start
            rows[:n] = rows[self._lo : self._lo + n]
            self._lo = 0
        rows[self._lo + n] = (t, raw, ref, c, s)
        q.append(t)
        while t - q[0] > DRIFT_WINDOW_S:
            q.popleft()
            self._lo += 1
        if t - q[0] >= DRIFT_WINDOW_S - 2.0 * DRIFT_INTERVAL_S:
            self._judge(p)

    def _judge(self, p: Params | None) -> None:
        n = len(self.times)
        a = self._rows[self._lo : self._lo + n]
        x = a[:, :3]
        if p is not None:
            # the readings in speed through water: a change of the vessel's speed moves
            # them with the reference, not by the log's gain times it
            speed = correct_array(p, a[:, 1])
            if bool(np.isfinite(speed).all()):
                x = x.copy()
                x[:, 1] = speed
        # the least-squares line of each series (reading − reference, reading,
        # reference) in time, from the window's sums about its first sample: one Gram
        # matrix
        d = x - x[0]
        (gtt, gtr, gtf), (_, grr, grf), (_, _, gff) = (d.T @ d).tolist()
        st, sr, sf = d.sum(axis=0).tolist()
        sxx = gtt - st * st / n
        sums = ((gtr - gtf, sr - sf, grr - 2.0 * grf + gff), (gtr, sr, grr), (gtf, sf, gff))
        slope, se = [0.0] * 3, [math.inf] * 3
        for k, (sty, sy, syy) in enumerate(sums):
            sxy = sty - st * sy / n
            if sxx > 0.0:
                slope[k] = sxy / sxx
                if n > 2:
                    rss = max(syy - sy * sy / n - slope[k] * sxy, 0.0)
                    se[k] = math.sqrt(rss / (n - 2) / sxx)
        span = float(d[-1, 0])
        change = [b * span for b in slope]
        self.change_mps = change[0]
        sc, ss = a[:, 3:5].sum(axis=0).tolist()  # NaN when a sample had no heading
        straight = math.isnan(sc) or (1.0 - math.hypot(sc / n, ss / n) <= DRIFT_MAX_HEADING_SPREAD)
        trend = [
            abs(change[k]) >= DRIFT_MIN_MPS and abs(slope[k]) >= DRIFT_SIGMAS * se[k]
            for k in range(3)
        ]
        ref = abs(change[2])
        onset = trend[1] and ref <= DRIFT_STEADY_MPS and abs(change[1]) >= ref + DRIFT_STEADY_MPS
        self.on = trend[0] and straight and (self.on or onset)
        now = float(a[-1, 0])
        self.since = min(self.since, now) if self.on else math.inf
        self.sustained = now - self.since >= DRIFT_CONFIRM_S

    def reset_window(self) -> None:
        """Forget the samples, not the verdict."""
        self.times.clear()
        self._lo = 0

    def reset(self) -> None:
        """Forget the samples."""
        self.reset_window()
        self.on = False
        self.since = math.inf
        self.sustained = False


class SeaMemory:
    """The last :data:`CURRENT_MEMORY_S` of scored samples (reading, reference, heading),
    from which any calibration's own current is fitted (:meth:`current`), back to the
    last silence longer than :data:`CUSUM_MAX_GAP_S` (:meth:`renew`)."""

    def __init__(self) -> None:
        cap = int(CURRENT_MEMORY_S / MEMORY_INTERVAL_S) + 64
        self.data = np.zeros((5, cap), dtype=np.float64)
        self.i = 0
        self.n = 0
        self.t_last = -math.inf
        self.t_renewed = -math.inf
        """When the memory last forgot a sea before a silence (:meth:`renew`), s."""

    def renew(self, t: float, young_s: float) -> bool:
        """Forget the samples before a silence longer than :data:`CUSUM_MAX_GAP_S` up to
        ``t``: they are another sea's (the change detector starts afresh there too), and
        a current fitted on them judges the calibrations in that sea. True for ``young_s``
        after that: a current fitted on the new sea's first samples is stale within
        seconds."""
        if self.n and t - self.t_last > CUSUM_MAX_GAP_S:
            self.i = self.n = 0
            self.t_renewed = t
        return t - self.t_renewed < young_s

    def add(self, t: float, raw: float, ref: float, cs: tuple[float, float]) -> None:
        """One sample (kept when :data:`MEMORY_INTERVAL_S` after the last one kept)."""
        if t - self.t_last < MEMORY_INTERVAL_S:
            return
        self.t_last = t
        cap = self.data.shape[1]
        self.data[:, self.i] = (t, raw, ref, cs[0], cs[1])
        self.i = (self.i + 1) % cap
        self.n = min(self.n + 1, cap)

    def current(self, p: Params | None, now: float) -> tuple[float, float]:
        """The β with ``p(raw) − ref ≈ β·(cos ψ, sin ψ)`` (β is minus the current)."""
        if not self.n:
            return 0.0, 0.0
        t, raw, ref, c, s = self.data[:, : self.n] if self.n < self.data.shape[1] else self.data
        w = np.exp2(-(now - t) / CURRENT_HALF_LIFE_S) * (now - t <= CURRENT_MEMORY_S)
        d = (raw if p is None else correct_array(p, raw)) - ref
        ok = np.isfinite(d)
        w, d, c, s = w[ok], d[ok], c[ok], s[ok]
        r = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2
        wc, ws = w * c, w * s
        a11 = float(wc @ c) + r
        a12 = float(wc @ s)
        a22 = float(ws @ s) + r
        b1, b2 = float(wc @ d), float(ws @ d)
        det = a11 * a22 - a12 * a12
        if det <= 0.0:
            return 0.0, 0.0
        return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det


@dataclass
class FitWindow:
    """Squared errors of several calibrations, each after its own best current.

    For calibration k and sample i, the error is ``d = p_k(raw) − ref``; in the water
    frame the window fits ``d ≈ −c·(cos ψ, sin ψ)`` for each k by ridge least squares
    (:data:`FIT_CURRENT_PRIOR_MPS`) and keeps the residual. Fixed memory: one 2×2 Gram matrix
    shared by all, and per calibration two cross-products and a sum of squares, all
    forgotten with ``half_life_s`` (None: kept).
    """

    k: int
    water: bool
    half_life_s: float | None = None

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Empty the window."""
        self.t: float | None = None
        self.t0: float | None = None
        """The first sample's time since the window was emptied, s."""
        self.n = 0.0
        self.a = [0.0, 0.0, 0.0]
        self.b = [[0.0, 0.0] for _ in range(self.k)]
        self.ss = [0.0] * self.k

    def add(self, t: float, cs: HeadingCS, errors: Sequence[float]) -> None:
        """One sample's errors (one per calibration) at time ``t``."""
        if self.half_life_s is not None and self.t is not None and t > self.t:
            lam = 0.5 ** ((t - self.t) / self.half_life_s)
            self.n *= lam
            self.a = [x * lam for x in self.a]
            for bk in self.b:
                bk[0] *= lam
                bk[1] *= lam
            self.ss = [x * lam for x in self.ss]
        self.t = t if self.t is None else max(t, self.t)
        self.t0 = t if self.t0 is None else self.t0
        self.n += 1.0
        c, s = self._h(cs)
        self.a[0] += c * c
        self.a[1] += c * s
        self.a[2] += s * s
        for i, d in enumerate(errors):
            self.b[i][0] += c * d
            self.b[i][1] += s * d
            self.ss[i] += d * d

    def _h(self, cs: HeadingCS) -> tuple[float, float]:
        """The regressors: the heading's (cos, sin) in the water frame, else a constant
        (without current states the window fits each calibration's mean error)."""
        return cs if cs is not None and self.water else (1.0, 0.0)

    def _solve(self, i: int) -> tuple[float, float]:
        r = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2
        a11, a12, a22 = self.a[0] + r, self.a[1], self.a[2] + r
        det = a11 * a22 - a12 * a12
        if det <= 0.0:
            return 0.0, 0.0
        b1, b2 = self.b[i]
        return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det

    def rmse(self, i: int) -> float:
        """Calibration i's RMS error after its own current, m/s (nan when empty)."""
        if self.n <= 0.0:
            return math.nan
        x1, x2 = self._solve(i)
        b1, b2 = self.b[i]
        return math.sqrt(max(self.ss[i] - (x1 * b1 + x2 * b2), 0.0) / self.n)

    def predict(self, i: int, cs: HeadingCS) -> float:
        """Calibration i's error its current (or mean error) predicts at a heading, m/s."""
        x1, x2 = self._solve(i)
        c, s = self._h(cs)
        return x1 * c + x2 * s

    def leverage(self, cs: HeadingCS) -> float:
        """``hᵀ(A + ridge)⁻¹h`` at a heading: how much of a new sample's error the
        current's uncertainty there may explain, in units of the sample variance."""
        r = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2
        a11, a12, a22 = self.a[0] + r, self.a[1], self.a[2] + r
        det = a11 * a22 - a12 * a12
        if det <= 0.0:
            return 0.0
        c, s = self._h(cs)
        return (a22 * c * c - 2.0 * a12 * c * s + a11 * s * s) / det

    def beta(self, i: int) -> tuple[float, float]:
        """Calibration i's fitted β, ``error ≈ β·(cos ψ, sin ψ)`` (minus its current)."""
        return self._solve(i)

    def current(self, i: int) -> tuple[float, float]:
        """Calibration i's fitted current (north, east), m/s."""
        x1, x2 = self._solve(i)
        return -x1, -x2


class Cusum:
    """A two-sided CUSUM of normalised innovations (:data:`CUSUM_K`, :data:`CUSUM_H`),
    with the squared errors of the applied calibration and of raw over each side's run
    (since that side last stood at zero): the evidence an alarm is judged on is the run
    of the side that alarmed. A step is judged on the samples after it, not on the
    other side's run of noise before it, over which raw's own offset would count
    against raw and a step of the sensor read as a change of the sea."""

    __slots__ = ("_ss", "hi", "lo", "run_app", "run_raw", "ss_app", "ss_raw")

    def __init__(self) -> None:
        self.hi = self.lo = 0.0
        self.ss_app = self.ss_raw = 0.0
        self._ss = [0.0, 0.0, 0.0, 0.0]
        """The squared errors of the applied calibration and of raw over the high
        side's run, then over the low side's."""
        self.run_app = self.run_raw = 0.0
        """The same over the whole run (since both sides last stood at zero)."""

    def add(self, z: float, e_app: float, e_raw: float) -> bool:
        """Add one normalised innovation and both errors; True on an alarm.

        :attr:`ss_app` and :attr:`ss_raw` are then the squared errors over the run of the
        side further from zero (the one that alarmed)."""
        ss = self._ss
        if self.hi == 0.0 and self.lo == 0.0:
            self.run_app = self.run_raw = 0.0
        if self.hi == 0.0:
            ss[0] = ss[1] = 0.0
        if self.lo == 0.0:
            ss[2] = ss[3] = 0.0
        z = min(max(z, -CUSUM_CLIP), CUSUM_CLIP)
        self.hi = max(0.0, self.hi + z - CUSUM_K)
        self.lo = max(0.0, self.lo - z - CUSUM_K)
        a2, r2 = e_app * e_app, e_raw * e_raw
        self.run_app += a2
        self.run_raw += r2
        if self.hi > 0.0:
            ss[0] += a2
            ss[1] += r2
        if self.lo > 0.0:
            ss[2] += a2
            ss[3] += r2
        side = 0 if self.hi >= self.lo else 2
        self.ss_app, self.ss_raw = ss[side], ss[side + 1]
        return self.hi > CUSUM_H or self.lo > CUSUM_H

    def reset(self) -> None:
        """Start again (the applied calibration changed)."""
        self.hi = self.lo = 0.0
        self.ss_app = self.ss_raw = 0.0
        self._ss = [0.0, 0.0, 0.0, 0.0]
        self.run_app = self.run_raw = 0.0
