"""A two-axis log's misalignment, transverse scale and bias learnt online (``axes: 2``).

A log that sends VBW (forward and athwart speed through the water) against a reference
with both horizontal axes (a DVL's bottom track: PD6 ``:BS``, PD0, PD4/PD5) learns the
installation figures of :mod:`calib.twoaxis`: the misalignment α, the transverse
scale ``m_t`` and bias ``b_t``. The one-axis learner keeps the forward axis; this one
shares its lag (the UUT's, once known) and its heading.

- Each VBW reading is paired with the reference's ground velocity forward and to
  starboard and the heading at ``t − lag`` (the alignment rule of
  :mod:`emlogd.pipeline.align`), and the pairs are averaged into block means of
  :data:`BLOCK_S` (the sway of a turn changes over tens of seconds; the DVL's and the
  log's 10 Hz noise averages out).
- The last :data:`WINDOW_S` of block means is kept (fixed memory) and fitted by the
  offline command's least squares (:func:`calib.twoaxis.fit_two_axis`, the current
  shared by both axes and linear between knots :data:`CURRENT_KNOT_S` apart) every
  :data:`FIT_EVERY_S`, once the window spans :data:`MIN_FIT_S`. The same
  identifiability rule decides (:mod:`calib.twoaxis_ident`): α is refused where the
  data cannot separate it — a straight run (the forward speed nearly constant), sway
  that follows the surge (the transverse scale not determined) — with the reason. A
  window whose cheap rules (spreads, heading sectors) already refuse α is not fitted.
  The rule's bound on α's σ (``max_std_misalign_deg``, 0.25°) holds for the σ the fit
  reports too, its residuals' correlation counted: a window the model does not fit
  (on a held-out trial with its DVL's bottom lost for minutes, every other fit of the
  figure-8 gave ±0.36–1.19°, 0.5–1.7° off, between fits at ±0.14–0.25° within 0.15°
  of the truth) is refused with that reason, and a noisier estimate never replaces
  the figures in use.
- An estimate that determines α, ``m_t`` and ``b_t`` is offered to the two-axis
  supervisor (:mod:`emlogd.pipeline.twoaxis_sup`), which applies it to the VBW only
  once its athwart speed is not worse than raw; a refusal keeps what was learnt. With
  it go the fit's longitudinal parameters when it determined them all, which the
  supervisor lets correct the forward speed once that is not worse than the one-axis
  calibration's nor raw's (a VHW reading, which has no athwart speed, takes the
  athwart reading of the VBW before it, within :data:`ATHWART_FRESH_S`); each reading
  then goes out by whichever of the two has the smaller expected error
  (:func:`emlogd.pipeline.twoaxis_sup.one_axis_better`, weighed on the readings of the
  last :data:`~emlogd.pipeline.twoaxis_sup.CHOICE_S` up to it,
  :class:`~emlogd.pipeline.twoaxis_sup.ForwardChoice`), with the
  reading's noise measured as the scatter of the readings inside the last
  :data:`NOISE_BLOCKS` blocks.

A fit of a full window costs about 0.2 s of CPU with one BLAS thread (on a loaded
machine a multi-threaded BLAS took seconds: ``OPENBLAS_NUM_THREADS=1`` suits the
daemon); whoever feeds the pipeline reads nothing meanwhile.

No I/O, no clock: times come with the data.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from calib.errors import CalibrationError
from calib.models import check_model
from calib.twoaxis import (
    ALPHA,
    B_T,
    DEFAULT_TWO_AXIS_RULE,
    M_T,
    TwoAxisFit,
    TwoAxisSeries,
    fit_two_axis,
    judge_two_axis,
)
from drivers.framing import with_checksum
from emlogd.pipeline.align import SampleRing
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.integrity import emitted_speed
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.twoaxis_sup import (
    NO_GUARD,
    Block,
    Figures,
    ForwardChoice,
    Guard,
    TwoAxisSupervisor,
    lon_of_fit,
    noise_gain,
)

BLOCK_S = 1.0
"""The block means the window holds, s (a 27-minute figure-8 in 1-s blocks gives the
offline command's α, 3.25 ± 0.14° for 3°, in a fifth of a second of CPU)."""
WINDOW_S = 1800.0
"""The window fitted, s: the longest manoeuvre that determines α (a figure-8 of
27 minutes, α's σ 0.14–0.15°; its first 10–15 minutes give α near the rule's bound of
0.25°, and the figures applied follow the sharper estimates as the window fills,
:data:`emlogd.pipeline.twoaxis_sup.OFFER_SHARPER`) and no longer (memory and the
fit's CPU grow with it)."""
FIT_EVERY_S = 120.0
"""Block time between two fits, s: a manoeuvre that fills the window is fitted whole
at least once before it slides out."""
MIN_FIT_S = 600.0
"""The window's least span before its first fit, s."""
CURRENT_KNOT_S = 300.0
"""The fit's current is linear between knots this many seconds apart, here and in
``calibrate --axes 2``. Both axes see the current, so a current that turns over half an
hour leaves a residual on both: on the simulated figure-8 of ``emlogd simulate --seed 1
--sensor emlog2:misalign=3,mt=-0.08,bt=0.04`` (EM3), one current for its 27 minutes left
residuals correlated over 75 samples and α refused; a current constant per 5-minute
block, correlated over 4 and α 3.28 ± 0.30°; linear between knots 5 minutes apart (a
figure-8 covers every heading in 90 s, a circle in 120 s), white residuals (correlation
factor 1.0) and α 3.24 ± 0.14°."""

NOISE_BLOCKS = 300
"""The reading's noise (what a correction's gain passes, :func:`~emlogd.pipeline.
twoaxis_sup.one_axis_better`) is the pooled scatter of the forward readings about their
block's mean over this many of the last blocks (5 minutes of 1-s blocks: a speed that
changes inside one second adds little, and the noise of a log does not change
faster)."""
MIN_NOISE_DOF = 100
"""The least number of degrees of freedom (readings less one per block) the noise
is measured on before a reading may go out by the one-axis correction in preference
to the figures' own (10 s of a 10-Hz log)."""

ATHWART_FRESH_S = 1.0
"""A VHW reading's forward speed is the applied figures' own (turned back by α with the
athwart speed) only when a VBW's athwart reading came this recently, s (the log's VBW
at 10 Hz, its VHW at 5 Hz); else the one-axis calibration's."""

NO_TWO_AXIS_REFERENCE = (
    "no reference speed athwart the hull at the readings' time (a DVL's bottom track "
    "gives both axes; GNSS and a one-axis log do not)"
)
"""Why nothing is learnt while no reading has been paired with a two-axis reference."""

FALLBACK_REASON = (
    "set aside after a fallback of the one-axis calibration (a change detected, or it "
    "was worse than raw): the two-axis fit's own forward speed is judged again at the "
    "next two-axis recheck"
)
"""Why the figures' own forward speed is not let out after a fallback of the one-axis
supervisor (:meth:`TwoAxisLearner.answers`)."""

ONE_AXIS_FORWARD = "the one-axis calibration's"
"""What a reason for the forward speed not being the two-axis figures' own starts with
(:meth:`TwoAxisLearner.forward_reason`; the offline ``forward_reason`` too,
:class:`emlogd.offline.twoaxis_forward.ForwardRule`)."""

_Pending = tuple[float, float, float, float]


@dataclass(slots=True)
class _Acc:
    """Sums of one block: t, forward (one-axis corrected), raw forward, raw athwart,
    ground forward, ground starboard, cos ψ, sin ψ, raw forward squared."""

    t0: float
    n: int = 0
    sums: tuple[float, ...] = (0.0,) * 9

    def add(self, row: tuple[float, ...]) -> None:
        self.sums = tuple(a + b for a, b in zip(self.sums, row, strict=True))
        self.n += 1

    def mean(self) -> tuple[float, ...]:
        m = [x / self.n for x in self.sums]
        hd = math.degrees(math.atan2(m[7], m[6])) % 360.0
        return (*m[:6], hd)

    def scatter(self) -> tuple[float, int]:
        """The raw forward readings' sum of squares about their mean, and its degrees
        of freedom."""
        mean = self.sums[2] / self.n
        return max(self.sums[8] - self.n * mean * mean, 0.0), self.n - 1


class TwoAxisLearner:
    """The online two-axis calibration of one UUT (module docstring).

    Args:
        s: the UUT's settings.
        event: called as ``event(t, kind, detail)`` for what is worth a log line.
    """

    def __init__(
        self, s: UutSettings, event: Callable[[float, str, Mapping[str, object]], None]
    ) -> None:
        self.s = s
        self._event = event
        cap = int((s.max_lag_s + 5.0) * 20) + 16
        self.fwd = SampleRing(cap, cadence=True)
        self.stb = SampleRing(cap, cadence=True)
        self.pending: deque[_Pending] = deque(maxlen=cap)
        self.blocks: deque[tuple[float, ...]] = deque(maxlen=int(WINDOW_S / BLOCK_S))
        """Block means: t, forward corrected, raw forward, raw athwart, ground forward,
        ground starboard, heading."""
        self._acc: _Acc | None = None
        self.sup = TwoAxisSupervisor(s.validation_s, s.recheck_s, event)
        self.estimate: Figures | None = None
        """The latest estimate that determined α, m_t and b_t."""
        self.refused = "no two-axis window fitted yet"
        """Why the latest window did not determine α ("" when it did)."""
        self.fits = 0
        self.fit_failures = 0
        self.t_fit = -math.inf
        self.leeway_deg: float | None = None
        """The leeway angle of the last corrected VBW, degrees (+ the hull moving to
        starboard of its heading); None before one."""
        self.counts = {"no_lag": 0, "no_reference": 0, "no_heading": 0}
        """Readings not learnt from, by why."""
        self.fallbacks = 0
        """The one-axis supervisor's fallbacks when last seen (:meth:`answers`)."""
        self.athwart: tuple[float, float] | None = None
        """The last VBW's time and raw athwart reading (what a VHW reading is turned
        back with)."""
        self.scatter: deque[tuple[float, int]] = deque(maxlen=NOISE_BLOCKS)
        """The last blocks' raw forward sums of squares about their means, and their
        degrees of freedom (:meth:`noise_var`)."""
        self._scatter_sum = [0.0, 0]
        """Their totals."""
        self.forward_by = {"own": 0, "one_axis": 0}
        """Readings whose forward speed went out by the figures' own correction, or by the
        one-axis one where that has the smaller expected error, while the figures' own
        was let out (:func:`~emlogd.pipeline.twoaxis_sup.one_axis_better`)."""
        self.choice = {"VBW": ForwardChoice(), "VHW": ForwardChoice()}
        """The choice between the two corrections, per sentence whose forward speed it
        is (a VBW's is turned back by α, a VHW's one-axis speed is not)."""
        self.tap: Callable[[float, float, float, float, bool], None] | None = None
        """Offline use (``replay --truth``): receives every VBW reading as ``(t, forward
        corrected by the one-axis calibration, raw forward, raw athwart, figures
        applied)``."""

    def restore(self, rec: Calibration) -> None:
        """The figures of a state file's record (its ``two_axis``, checked), restored
        with the sea saved with it when it has one (the early evidence of
        :meth:`TwoAxisSupervisor.restore`)."""
        if rec.two_axis is None:
            return
        sea = rec.current_mps if rec.current else None
        self.sup.restore(
            Figures.from_dict(rec.two_axis, rec.params.model),
            (*sea, rec.t) if sea is not None else None,
        )

    # -- inputs -------------------------------------------------------------

    def reference(self, t: float, fwd: float | None, stb: float | None, valid: bool) -> None:
        """One sample of the reference's ground velocity in the ship frame, m/s."""
        ok = valid and fwd is not None and stb is not None
        self.fwd.add(t, fwd if ok else None, ok)
        self.stb.add(t, stb if ok else None, ok)

    def reading(self, t: float, forward_mps: float, raw_l: float, raw_t: float) -> None:
        """One VBW reading: ``forward_mps`` corrected by the one-axis calibration, the
        raw forward and athwart readings."""
        self.pending.append((t, forward_mps, raw_l, raw_t))
        self.athwart = (t, raw_t)
        if self.tap is not None:
            self.tap(t, forward_mps, raw_l, raw_t, self.sup.applied is not None and self.s.apply)

    def correct(
        self,
        t: float,
        forward_mps: float,
        athwart_mps: float,
        raw_l_mps: float | None = None,
        guard: Guard = NO_GUARD,
    ) -> tuple[float, float] | None:
        """The VBW's hull-frame speeds with the applied figures (None: none applied):
        their own forward speed from the raw one ``raw_l_mps`` where the supervisor
        lets it (:attr:`TwoAxisSupervisor.forward_own`), else ``forward_mps`` (the
        one-axis calibration's) turned back, also where that has the smaller expected
        error (:meth:`_own_better`); ``guard`` the one-axis supervisor's
        (:meth:`answers`) and its calibration in use (None: raw passes)."""
        f = self.sup.applied
        if f is None or not self.s.apply:
            return None
        own = None
        if raw_l_mps is not None and self.answers(guard) and self.forward_on():
            own = self._own(raw_l_mps, athwart_mps)
        one = f.hull_frame(forward_mps, athwart_mps)
        ca = math.cos(math.radians(f.misalign_deg))
        one_gain = ca * ca * noise_gain(guard.in_use, forward_mps)
        if (
            own is not None
            and raw_l_mps is not None
            and self._own_better(t, "VBW", own[0], raw_l_mps, one[0], one_gain)
        ):
            u, w = own
        else:
            u, w = one
        self.leeway_deg = math.degrees(math.atan2(w, u)) if u or w else 0.0
        return u, w

    def forward(
        self,
        t: float,
        raw_l_mps: float | None,
        one_axis_mps: float,
        guard: Guard = NO_GUARD,
    ) -> float:
        """A VHW reading's forward speed: by the applied figures' own longitudinal
        parameters, turned back with the last VBW's athwart reading, where the
        supervisor lets them correct the forward speed and that reading is fresh
        (:data:`ATHWART_FRESH_S`) and the one-axis supervisor's ``guard`` lets them
        (:meth:`answers`) and the one-axis calibration's has not the smaller expected
        error (:meth:`_own_better`); else ``one_axis_mps``, the one-axis calibration's."""
        f, last = self.sup.applied, self.athwart
        if f is None or raw_l_mps is None or last is None or not self.answers(guard):
            return one_axis_mps
        if not self.forward_on() or abs(t - last[0]) > ATHWART_FRESH_S:
            return one_axis_mps
        own = self._own(raw_l_mps, last[1])
        one_gain = noise_gain(guard.in_use, one_axis_mps)
        if own is None or not self._own_better(t, "VHW", own[0], raw_l_mps, one_axis_mps, one_gain):
            return one_axis_mps
        return own[0]

    def _own_better(
        self,
        t: float,
        sentence: str,
        own_mps: float,
        raw_l_mps: float,
        one_mps: float,
        one_gain: float,
    ) -> bool:
        """Whether the forward speed of a reading at ``t`` (of a ``sentence``, VBW or
        VHW) goes out by the applied figures' own correction ``own_mps`` rather than the
        one-axis one ``one_mps`` (whose noise gain is ``one_gain``): unless the one-axis
        one has the smaller expected error at the measured noise, weighed on the readings
        of the last :data:`~emlogd.pipeline.twoaxis_sup.CHOICE_S`
        (:class:`~emlogd.pipeline.twoaxis_sup.ForwardChoice`); counted."""
        f = self.sup.applied
        if f is not None and f.lon is not None:
            us = f.lon.correct(raw_l_mps)
            own_gain = math.cos(math.radians(f.misalign_deg)) * noise_gain(f.lon, us)
            var = self.noise_var()
            if self.choice[sentence].one_axis(t, own_mps, own_gain, one_mps, one_gain, var):
                self.forward_by["one_axis"] += 1
                return False
        self.forward_by["own"] += 1
        return True

    def noise_var(self) -> float | None:
        """The forward reading's noise variance, m²/s²: the pooled scatter about their
        block's mean of the last :data:`NOISE_BLOCKS` blocks' readings (None: under
        :data:`MIN_NOISE_DOF` degrees of freedom)."""
        ss, dof = self._scatter_sum
        return max(ss, 0.0) / dof if dof >= MIN_NOISE_DOF else None

    def _own(self, raw_l_mps: float, athwart_mps: float) -> tuple[float, float] | None:
        """The hull-frame speeds by the applied figures' own longitudinal parameters, the
        forward one under the low-speed and range policy the one-axis output obeys
        (:func:`~emlogd.pipeline.integrity.emitted_speed`); None where that is no number."""
        assert self.sup.applied is not None
        u, w = self.sup.applied.hull_frame_own(raw_l_mps, athwart_mps)
        u = emitted_speed(u, raw_l_mps, self.s.low_speed_mps, self.s.envelope.max_speed_mps)
        return None if math.isnan(u) else (u, w)

    def answers(self, guard: Guard) -> bool:
        """Whether the figures' own forward speed may go out under the one-axis
        supervisor's ``guard``: not while it sends raw for a cause (``held``: the change
        detector's hold, a fault), and not after a fallback of its (``fallbacks`` grew: a
        change it detected, a calibration worse than raw) until the two-axis recheck has
        judged the forward speed again on readings since
        (:attr:`TwoAxisSupervisor.forward_own`)."""
        if guard.fallbacks != self.fallbacks:
            self.fallbacks = guard.fallbacks
            if self.sup.forward_own:
                self.sup.forward_own = False
                self.sup.forward_why = FALLBACK_REASON
        return not guard.held

    def forward_on(self) -> bool:
        """Whether the forward speed goes out by the applied figures' own longitudinal
        parameters (applied, let by the supervisor, ``apply`` on)."""
        f = self.sup.applied
        return f is not None and f.lon is not None and self.sup.forward_own and self.s.apply

    def forward_reason(self, refused: str = "") -> str | None:
        """Why the forward speed is the one-axis calibration's rather than the applied
        figures' own (None: it is theirs, :meth:`forward_on`): ``apply`` off, no figures
        applied (α refused by the latest window, ``refused`` (default: :attr:`refused`),
        with its reason; figures validating; withdrawn), figures without longitudinal
        parameters, or the supervisor's judgement of their own forward speed
        (:attr:`TwoAxisSupervisor.forward_why`)."""
        if self.forward_on():
            return None
        sup, refused = self.sup, refused or self.refused
        if not self.s.apply:
            why = "apply is off: no learnt two-axis figures are applied"
        elif sup.applied is None and sup.candidate is not None:
            why = "two-axis figures validating (their athwart speed against raw's)"
        elif sup.applied is None and refused:
            why = f"the misalignment is refused ({refused})"
        elif sup.applied is None:
            why = sup.note or "no two-axis figures learnt yet"
        elif sup.applied.lon is None:
            why = "the two-axis fit did not determine the forward scale and offset"
        else:
            why = sup.forward_why or "the two-axis fit's own forward speed not judged yet"
        return f"{ONE_AXIS_FORWARD}: {why}"

    # -- learning -----------------------------------------------------------

    def drain(
        self,
        now: float,
        lag_s: float | None,
        heading_at: Callable[[float], float | None],
        learn: bool,
        *,
        final: bool = False,
    ) -> None:
        """Pair every queued reading whose reference has arrived (or never will) and
        learn from the blocks it closes; ``final``: end of input, fit what is left."""
        while self.pending:
            t = self.pending[0][0]
            if lag_s is None:
                self.pending.popleft()
                self.counts["no_lag"] += 1
                continue
            target = t - lag_s
            if not final and not self.fwd.covers(target) and now - target <= self.fwd.gap_s + 1.0:
                break
            _, fwd_c, raw_l, raw_t = self.pending.popleft()
            gf, gs = self.fwd.at(target), self.stb.at(target)
            if gf is None or gs is None:
                self.counts["no_reference"] += 1
                continue
            hd = heading_at(target)
            if hd is None:
                self.counts["no_heading"] += 1
                continue
            psi = math.radians(hd)
            row = (t, fwd_c, raw_l, raw_t, gf, gs, math.cos(psi), math.sin(psi), raw_l * raw_l)
            self._add(t, row, learn)
        if final:
            self._close(learn)
            if learn and self.blocks and self.t_fit < self.blocks[-1][0]:
                self._fit()

    def _add(self, t: float, row: tuple[float, ...], learn: bool) -> None:
        acc = self._acc
        if acc is not None and t - acc.t0 >= BLOCK_S:
            self._close(learn)
            acc = None
        if acc is None:
            acc = self._acc = _Acc(t)
        acc.add(row)

    def _close(self, learn: bool) -> None:
        acc, self._acc = self._acc, None
        if acc is None or acc.n == 0:
            return
        b = acc.mean()
        self.blocks.append(b)
        if acc.n > 1:
            totals = self._scatter_sum
            if len(self.scatter) == self.scatter.maxlen:
                ss, k = self.scatter[0]
                totals[0], totals[1] = totals[0] - ss, totals[1] - k
            ss, k = acc.scatter()
            self.scatter.append((ss, k))
            totals[0], totals[1] = totals[0] + ss, totals[1] + k
        block: Block = (b[0], b[1], b[3], b[5], b[6], b[2], b[4])
        self.sup.observe(block)
        span = b[0] - self.blocks[0][0]
        if learn and span >= MIN_FIT_S and b[0] - self.t_fit >= FIT_EVERY_S:
            self._fit()

    def _fit(self) -> None:
        a = np.asarray(self.blocks, dtype=np.float64)
        t, raw_l, raw_t, gf, gs, hd = a[:, 0], a[:, 2], a[:, 3], a[:, 4], a[:, 5], a[:, 6]
        self.t_fit = float(t[-1])
        model = check_model(self.s.model)
        cheap = judge_two_axis(model, gf, gs, raw_l, hd, current=self.s.current)
        if ALPHA in cheap.unidentifiable:
            self._refuse(float(t[-1]), cheap.verdict(ALPHA).reason)
            return
        try:
            fit = fit_two_axis(
                model,
                TwoAxisSeries.of(gf, gs, raw_l, raw_t, hd),
                current=self.s.current,
                t_s=t,
                current_knot_s=CURRENT_KNOT_S,
            )
        except (CalibrationError, np.linalg.LinAlgError, ValueError) as exc:
            self.fit_failures += 1
            self._refuse(float(t[-1]), f"two-axis fit failed: {exc}")
            return
        self.fits += 1
        self._take(fit, float(t[-1]))

    def _take(self, fit: TwoAxisFit, t: float) -> None:
        need = (ALPHA, M_T, B_T)
        if any(k in fit.ident.unidentifiable for k in need):
            self._refuse(t, fit.ident.verdict(ALPHA).reason or fit.ident.reason)
            return
        std = fit.stderr
        p = fit.params
        sa, sm, sb = std.get("misalign_deg"), std.get(M_T), std.get(B_T)
        if sa is None or sm is None or sb is None:
            self._refuse(t, "two-axis fit gave no standard errors")
            return
        bound = DEFAULT_TWO_AXIS_RULE.max_std_misalign_deg
        if sa > bound:
            self._refuse(
                t,
                f"misalignment not determined closely enough in this window: ±{sa:.2f}° "
                f"once its residuals' correlation is counted (one independent residual "
                f"in {fit.correlation:.1f}), above {bound:.2f}°: the model does not fit "
                "the window as well as its information says",
            )
            return
        lon = lon_of_fit(p.model, p.longitudinal, std)
        self.estimate = Figures(p.misalign_deg, sa, p.m_t, sm, p.b_t_mps, sb, t, lon)
        if self.refused:
            self._event(
                t,
                "two_axis_learnt",
                {"misalign_deg": round(p.misalign_deg, 3), "misalign_std_deg": round(sa, 3)},
            )
        self.refused = ""
        self.sup.offer(self.estimate)

    def _refuse(self, t: float, why: str) -> None:
        if why != self.refused:
            self._event(t, "two_axis_refused", {"why": why})
        self.refused = why

    # -- read-outs ----------------------------------------------------------

    def status(self) -> dict[str, object]:
        """The ``two_axis`` block of a UUT's status (README: ``emlogd status --json``)."""
        sup = self.sup
        state = (
            "applied"
            if sup.applied is not None
            else "validating"
            if sup.candidate is not None
            else "learning"
        )
        span = self.blocks[-1][0] - self.blocks[0][0] if self.blocks else 0.0
        refused = self.refused
        if not self.blocks and self.counts["no_reference"]:
            refused = NO_TWO_AXIS_REFERENCE
        return {
            "state": state,
            "applied": sup.applied.as_dict() if sup.applied is not None else None,
            "estimate": self.estimate.as_dict() if self.estimate is not None else None,
            "refused": refused or None,
            "note": sup.note or None,
            "leeway_deg": self.leeway_deg,
            "window_s": round(span, 1),
            "fits": self.fits,
            "fit_failures": self.fit_failures,
            "rmse_t": {k: (None if math.isnan(v) else v) for k, v in sup.last_scores.items()},
            "forward": "two_axis" if self.forward_on() else "one_axis",
            "forward_reason": self.forward_reason(refused),
            "rmse_l": {k: (None if math.isnan(v) else v) for k, v in sup.forward_scores.items()},
            "not_learnt": dict(self.counts),
        }


_STATE_CODES = {"applied": "A", "validating": "V", "learning": "L"}


def encode_two_axis_status(port: str, maker: str, learner: TwoAxisLearner) -> str:
    """The two-axis status sentence (without CR LF)::

        $PEMLT,emlog2,A,+3.24,1.4e-01,-0.0870,+0.045,+1.2,*hh

    fields: UUT port (at most 8 characters), state (``A`` figures applied, ``V`` an
    estimate validating, ``L`` learning), α in degrees and its σ, ``m_t``, ``b_t`` in
    m/s (the applied figures, else those validating, else the latest estimate; empty before one), the leeway
    angle of the last corrected VBW in degrees (empty before one), and ``R`` when the
    latest window refused α (the reason is in the status). At most 82 characters.
    """
    st = learner.status()
    f = learner.sup.applied or learner.sup.candidate or learner.estimate

    def num(x: float | None, spec: str, limit: float) -> str:
        if x is None or not math.isfinite(x):
            return ""
        return format(max(min(x, limit), -limit), spec)

    fields = [
        f"P{maker}T",
        "".join(c for c in port if c.isascii() and (c.isalnum() or c in "_-"))[:8],
        _STATE_CODES[str(st["state"])],
        num(f.misalign_deg if f else None, "+.2f", 99.99),
        num(f.misalign_std_deg if f else None, ".1e", 9.9e9),
        num(f.m_t if f else None, "+.4f", 9.9999),
        num(f.b_t_mps if f else None, "+.3f", 9.999),
        num(learner.leeway_deg, "+.1f", 180.0),
        "R" if learner.refused else "",
    ]
    return with_checksum(",".join(fields))
