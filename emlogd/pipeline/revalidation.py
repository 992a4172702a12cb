"""A calibration's validation window, and the verdicts on one validated before.

:class:`Candidate` is what the supervisor (:mod:`emlogd.pipeline.supervisor`) scores
over a candidate's validation window. A new calibration, or one withdrawn for cause,
must beat raw by the margin of :func:`worse`, in the water frame both after a current
of each one's own and in one sea for both (:func:`common_current`, where the headings
determine it: :meth:`CommonSea.along`); a restored one
need only not be worse than raw. A restored one in the water frame, where a current and an offset look
alike on a straight leg, is judged after a current of its own where the window's
headings spread (:func:`judge_own_currents`), else in the sea it was saved in
(:func:`judge_saved_sea`) or by the current its errors imply (:func:`judge_restored`).
No I/O, no clock.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

from calib.kalman import KfConfig
from calib.models import HeadingCS, Params
from emlogd.pipeline.evidence import (
    CURRENT_HALF_LIFE_S,
    CURRENT_MEMORY_S,
    FIT_CURRENT_PRIOR_MPS,
    FIT_NOISE_MPS,
    SeaMemory,
)
from emlogd.pipeline.separation import Separation

if TYPE_CHECKING:
    from emlogd.pipeline.learner import Offer

CandidateKind = Literal["new", "restored", "revalidate", "verify"]


class CandidateSource(Protocol):
    """What the supervisor may ask of the learner: an offer, and its uncertainty now."""

    def offer(self) -> Offer | None:
        """The learner's estimate as a candidate, or None when it has none to offer."""

    @property
    def param_std(self) -> Mapping[str, float]:
        """The standard deviation of each parameter now."""


RESTORE_VALIDATION_S = 20.0
"""A restored or withdrawn calibration (validated before) re-validates over this long,
s (or ``validation_s`` when that is shorter), against ``validation_s`` for a new one:
raw passes through meanwhile. The change detector and the re-check watch it from then
on."""

RESTORE_SEA_MAX_AGE_S = 3600.0
"""A restored calibration saved with a determined current is re-validated in the sea it
was saved in (raw and it against the reference less that current) when it was saved at
most this long before the first reading, s; older, each is given a current of its own
like any candidate. On a straight leg a current of raw's own takes raw's offset, so
only a known sea can tell a good restored calibration from raw there; within an hour a
tidal current changes by a fraction of itself."""

RESTORE_EARLY_SAMPLES = 5
"""A restored calibration is applied after this many samples (:func:`judge_early`) when,
saved with its sea (:data:`RESTORE_SEA_MAX_AGE_S`), its RMSE over them against the
reference less the saved current is below raw's by raw's margin (:func:`worse` the other
way round: the evidence is for it), or, in the water frame on a straight leg, when the
verdict of its whole window (:func:`judge_restored`) already applies it on them: a sea
that moved between the save and the restart makes raw's current as odd as its own, and
more samples of one heading would not tell the two apart. It is validated in place over
the rest of its window and withdrawn when that fails; otherwise raw passes through until
then."""

RESTORE_RETRY_S = 120.0
"""A restored calibration refused on a window whose headings cannot tell a current from
an offset, for the current its errors imply (beyond what the sea can have become since
it was saved, :data:`RESTORE_SEA_SIGMAS`), is validated again this long after, s, while
nothing is applied and the learner has nothing to offer: it was not shown wrong, only
unexplained by the sea it was saved in, and that sea's allowance grows with the time
since it was saved (a current that changed faster than the learner's random walk is
seen as such a little later). Raw passes through meanwhile. One refused with the whole
allowance (the learner's prior of a current component: saved without its sea, or long
enough ago) is not judged again: time would not change its verdict, only give it more
draws."""

RESTORE_WAIT_S = 10.0
"""A restored calibration is applied unverified when no reference has been heard this
long after the first reading, s."""


WORSE_FACTOR = 1.05
WORSE_MARGIN_MPS = 0.005
"""The applied calibration is worse than raw when its RMSE exceeds raw's × 1.05 + 5 mm/s."""

