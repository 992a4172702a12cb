"""What a two-axis log's VBW is corrected with, and why: the learnt installation figures
(misalignment α, transverse scale and bias) validated against the raw athwart reading.

The figures the learner offers (:mod:`emlogd.pipeline.twoaxis_learn`) are applied only
after they are not worse than the raw athwart reading over ``validation_s`` of block
means learnt after the offer (and not worse than the figures in use); figures restored
from the state file, validated before, over the restored one-axis calibration's
window (:data:`~emlogd.pipeline.revalidation.RESTORE_VALIDATION_S`, or ``validation_s``
when that is shorter): an installation's misalignment does not change across a
restart, and raw's phantom leeway goes out meanwhile. The applied
ones are rechecked against raw every ``recheck_s``; worse than raw, they are withdrawn
and the athwart speed passes through raw while they (the last good ones) or another
offer validate again. The rule
"worse" is the one-axis supervisor's (:func:`emlogd.pipeline.revalidation.worse`).

Each side is judged in the water frame with a current of its own: the athwart error
(the corrected or raw athwart speed less the reference's ground speed to starboard)
less the best current across the hull over the window, ``c_N·sin ψ − c_E·cos ψ``
(least squares, minimum norm: on a steady heading it takes each side's offset, so
there the figures and raw score alike and neither is judged on an offset a current
could explain).

**The forward speed.** Figures learnt with the longitudinal parameters determined carry
them (:attr:`Figures.lon`: the two-axis fit's, on the sensor's axis). The athwart axis
sees the current across the hull on any heading, so that fit does not trade the
current with the forward scale as the one-axis fit must wherever the headings are few
(trained on a figure-8, the one-axis calibration's forward speed is up to 1.9 times
its floor on a transit, the two-axis fit's at it). Once the figures are applied, the
forward speed is corrected by their longitudinal parameters and turned back by α
(:meth:`Figures.hull_frame_own`) when, over the same window, its forward error after
a current of its own along the hull (``c_N·cos ψ + c_E·sin ψ``) is not worse than
the one-axis calibration's forward speed as emitted nor than the raw forward reading
(:func:`forward_rmse`); else the one-axis calibration's forward speed is turned back
(:meth:`Figures.hull_frame`). Each recheck judges it again: worse than either, the
forward speed goes back to the one-axis calibration's, and the figures' forward speed
returns only where the one-axis one is worse than it by the margin (the recheck was
evidence against it). Set aside for want of the one-axis supervisor's word (its
fallback, :meth:`emlogd.pipeline.twoaxis_learn.TwoAxisLearner.answers`), which is no
evidence against it, it returns at the next recheck by the rule it was first applied
by. A tie goes to the figures' own, by physics: the two-axis fit determines the
forward scale and offset with the current seen on both axes, where the one-axis fit
trades them with the current wherever the headings are few, and a current of its own
over the window hides an offset from this judgement. The one-axis calibration's
forward speed reads below the figures' own only through its noise: at one speed (a
straight run) any correction fits the offset, and one whose scale is nearer 0
divides the reading's noise by less (the ratio ``(1 + m_own)/(1 + m_one)``, 2–3 % on
the straight runs after a restart where the one-axis fit held its scale).

**Per reading, the smaller expected error.** Where the figures' own forward speed is
let out, each reading still goes out by whichever of the two corrections has the
smaller expected squared error (:func:`one_axis_better`). A correction's error at
one speed is its offset there plus the reading's noise times its gain ``1/f'(v)``
(:func:`noise_gain`): the two-axis fit's is the sensor's local slope, the one-axis
fit's — its scale traded with the current — lower wherever that scale is nearer 0.
Taking the figures' own as unbiased (its scale and offset determined with the current
seen on both axes), the one-axis correction's offset at this speed is their
difference ``d``, computed from the two sets of parameters and weighed as its mean
over the readings of the last :data:`CHOICE_S` (one reading's ``d`` carries that
reading's noise, :class:`ForwardChoice`), and its expected squared error is the
smaller when ``d² < (g_own² − g_one²)·σ²``, σ the reading's
noise (measured by the learner, the scatter of the readings inside each block). On a
straight run where the one-axis offset happens to fit (its scale held, its noise
divided by less) that sends the one-axis speed; where its offset does not (the
return after a restart, 2.3 times the floor) the figures' own. The uncertainty of the
figures' own offset adds to both sides alike and drops out.

**Restored figures early.** Figures restored with the sea of their state file (the
current saved with the one-axis calibration, at most
:data:`~emlogd.pipeline.revalidation.RESTORE_SEA_MAX_AGE_S` old) are applied on the
first :data:`~emlogd.pipeline.revalidation.RESTORE_EARLY_SAMPLES` blocks when, against
the reference less that current across the hull, raw's athwart speed is worse than
theirs (:func:`~emlogd.pipeline.revalidation.worse`): the one-axis supervisor's rule
for its restored calibration. They are validated in place over the rest of the window
and withdrawn when that fails; with any other evidence raw passes meanwhile.

No I/O, no clock.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from calib.errors import ModelError
from calib.models import PARAM_NAMES, Params, check_model, correct_array
from emlogd.pipeline.calibration import TWO_AXIS_LON_KEYS
from emlogd.pipeline.revalidation import (
    RESTORE_EARLY_SAMPLES,
    RESTORE_SEA_MAX_AGE_S,
    RESTORE_VALIDATION_S,
    worse,
)

OFFER_MIN_CHANGE_SIGMA = 1.0
"""A new estimate is validated against the figures in use only when one of α, m_t, b_t
moved by more than this many of its σ, or α's σ shrank (:data:`OFFER_SHARPER`); else
the figures in use stay, without churn."""
OFFER_SHARPER = 0.9
"""A new estimate whose α has a σ under this share of the figures in use's is
validated too, though within their σ: the window first determines α before the whole
figure-8 is in (σ near the rule's bound, :class:`calib.twoaxis_ident.TwoAxisRule`),
and the figures applied follow it as it fills (a 27-minute figure-8 ends near
0.15°)."""

LON_KEYS = TWO_AXIS_LON_KEYS
"""The keys of a figures' longitudinal parameters (:attr:`Figures.lon`) in
:meth:`Figures.as_dict` and a state file's ``two_axis``: ``a`` s/m, ``m``, ``b`` m/s."""

Block = tuple[float, float, float, float, float, float, float]
"""One block mean as judged: (t s, forward corrected by the one-axis calibration m/s,
raw athwart m/s, the reference's ground speed to starboard m/s, heading degrees, raw
forward m/s, the reference's ground speed forward m/s)."""


@dataclass(frozen=True, slots=True)
class Figures:
    """A two-axis log's installation figures learnt online, with their σ.

    Attributes:
        misalign_deg: α, the sensor's forward axis from the bow, degrees (+ starboard).
        misalign_std_deg: its σ, degrees.
        m_t: the transverse scale error.
        m_t_std: its σ.
        b_t_mps: the transverse bias, m/s.
        b_t_std_mps: its σ, m/s.
        t: the time of the last block of the window they were learnt on, s.
        lon: the longitudinal parameters on the sensor's axis learnt with them (None:
            the fit did not determine them all, or a state file without them).
    """

    misalign_deg: float
    misalign_std_deg: float
    m_t: float
    m_t_std: float
    b_t_mps: float
    b_t_std_mps: float
    t: float
    lon: Params | None = None

    def hull_frame(self, forward_mps: float, athwart_mps: float) -> tuple[float, float]:
        """The speed through the water along and athwart the hull, m/s.

        ``forward_mps`` is the forward reading corrected by the one-axis calibration,
        which is learnt against the hull's forward speed: it reads ``u + w·tan α``
        (the sensor's ``cos α`` is in its scale). With the athwart reading on the
        sensor's axis ``w_s = (athwart − b_t)/(1 + m_t) = w·cos α − u·sin α``:
        ``u = v·cos²α − w_s·sin α`` and ``w = cos α·(w_s + v·sin α)``.
        """
        ws = (athwart_mps - self.b_t_mps) / (1.0 + self.m_t)
        a = math.radians(self.misalign_deg)
        ca, sa = math.cos(a), math.sin(a)
        return forward_mps * ca * ca - ws * sa, ca * (ws + forward_mps * sa)

    def hull_frame_own(self, raw_l_mps: float, athwart_mps: float) -> tuple[float, float]:
        """The speed through the water along and athwart the hull, m/s, from the raw
        readings by these figures alone: the forward reading corrected by
        :attr:`lon` on the sensor's axis (``u_s``), the athwart one by the transverse
        scale and bias (``w_s``), both turned back by α: ``u = u_s·cos α − w_s·sin α``,
        ``w = u_s·sin α + w_s·cos α`` (:meth:`calib.twoaxis.TwoAxisParams.correct`).

        Raises:
            ValueError: figures without :attr:`lon`.
        """
        if self.lon is None:
            raise ValueError("two-axis figures without longitudinal parameters")
        us = self.lon.correct(raw_l_mps)
        ws = (athwart_mps - self.b_t_mps) / (1.0 + self.m_t)
        a = math.radians(self.misalign_deg)
        ca, sa = math.cos(a), math.sin(a)
        return us * ca - ws * sa, us * sa + ws * ca

    def moved(self, other: Figures) -> bool:
        """Whether ``other`` differs from these by more than
        :data:`OFFER_MIN_CHANGE_SIGMA` of its σ in any figure, or determines α more
        sharply (its σ under :data:`OFFER_SHARPER` of these')."""
        k = OFFER_MIN_CHANGE_SIGMA
        return (
            other.misalign_std_deg < OFFER_SHARPER * self.misalign_std_deg
            or abs(other.misalign_deg - self.misalign_deg) > k * other.misalign_std_deg
            or abs(other.m_t - self.m_t) > k * other.m_t_std
            or abs(other.b_t_mps - self.b_t_mps) > k * other.b_t_std_mps
        )

    @classmethod
    def from_dict(cls, d: Mapping[str, float], model: str | None = None) -> Figures:
        """Figures from :meth:`as_dict`'s keys (a state file's), learnt at no known
        time: any block validates them. The longitudinal parameters (:data:`LON_KEYS`)
        are taken when all are there and ``model`` (the UUT's error model, which the
        record's is) has them (a parameter the model lacks must be 0); else none."""
        return cls(
            d["misalign_deg"],
            d["misalign_std_deg"],
            d["m_t"],
            d["m_t_std"],
            d["b_t_mps"],
            d["b_t_std_mps"],
            -math.inf,
            _lon_of(d, model),
        )

    def as_dict(self) -> dict[str, float]:
        """JSON keys (README: the ``two_axis`` block of ``emlogd status --json``), with
        :data:`LON_KEYS` when the figures carry longitudinal parameters."""
        out = {
            "misalign_deg": self.misalign_deg,
            "misalign_std_deg": self.misalign_std_deg,
            "m_t": self.m_t,
            "m_t_std": self.m_t_std,
            "b_t_mps": self.b_t_mps,
            "b_t_std_mps": self.b_t_std_mps,
        }
        if self.lon is not None:
            lon = self.lon
            out |= dict(zip(LON_KEYS, (lon.a_spm, lon.m, lon.b_mps), strict=True))
        return out


def _lon_of(d: Mapping[str, float], model: str | None) -> Params | None:
    """The longitudinal parameters of a figures' dict (:meth:`Figures.from_dict`)."""
    if model is None or not all(k in d for k in LON_KEYS):
        return None
    try:
        name = check_model(model)
        a, m, b = (float(d[k]) for k in LON_KEYS)
        return Params(name, a, m, b)
    except (ModelError, TypeError, ValueError):
        return None


def lon_of_fit(model: str, params: Params, stderr: Mapping[str, float | None]) -> Params | None:
    """A two-axis fit's longitudinal parameters when it determined every one of them
    (each with a σ), else None: one held at its prior is not the log's."""
    names = PARAM_NAMES[check_model(model)]
    return params if all(stderr.get(k) is not None for k in names) else None


def athwart_rmse(blocks: list[Block], figures: Figures | None) -> float:
    """RMS of the athwart error of ``blocks`` corrected with ``figures`` (None: raw)
    after a current of its own across the hull (module docstring), m/s."""
    a = np.asarray(blocks, dtype=np.float64).reshape(-1, 7)
    if a.shape[0] == 0:
        return math.nan
    fwd, raw_t, gs, psi = a[:, 1], a[:, 2], a[:, 3], np.radians(a[:, 4])
    if figures is None:
        w = raw_t
    else:
        ws = (raw_t - figures.b_t_mps) / (1.0 + figures.m_t)
        al = math.radians(figures.misalign_deg)
        w = math.cos(al) * (ws + fwd * math.sin(al))
    e = w - gs
    design = np.column_stack([np.sin(psi), -np.cos(psi)])
    coef = np.linalg.lstsq(design, e, rcond=None)[0]
    r = e - design @ coef
    return math.sqrt(float(r @ r) / r.size)


FORWARD_ONE_AXIS = "one_axis"
FORWARD_RAW = "raw"
FORWARD_OWN = "own"


def forward_rmse(blocks: list[Block], figures: Figures | None) -> dict[str, float]:
    """RMS of the forward error of ``blocks`` after a current of its own along the
    hull (``c_N·cos ψ + c_E·sin ψ``, least squares, minimum norm), m/s: of the
    one-axis calibration's forward speed as emitted (:data:`FORWARD_ONE_AXIS`), of the
    raw forward reading (:data:`FORWARD_RAW`) and, for figures with longitudinal
    parameters, of their own forward speed (:data:`FORWARD_OWN`,
    :meth:`Figures.hull_frame_own`)."""
    a = np.asarray(blocks, dtype=np.float64).reshape(-1, 7)
    if a.shape[0] == 0:
        return {}
    fwd, raw_t, psi, raw_l, gf = a[:, 1], a[:, 2], np.radians(a[:, 4]), a[:, 5], a[:, 6]
    design = np.column_stack([np.cos(psi), np.sin(psi)])

    def rms(u: npt.NDArray[np.float64]) -> float:
        e = u - gf
        coef = np.linalg.lstsq(design, e, rcond=None)[0]
        r = e - design @ coef
        return math.sqrt(float(r @ r) / r.size)

    out = {FORWARD_ONE_AXIS: rms(fwd), FORWARD_RAW: rms(raw_l)}
    if figures is not None and figures.lon is not None:
        us = correct_array(figures.lon, raw_l)
        ws = (raw_t - figures.b_t_mps) / (1.0 + figures.m_t)
        al = math.radians(figures.misalign_deg)
        out[FORWARD_OWN] = rms(us * math.cos(al) - ws * math.sin(al))
    return out


class Guard(NamedTuple):
    """What a two-axis forward speed answers to of the one-axis supervisor
    (:meth:`~emlogd.pipeline.twoaxis_learn.TwoAxisLearner.answers`)."""

    fallbacks: int
    """Its fallbacks to raw or the previous calibration so far."""
    held: bool
    """Whether a reading goes out raw for a cause now (the change detector's hold, a fault)."""
    in_use: Params | None
    """The calibration a reading goes out by (None: raw passes), whose noise gain the
    two-axis forward speed is weighed against."""


NO_GUARD = Guard(0, False, None)
"""No one-axis supervisor to answer to."""


def noise_gain(p: Params | None, v_mps: float) -> float:
    """How much of a reading's noise a correction passes at the corrected speed
    ``v_mps``: ``1/f'(v) = 1/(2a·v + 1 + m)`` (None: raw passes, 1); inf where the
    slope is not positive."""
    if p is None:
        return 1.0
    slope = 2.0 * p.a_spm * v_mps + 1.0 + p.m
    return 1.0 / slope if slope > 0.0 else math.inf


def one_axis_better(d_mps: float, own_gain: float, one_gain: float, noise_var: float) -> bool:
    """Whether the one-axis correction of a reading has the smaller expected squared
    error than the figures' own (module docstring): the figures' own taken as unbiased,
    the one-axis one's offset is ``d_mps``, the two corrections' difference, and it
    wins when that squared is under the noise it spares, ``(g_own² − g_one²)·σ²``."""
    spare = (own_gain * own_gain - one_gain * one_gain) * noise_var
    return math.isfinite(spare) and spare > 0.0 and d_mps * d_mps < spare


CHOICE_S = 2.0
"""The one-axis correction's offset a reading's choice weighs (:class:`ForwardChoice`)
is the mean of the two corrections' difference over the readings of this many seconds
up to it. One reading's difference carries its noise times the difference of the two
corrections' slopes (0.05 m/s of noise, scales −0.15 and −0.20: ±4 mm/s), enough to
flip a choice near the bound from reading to reading; the mean over ``n`` readings
divides that by √n, while the difference itself follows the speed, which the mean
trails by half the window. Chosen by leaving trials out: of 0.5, 1, 2, 3, 5, 10 and
30 s, 2 s gave the lowest mean over the trajectories of the VBW's forward RMSE over the
one-axis calibration's in the daemon's replays of seeds 2–4 (a misaligned log), and
of the held-out seeds 5 and 6 and the aligned logs of seeds 2–6, with no trajectory
worse than the one-axis calibration's; seed 1, out of both, 1.0003 times it on one
(its circles after a restart, 1.0032 at 1 s; docs/REPRODUCTION.md)."""


class ForwardChoice:
    """Which correction a reading's forward speed goes out by, readings one after the
    other: the one-axis one where :func:`one_axis_better` holds for the mean of the two
    corrections' difference over the last :data:`CHOICE_S` (the reading's included),
    else the figures' own. Keep one per stream of readings (a VBW's and a VHW's forward
    speeds differ by their turning back)."""

    def __init__(self) -> None:
        self._diffs: deque[tuple[float, float]] = deque()
        self._sum = 0.0

    def one_axis(
        self,
        t: float,
        own_mps: float,
        own_gain: float,
        one_mps: float,
        one_gain: float,
        noise_var: float | None,
    ) -> bool:
        """Whether the reading at ``t`` goes out by the one-axis correction ``one_mps``
        rather than the figures' own ``own_mps`` (their noise gains given), at the
        reading's noise variance ``noise_var`` (None: not measured, the figures' own)."""
        diffs = self._diffs
        if diffs and t < diffs[-1][0]:
            diffs.clear()
            self._sum = 0.0
        d = one_mps - own_mps
        diffs.append((t, d))
        self._sum += d
        while diffs[0][0] <= t - CHOICE_S:
            self._sum -= diffs.popleft()[1]
        if noise_var is None:
            return False
        return one_axis_better(self._sum / len(diffs), own_gain, one_gain, noise_var)


def own_forward_verdict(r: Mapping[str, float]) -> str:
    """Why the figures' own forward speed is worse than the one-axis calibration's or
    than raw (:func:`emlogd.pipeline.revalidation.worse`) on scores of
    :func:`forward_rmse`, with the scores; "" where it is not."""
    own = r.get(FORWARD_OWN, math.nan)
    if not math.isfinite(own):
        return "the two-axis fit did not determine the forward scale and offset"
    for key, name in ((FORWARD_ONE_AXIS, "the one-axis calibration's"), (FORWARD_RAW, "raw's")):
        if worse(own, r[key]):
            return (
                f"the two-axis fit's own forward speed was worse than {name} "
                f"({own:.4f} against {r[key]:.4f} m/s after a current of its own)"
            )
    return ""


class TwoAxisSupervisor:
    """The figures applied to a two-axis log's VBW (module docstring).

    Args:
        validation_s: a candidate's validation window, s (the UUT's ``validation_s``).
        recheck_s: the applied figures' recheck window, s (the UUT's ``recheck_s``).
        event: called as ``event(t, kind, detail)`` for every decision.
    """

    def __init__(
        self,
        validation_s: float,
        recheck_s: float,
        event: Callable[[float, str, Mapping[str, object]], None],
    ) -> None:
        self.validation_s = validation_s
        self._window = validation_s
        """The candidate's validation window, s (shorter for restored figures)."""
        self.recheck_s = recheck_s
        self._event = event
        self.applied: Figures | None = None
        """The figures the VBW is corrected with (None: raw athwart passes through)."""
        self.kept: Figures | None = None
        """The last figures that validated (applied, or withdrawn for cause)."""
        self.candidate: Figures | None = None
        self._cand_blocks: list[Block] = []
        self._recheck: list[Block] = []
        self.note = ""
        """The last decision, in words."""
        self.changed = False
        """The last good figures changed since the caller last persisted them."""
        self.last_scores: dict[str, float] = {}
        """The athwart RMSE of the last judgement, m/s (``raw``, ``candidate``,
        ``applied``)."""
        self.forward_own = False
        """The forward speed is the applied figures' own (:meth:`Figures.hull_frame_own`),
        not the one-axis calibration's turned back by α (module docstring)."""
        self.forward_scores: dict[str, float] = {}
        """The forward RMSE of the last judgement, m/s (:func:`forward_rmse`'s keys)."""
        self.forward_doubted = False
        """The figures' own forward speed was set aside by a recheck that found it worse:
        it returns only where the one-axis one is worse than it by the margin."""
        self.forward_why = ""
        """Why the applied figures' own forward speed is not let out, in words (with the
        scores of the judgement that set it aside); "" while it is, or before figures
        are applied."""

        self.sea: tuple[float, float, float] | None = None
        """The restored figures' saved current (north, east, m/s) and its time, s, while
        their early evidence is gathered (module docstring); None otherwise."""
        self._sea_sums = [0.0, 0.0, 0]
        """Over the restored figures' first blocks: raw's and their squared athwart error
        in the saved sea, and how many blocks."""
        self.early = False
        """The applied figures are restored ones applied early, validating in place."""

    def restore(self, figures: Figures, sea: tuple[float, float, float] | None = None) -> None:
        """Figures from the state file: the last good ones, a candidate that
        validates before it is applied, over the restored window; ``sea``: the current
        saved with them (north, east, m/s) and its time, s, the early evidence's
        (module docstring)."""
        self.kept = figures
        self.offer(figures)
        if self.candidate is figures:
            self._window = min(RESTORE_VALIDATION_S, self.validation_s)
            self.sea = sea

    def offer(self, figures: Figures) -> None:
        """A new estimate from the learner: validated unless it is the figures in use
        within their σ (:meth:`Figures.moved`)."""
        current = self.candidate or self.applied
        if current is not None and not current.moved(figures):
            return
        self.candidate = figures
        self._cand_blocks = []
        self._window = self.validation_s
        self.sea = None

    def observe(self, block: Block) -> None:
        """One block mean learnt from: the candidate's validation, the applied
        figures' recheck."""
        t = block[0]
        if self.candidate is not None and t > self.candidate.t:
            self._cand_blocks.append(block)
            if self.sea is not None:
                self._early_evidence(block)
            if t - self._cand_blocks[0][0] >= self._window:
                self._judge_candidate(t)
        if self.applied is not None:
            self._recheck.append(block)
            if t - self._recheck[0][0] >= self.recheck_s:
                self._judge_applied(t)

    def _early_evidence(self, block: Block) -> None:
        """One of the restored figures' first blocks in their saved sea: applied once
        raw is worse than them there (module docstring)."""
        sea, cand = self.sea, self.candidate
        assert sea is not None and cand is not None
        t, fwd, raw_t, gs, hd = block[:5]
        if not 0.0 <= t - sea[2] <= RESTORE_SEA_MAX_AGE_S:
            self.sea = None
            return
        psi = math.radians(hd)
        across = sea[0] * math.sin(psi) - sea[1] * math.cos(psi)  # w − gs of the current
        sums = self._sea_sums
        sums[0] += (raw_t - gs - across) ** 2
        sums[1] += (_athwart(cand, fwd, raw_t) - gs - across) ** 2
        sums[2] += 1
        n = sums[2]
        if n < RESTORE_EARLY_SAMPLES:
            return
        self.sea = None
        r_raw, r_cand = math.sqrt(sums[0] / n), math.sqrt(sums[1] / n)
        if self.applied is not None or not worse(r_raw, r_cand):
            return
        self.applied = cand
        self.early = True
        self._recheck = []
        self.note = "restored two-axis figures applied on their first blocks: validating"
        self.forward_why = (
            "restored two-axis figures applied early: their own forward speed is judged "
            "once they have validated"
        )
        self._event(
            t,
            "two_axis_applied",
            {
                "misalign_deg": round(cand.misalign_deg, 3),
                "rmse_t_raw_saved_sea": round(r_raw, 4),
                "rmse_t_candidate_saved_sea": round(r_cand, 4),
                "blocks": n,
                "kind": "restored-early",
                "forward": FORWARD_ONE_AXIS,
            },
        )

    def _judge_candidate(self, t: float) -> None:
        cand = self.candidate
        assert cand is not None
        early, self.early = self.early and self.applied is cand, False
        if early:
            self.applied = None  # judged as the candidate it still is
        blocks, self._cand_blocks, self.candidate = self._cand_blocks, [], None
        r_raw, r_cand = athwart_rmse(blocks, None), athwart_rmse(blocks, cand)
        r_app = athwart_rmse(blocks, self.applied) if self.applied is not None else math.nan
        self.last_scores = {"raw": r_raw, "candidate": r_cand, "applied": r_app}
        detail: dict[str, object] = {
            "misalign_deg": round(cand.misalign_deg, 3),
            "rmse_t_raw": round(r_raw, 4),
            "rmse_t_candidate": round(r_cand, 4),
        }
        if worse(r_cand, r_raw):
            self.note = "two-axis figures rejected: athwart worse than raw"
            if early:
                self.note = "restored two-axis figures withdrawn: athwart worse than raw"
            self._event(t, "two_axis_rejected", detail | {"why": self.note})
            return
        if self.applied is not None and worse(r_cand, r_app):
            self.note = "two-axis figures rejected: athwart worse than the figures in use"
            self._event(t, "two_axis_rejected", detail | {"why": self.note})
            return
        self.applied = self.kept = cand
        self.changed = True
        self._recheck = []
        self.note = ""
        self.forward_scores = forward_rmse(blocks, cand)
        self.forward_why = own_forward_verdict(self.forward_scores)
        self.forward_own = not self.forward_why
        self.forward_doubted = not self.forward_own
        detail["forward"] = FORWARD_OWN if self.forward_own else FORWARD_ONE_AXIS
        detail |= {f"rmse_l_{k}": round(v, 4) for k, v in self.forward_scores.items()}
        self._event(t, "two_axis_applied", detail)

    def _judge_applied(self, t: float) -> None:
        app = self.applied
        assert app is not None
        blocks, self._recheck = self._recheck, []
        r_raw, r_app = athwart_rmse(blocks, None), athwart_rmse(blocks, app)
        self.last_scores = {"raw": r_raw, "applied": r_app}
        if worse(r_app, r_raw):
            self.applied = None
            self.forward_own = False
            self.candidate, self._cand_blocks = app, []  # the last good, re-validated
            self._window = self.validation_s
            self.note = "two-axis figures withdrawn: athwart worse than raw"
            self._event(
                t,
                "two_axis_withdrawn",
                {"rmse_t_raw": round(r_raw, 4), "rmse_t_applied": round(r_app, 4)},
            )
            return
        self._recheck_forward(t, blocks, app)

    def _recheck_forward(self, t: float, blocks: list[Block], app: Figures) -> None:
        """The applied figures' own forward speed judged again (module docstring)."""
        if app.lon is None:
            return
        r = self.forward_scores = forward_rmse(blocks, app)
        detail = {f"rmse_l_{k}": round(v, 4) for k, v in r.items()}
        verdict = own_forward_verdict(r)
        if self.forward_own and verdict:
            self.forward_own, self.forward_doubted = False, True
            self.forward_why = verdict
            self._event(t, "two_axis_forward_withdrawn", detail)
        elif self.forward_own:
            return
        elif verdict:
            self.forward_why = verdict
        elif self.forward_doubted and not worse(r[FORWARD_ONE_AXIS], r[FORWARD_OWN]):
            self.forward_why = (
                "the two-axis fit's own forward speed, found worse at a recheck, returns "
                "once the one-axis calibration's is worse than it by the margin "
                f"({r[FORWARD_OWN]:.4f} against {r[FORWARD_ONE_AXIS]:.4f} m/s)"
            )
        else:
            self.forward_own, self.forward_why = True, ""
            self._event(t, "two_axis_forward_applied", detail)


def _athwart(figures: Figures, forward_mps: float, athwart_mps: float) -> float:
    """The athwart speed ``figures`` give (:meth:`Figures.hull_frame`'s), m/s."""
    return figures.hull_frame(forward_mps, athwart_mps)[1]