RESTORE_MIN_HEADING_SPREAD = 0.1
"""A restored calibration's validation window tells a current from an offset when its
headings spread this much (one minus the mean resultant length of the heading's unit
vector: 0 on a straight leg, 0.1 for headings spread evenly over about 90°); then raw
and it are each judged after a current of their own fitted to that window. On a
narrower window a current and an offset look alike, and it falls back on the sea (see
:data:`RESTORE_SEA_SIGMAS`)."""

RESTORE_SEA_SIGMAS = 3.0
"""Where the validation window cannot tell a current from an offset, a restored
calibration keeps the verdict that made it (it was validated before it was saved) unless
its errors imply a current that the sea cannot have: its mean error against the
reference less the saved current is beyond this many standard deviations of that current
(its saved uncertainty grown by the learner's random walk over the time since it was
saved), and never beyond the learner's prior standard deviation of a current component
(``sqrt(current_p0_m2ps2)``, the whole allowance when no current was saved)
— and the current raw's errors imply is the likelier one by as much (the squares of the
two, less the centre, differ by more than the allowance's square: a log ratio of
``RESTORE_SEA_SIGMAS²/2`` under that sea's Gaussian). A sea that moved since it was saved
makes raw's current as odd as the calibration's; a wrong calibration makes its own odd
alone."""


def _rms_after_current(
    d: npt.NDArray[np.float64], c: npt.NDArray[np.float64], s: npt.NDArray[np.float64]
) -> float:
    """RMS of errors after a current fitted to them (``d ≈ β·(cos ψ, sin ψ)``), m/s."""
    x = np.column_stack((c, s))
    ridge = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2
    beta = np.linalg.solve(x.T @ x + ridge * np.eye(2), x.T @ d)
    return float(np.sqrt(np.mean((d - x @ beta) ** 2)))


COMMON_SEA_DEGREE = 2
"""The degree of the free polynomial of the reading in :func:`common_current`: a
quadratic spans the corrections of every error model (EM1–EM4), so the common sea is
one for any of them, and a log whose error curves with speed (EM4's ``a``, which a
configured EM3 does not model) does not leak its curvature into the current where
speed and heading change together."""


COMMON_SEA_MAX_STD_MPS = 0.1
"""A sample is scored in the common sea only where that sea's current along the hull at
its heading is known to this, m/s (its standard deviation from the fit): where the
memory's headings do not tell it from the free polynomial's offset (one heading, or two
sectors whose offsets the polynomial takes), the ridge holds it near zero, which is the
ground frame, not a sea; such a sample is no evidence for raw or against a candidate."""


class CommonSea(NamedTuple):
    """The common sea's β (north, east, m/s: minus the current) and its covariance
    (m²/s²), from :func:`common_current`."""

    n: float
    e: float
    var_nn: float
    var_ne: float
    var_ee: float

    def along(self, cs: tuple[float, float]) -> float | None:
        """β along the hull at the heading's (cos, sin) ``cs``, or None where the fit
        does not determine it (:data:`COMMON_SEA_MAX_STD_MPS`)."""
        c, s = cs
        var = self.var_nn * c * c + 2.0 * self.var_ne * c * s + self.var_ee * s * s
        return self.n * c + self.e * s if var <= COMMON_SEA_MAX_STD_MPS**2 else None


UNDETERMINED_SEA = CommonSea(0.0, 0.0, math.inf, 0.0, math.inf)
"""The common sea of a memory too short to fit one."""


def common_current(mem: SeaMemory, now: float, degree: int) -> CommonSea:
    """The second sea a candidate and raw are validated in: the β (minus the current) of
    ``raw − ref ≈ Σₖ αₖ·rawᵏ (k ≤ degree) + β·(cos ψ, sin ψ)`` over the memory's
    samples, weighted like :meth:`~emlogd.pipeline.evidence.SeaMemory.current`
    (the supervisor's degree is :data:`COMMON_SEA_DEGREE`), and its covariance (each
    sample's error :data:`~emlogd.pipeline.evidence.FIT_NOISE_MPS`).

    The polynomial of the reading is free, so the fitted β is the same for raw and for
    any correction of at most that degree (``p(raw) − raw`` is such a polynomial): one sea for raw and the candidate, which neither can fit to its own
    errors. A current of each one's own takes its offset on a straight leg and can make
    a wrong correction look better than raw there; this sea instead assumes one
    correction over the whole memory, which a sensor that drifts breaks. Neither is
    sure, so a candidate must beat raw in both. Where the headings do not determine β,
    the ridge of :data:`~emlogd.pipeline.evidence.FIT_CURRENT_PRIOR_MPS` keeps it near
    zero and the polynomial takes the rest: its variance along such a heading stays
    near that prior's, and :meth:`CommonSea.along` gives no sea there.
    """
    if not mem.n:
        return UNDETERMINED_SEA
    data = mem.data[:, : mem.n] if mem.n < mem.data.shape[1] else mem.data
    t, raw, ref, c, s = data
    w = np.exp2(-(now - t) / CURRENT_HALF_LIFE_S) * (now - t <= CURRENT_MEMORY_S)
    d = raw - ref
    ok = np.isfinite(d) & (w > 0.0)
    if np.count_nonzero(ok) < degree + 3:
        return UNDETERMINED_SEA
    w, d, raw, c, s = w[ok], d[ok], raw[ok], c[ok], s[ok]
    x = np.column_stack([raw**k for k in range(degree + 1)] + [c, s])
    ridge = np.zeros(degree + 3)
    ridge[-2:] = (FIT_NOISE_MPS / FIT_CURRENT_PRIOR_MPS) ** 2
    a = (x * w[:, None]).T @ x + np.diag(ridge)
    b = (x * w[:, None]).T @ d
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    cov = FIT_NOISE_MPS**2 * np.linalg.pinv(a)[-2:, -2:]
    return CommonSea(
        float(sol[-2]), float(sol[-1]), float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
    )


@dataclass
class Candidate:
    """A calibration under validation: what it is, since when, and its scores so far
    (sums of squared errors of raw, of it and of the applied one over ``n`` samples)."""

    params: Params
    t0: float
    kind: CandidateKind = "new"
    std: Mapping[str, float | None] | None = None
    """Its standard deviations (a restored or withdrawn one keeps its own)."""
    raw: float = 0.0
    cand: float = 0.0
    applied: float = 0.0
    sea_raw: float = 0.0
    sea_cand: float = 0.0
    """Squared errors of raw and of it against the reference less the saved current (a
    restored calibration saved with one, :data:`RESTORE_SEA_MAX_AGE_S`)."""
    n_sea: int = 0
    sea_fixed: bool = False
    """``beta`` is the sea as it stood before a change of the sensor the detector saw (a
    calibration it withdrew): raw and it are judged in it, and it is not fitted again."""
    early: bool = False
    """A restored calibration applied on its first samples (they told it from raw in the
    saved sea), validated in place over the rest of its window."""
    n: int = 0
    samples: list[tuple[float, float, float, float]] | None = None
    """A restored one's validation samples (in the water frame): raw's and its error against the reference,
    and the heading's (cos, sin): judged at the end (:func:`judge_restored`)."""
    beta: tuple[float, float] | None = None
    """Its own current (see :meth:`emlogd.pipeline.evidence.SeaMemory.current`), once fitted."""
    common_raw: float = 0.0
    common_cand: float = 0.0
    """Squared errors of raw and of it in the common sea (:func:`common_current`)."""
    n_common: int = 0
    separation: Separation | None = None
    """A calibration withdrawn for cause in the water frame (the log did not jump): the
    fit that tells it from raw whatever the current (:mod:`emlogd.pipeline.separation`)."""

    @classmethod
    def withdrawn(cls, p: Params, std: Mapping[str, float | None], water: bool) -> Candidate:
        """A calibration withdrawn for cause, to be validated again (in the water frame,
        on what no current explains: :meth:`separate`)."""
        return cls(p, math.nan, "revalidate", std, separation=Separation() if water else None)

    def score_common(self, d_raw: float, d_cand: float, sea: float | None) -> None:
        """Raw's and its error against the reference in the common sea (β along the
        hull ``sea``; None: not determined there, not scored)."""
        if sea is not None:
            self.common_raw += (d_raw - sea) ** 2
            self.common_cand += (d_cand - sea) ** 2
            self.n_common += 1

    def separate(self, t: float, d_raw: float, ref: float, cs: HeadingCS) -> None:
        """One sample of raw's error against the reference ``ref`` for :attr:`separation`."""
        if self.separation is not None and cs is not None:
            self.separation.add(t, d_raw, self.params.forward(ref) - ref, cs)

    def recall(self, mem: SeaMemory, t: float) -> None:
        """The sea memory's samples before ``t`` for :attr:`separation`
        (:meth:`~emlogd.pipeline.separation.Separation.add_memory`)."""
        if self.separation is not None:
            self.separation.add_memory(mem, self.params, t)

    def in_sea_before(self, beta: tuple[float, float]) -> None:
        """Judged in the sea ``beta`` as it stood before the log jumped, raw and it alike
        (:attr:`sea_fixed`), not on :attr:`separation`."""
        self.beta = beta
        self.sea_fixed = True
        self.separation = None


def worse(r: float, r_raw: float) -> bool:
    """An RMSE ``r`` is worse than raw's (:data:`WORSE_FACTOR`, :data:`WORSE_MARGIN_MPS`)."""
    return r > r_raw * WORSE_FACTOR + WORSE_MARGIN_MPS


def beats_raw(cand: Candidate, r_raw: float, r_cand: float, detail: dict[str, object]) -> bool:
    """Raw is worse than a new or withdrawn candidate by the margin (:func:`worse` the
    other way round), after a current of each one's own (``r_raw``, ``r_cand``) and,
    where it was scored, in the common sea (:func:`common_current`)."""
    if not worse(r_raw, r_cand):
        return False
    n = cand.n_common
    if not n:
        return True
    c_raw, c_cand = math.sqrt(cand.common_raw / n), math.sqrt(cand.common_cand / n)
    detail["rmse_raw_common_sea"] = round(c_raw, 4)
    detail["rmse_candidate_common_sea"] = round(c_cand, 4)
    return worse(c_raw, c_cand)


def judge_withdrawn(cand: Candidate, detail: dict[str, object], final: bool = True) -> bool | None:
    """A calibration withdrawn for cause (the log did not jump), on its window so far.

    Re-applied (True) when raw is worse than it by the margin after a current of each
    one's own and in the common sea (:func:`beats_raw`: the withdrawal was evidence
    against it, a tie none for it), or where the window tells it from raw whatever the
    current (:attr:`Candidate.separation`) and it is the better one. Refused (False) on
    that evidence alone: a current guessed from a window that cannot tell a current from
    a scale error (one heading, one speed) may favour raw by chance. Neither: None, and
    False once the window is ``final``.
    """
    n = cand.n
    r_raw, r_cand = math.sqrt(cand.raw / n), math.sqrt(cand.cand / n)
    sep = cand.separation
    verdict = None if sep is None else sep.verdict(detail)
    if verdict is not None:
        return verdict
    if sep is not None and sep.partial():  # the calibration half right: nothing re-applied
        return False if final else None
    if beats_raw(cand, r_raw, r_cand, detail):
        return True
    return False if final or sep is None else None


def judge_saved_sea(cand: Candidate, detail: dict[str, object]) -> bool:
    """Raw and it against the reference less the saved current: not worse than raw."""
    n = cand.n
    s_raw, s_cand = math.sqrt(cand.sea_raw / n), math.sqrt(cand.sea_cand / n)
    detail["rmse_raw_saved_sea"] = round(s_raw, 4)
    detail["rmse_candidate_saved_sea"] = round(s_cand, 4)
    return not worse(s_cand, s_raw)


def heading_spread(samples: list[tuple[float, float, float, float]]) -> float:
    """One minus the mean resultant length of a restored calibration's validation
    samples' headings (:data:`RESTORE_MIN_HEADING_SPREAD`)."""
    a = np.asarray(samples, dtype=np.float64)
    return 1.0 - math.hypot(float(np.mean(a[:, 2])), float(np.mean(a[:, 3])))


def judge_own_currents(cand: Candidate, detail: dict[str, object]) -> bool | None:
    """A restored calibration, on a window whose headings tell a current from an
    offset (:data:`RESTORE_MIN_HEADING_SPREAD`): raw and it each judged after a
    current of their own fitted to the window; not worse than raw. None on a
    narrower window."""
    assert cand.samples is not None
    a = np.asarray(cand.samples, dtype=np.float64)
    d_raw, d_c, c, s = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    spread = heading_spread(cand.samples)
    detail["heading_spread"] = round(spread, 3)
    if spread < RESTORE_MIN_HEADING_SPREAD:
        return None
    r_raw = _rms_after_current(d_raw, c, s)
    r_cand = _rms_after_current(d_c, c, s)
    detail["rmse_raw_own_current"] = round(r_raw, 4)
    detail["rmse_candidate_own_current"] = round(r_cand, 4)
    return not worse(r_cand, r_raw)


def judge_restored(
    cand: Candidate,
    detail: dict[str, object],
    kf: KfConfig,
    restored_sea: tuple[float, float, float] | None,
    restored_sea_std: tuple[float, float] | None,
    t_first: float | None,
) -> bool:
    """A restored calibration in the water frame, on its validation window.

    Where the window's headings tell a current from an offset
    (:data:`RESTORE_MIN_HEADING_SPREAD`), raw and it are each judged after a current
    of their own fitted to the window. Elsewhere (a straight leg) it is applied when
    it is not worse than raw in the saved sea, or when the current its errors imply
    is one the sea can have (:data:`RESTORE_SEA_SIGMAS`). Beyond, it is refused only
    where the current raw's errors imply is the likelier by as many σ
    (``implied² − implied_raw² > allowance²``): a state file that implies an impossible
    current where raw implies a likely one is refused, and one whose sea moved (raw's
    current as odd as its own) keeps the verdict that made it."""
    verdict = judge_own_currents(cand, detail)
    if verdict is not None:
        return verdict
    assert cand.samples is not None
    a = np.asarray(cand.samples, dtype=np.float64)
    d_c, c, s = a[:, 1], a[:, 2], a[:, 3]
    if cand.n_sea == cand.n and judge_saved_sea(cand, detail):
        return True
    allowance = math.sqrt(kf.current_p0_m2ps2)
    centre = (0.0, 0.0)
    sea = restored_sea
    if sea is not None:
        centre = (sea[0], sea[1])
        sd = restored_sea_std or (0.0, 0.0)
        age = max((t_first or sea[2]) - sea[2], 0.0)
        var = max(sd[0], sd[1]) ** 2 + kf.current_psd_m2ps3 * age
        allowance = min(RESTORE_SEA_SIGMAS * math.sqrt(var), allowance)
    # its mean error were the sea the centre: the current it implies, less the centre
    sea_cs = centre[0] * c + centre[1] * s
    implied = float(np.mean(d_c + sea_cs))
    implied_raw = float(np.mean(a[:, 0] + sea_cs))
    detail["implied_current_mps"] = round(implied, 4)
    detail["implied_current_raw_mps"] = round(implied_raw, 4)
    detail["current_allowance_mps"] = round(allowance, 4)
    # refused only where raw's current is the likelier by RESTORE_SEA_SIGMAS: a sea that
    # moved makes raw's current as odd as its own, a wrong calibration its own alone
    return implied**2 - implied_raw**2 <= allowance**2


def judge_early(
    cand: Candidate,
    detail: dict[str, object],
    kf: KfConfig,
    restored_sea: tuple[float, float, float] | None,
    restored_sea_std: tuple[float, float] | None,
) -> bool:
    """A restored calibration on its first :data:`RESTORE_EARLY_SAMPLES`: applied then
    when raw is worse than it by the margin in the saved sea, or, saved with its sea, in
    the water frame on a straight leg (headings spread less than
    :data:`RESTORE_MIN_HEADING_SPREAD`), when :func:`judge_restored` on them applies it.
    A window that turns waits for the whole window's currents of their own; so does a
    calibration saved without its sea, whose allowance there bounds nothing (a healthy
    one applied on half a second of a 10-Hz log was withdrawn by the re-check's first
    6 s at one heading)."""
    n = cand.n
    if cand.n_sea == n:
        s_raw, s_cand = math.sqrt(cand.sea_raw / n), math.sqrt(cand.sea_cand / n)
        detail["rmse_raw_saved_sea"] = round(s_raw, 4)
        detail["rmse_candidate_saved_sea"] = round(s_cand, 4)
        if worse(s_raw, s_cand):
            return True
    samples = cand.samples
    if restored_sea is None or samples is None or len(samples) != n:
        return False
    if heading_spread(samples) >= RESTORE_MIN_HEADING_SPREAD:
        return False
    return judge_restored(cand, detail, kf, restored_sea, restored_sea_std, cand.t0)
