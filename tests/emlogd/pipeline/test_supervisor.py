"""The supervisor on its own: what it applies before, without and after a reference."""

from __future__ import annotations

import math
import random
from collections.abc import Mapping

import pytest

from calib.models import Layout, Params, check_model
from emlogd.pipeline.counters import Counters
from emlogd.pipeline.learner import Offer
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.supervisor import RESTORE_WAIT_S, Candidate, Supervisor

RESTORED = Params("EM3", m=0.1, b_mps=0.05)


class _NoOffer:
    """A learner with nothing to offer."""

    def offer(self) -> Offer | None:
        return None

    @property
    def param_std(self) -> Mapping[str, float]:
        return {"m": 0.01, "b": 0.01}


def _applied(sup: Supervisor) -> Params | None:
    """The applied calibration now (a call: what a step changes is not narrowed away)."""
    return sup.applied


def _candidate(sup: Supervisor) -> Candidate | None:
    """The candidate now (a call, as :func:`_applied`)."""
    return sup.candidate


class _Offers:
    """A learner that offers one calibration."""

    def __init__(self, p: Params) -> None:
        self.p = p

    def offer(self) -> Offer | None:
        return Offer(self.p, {"m": 0.01, "b": 0.01})

    @property
    def param_std(self) -> Mapping[str, float]:
        return {"m": 0.01, "b": 0.01}


def _sup(
    restored: Params | None = RESTORED, s: UutSettings | None = None
) -> tuple[Supervisor, list[str]]:
    if s is None:
        s = UutSettings(port="log", reference_port="dvl", lag_s=0.0)
    kinds: list[str] = []
    sup = Supervisor(
        s,
        Layout(check_model(s.model), s.current),
        restored,
        {"m": 0.01, "b": 0.01},
        lambda t, k, d: kinds.append(k),
        Counters(),
    )
    return sup, kinds


def test_a_restored_calibration_waits_for_its_validation() -> None:
    """Raw passes through; the calibration is the candidate and the last good one."""
    sup, _ = _sup()
    assert _applied(sup) is None and sup.correct(2.0) == 2.0
    assert sup.candidate is not None and sup.candidate.kind == "restored"
    assert sup.kept == RESTORED and "awaiting validation" in sup.note


def test_without_a_reference_it_is_applied_unverified() -> None:
    """No reference heard RESTORE_WAIT_S after the first reading: applied, unverified."""
    sup, kinds = _sup()
    sup.reading(0.0, False)
    sup.reading(RESTORE_WAIT_S - 1.0, False)
    assert _applied(sup) is None
    sup.reading(RESTORE_WAIT_S, False)
    assert _applied(sup) == RESTORED and sup.unverified and "unverified" in sup.note
    assert kinds == ["calibration_unverified"]


def test_a_reference_heard_keeps_it_waiting() -> None:
    """Once a reference has been heard, the restored calibration must validate first."""
    sup, _ = _sup()
    sup.reading(0.0, True)
    sup.reading(10.0 * RESTORE_WAIT_S, False)
    assert _applied(sup) is None


def test_a_validated_restored_calibration_is_applied() -> None:
    """Scored against a reference the calibration explains, it is applied."""
    sup, kinds = _sup()
    for k in range(40):
        u = 1.5 + 0.02 * k
        sup.observe(float(k), RESTORED.forward(u), u, None, _NoOffer())
    assert _applied(sup) == RESTORED and "calibrated" in kinds


def test_nothing_restored_is_a_reset() -> None:
    """Without a calibration there is nothing to keep."""
    sup, _ = _sup(None)
    assert sup.kept is None and sup.candidate is None and sup.note == ""


def _noisy(k: int) -> float:
    """A reading's noise: ±0.05 m/s alternating."""
    return 0.05 if k % 2 else -0.05


@pytest.mark.parametrize(("offset", "applied"), [(0.004, False), (0.1, True)])
def test_a_new_calibration_must_beat_raw_by_the_margin(offset: float, applied: bool) -> None:
    """A log reading ``offset`` high in ±0.05 m/s of noise, offered the exact bias: it
    beats raw in both cases, but only the 0.1 m/s one by the margin raw would be
    withdrawn on (a 4-mm gain is no evidence: raw stays)."""
    sup, kinds = _sup(None)
    source = _Offers(Params("EM3", b_mps=offset))
    for k in range(300):
        u = 2.0 + 0.3 * math.sin(k / 20.0)
        sup.observe(float(k), u + offset + _noisy(k), u, None, source)
    assert (_applied(sup) is not None) is applied
    assert ("calibrated" in kinds) is applied and ("candidate_rejected" in kinds) is not applied


@pytest.mark.parametrize(("offset", "applied"), [(0.004, False), (0.1, True)])
def test_a_withdrawn_calibration_comes_back_only_on_evidence(offset: float, applied: bool) -> None:
    """A calibration withdrawn for cause re-validates: tying raw (within the margin) it
    stays withdrawn; beating raw by the margin it is applied again."""
    sup, kinds = _sup(None)
    p = Params("EM3", b_mps=offset)
    sup.candidate = Candidate(p, math.nan, "revalidate", {"m": 0.01, "b": 0.01})
    for k in range(40):
        u = 2.0 + 0.3 * math.sin(k / 20.0)
        sup.observe(float(k), u + offset + _noisy(k), u, None, _NoOffer())
    assert (_applied(sup) == p) is applied
    assert kinds == (["calibrated"] if applied else ["candidate_rejected"])


REFUSED = Params("EM3", b_mps=0.004)
"""The withdrawn calibration the refusal tests re-validate: a log reading 4 mm high."""


def _refused() -> tuple[Supervisor, list[str]]:
    """A supervisor whose re-validation of :data:`REFUSED` (withdrawn for cause) refused
    it over 40 readings on one heading, and its event kinds."""
    sup, kinds = _sup(None)
    sup.candidate = Candidate(REFUSED, math.nan, "revalidate", {"m": 0.01, "b": 0.01})
    for k in range(40):
        u = 2.0 + 0.3 * math.sin(k / 20.0)
        sup.observe(float(k), u + 0.004 + _noisy(k), u, None, _NoOffer())
    return sup, kinds


@pytest.mark.parametrize(("b_offered", "proposed"), [(0.004, False), (0.01, False), (0.05, True)])
def test_a_refused_withdrawn_calibration_is_not_offered_again_unchanged(
    b_offered: float, proposed: bool
) -> None:
    """A calibration withdrawn for cause and refused by its re-validation: an offer
    within its σ of it (0.01 here) carries no evidence the refusal did not weigh and is
    no new candidate; one the learner moved beyond its σ is."""
    sup, kinds = _refused()
    assert kinds == ["candidate_rejected"] and _candidate(sup) is None
    sup.observe(40.0, 2.0, 2.0, None, _Offers(Params("EM3", b_mps=b_offered)))
    assert (_candidate(sup) is not None) is proposed


@pytest.mark.parametrize(("turn_deg", "proposed"), [(0.0, False), (5.0, False), (120.0, True)])
def test_a_refusal_lasts_until_the_headings_turn(turn_deg: float, proposed: bool) -> None:
    """After the refusal, 40 readings whose heading sweeps ``turn_deg``: on one heading
    (or 5°) the same offer is still no new candidate; after a 120° turn the offset and a
    current are told apart again and it is one (the learner's offer is new evidence)."""
    sup, _ = _refused()
    assert sup.refused == REFUSED
    for k in range(40, 80):
        h = math.radians(turn_deg * (k - 40) / 39.0)
        u = 2.0 + 0.3 * math.sin(k / 20.0)
        sup.observe(float(k), u + 0.004 + _noisy(k), u, (math.cos(h), math.sin(h)), _NoOffer())
    sup.observe(80.0, 2.0, 2.0, (1.0, 0.0), _Offers(Params("EM3", b_mps=0.004)))
    assert (_candidate(sup) is not None) is proposed


def test_a_surging_vessel_in_a_rising_current_keeps_its_calibration() -> None:
    """A healthy log (gain 1.27) on a straight leg: the vessel's speed through water
    swings ±0.02 m/s over two minutes while the current along the hull rises 0.72 m/s an
    hour, so the ground reference holds while the reading follows the water through its
    gain. The log does not drift against the water: the calibration stays applied."""
    p = Params("EM3", m=0.27, b_mps=0.05)
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True)
    sup, kinds = _sup(p, s)
    heading = (math.cos(0.5), math.sin(0.5))
    for k in range(900):
        t = float(k)
        stw = 1.6 + 0.02 * math.sin(2.0 * math.pi * t / 120.0)
        ref = stw + 0.0002 * t
        sup.observe(t, p.forward(stw) + 0.1 * _noisy(k), ref, heading, _NoOffer())
    assert _applied(sup) == p, kinds


def test_a_withdrawn_calibration_waits_for_evidence_no_current_explains() -> None:
    """A log reading 25 % high, withdrawn for cause, re-validates at one heading where
    the current along the hull (+0.25 m/s at 1 m/s) makes raw match the ground
    reference: no current the window holds tells the two apart, so raw is not preferred
    on a guess; once the vessel speeds up (raw's error then grows with the speed, which
    no current at one heading can do) the calibration is applied again."""
    p = Params("EM3", m=0.25)
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True)
    sup, kinds = _sup(None, s)
    sup._apply(0.0, p, {"m": 0.01, "b": 0.01})
    sup.withdraw(0.0, "a test", {})
    heading = (1.0, 0.0)
    for k in range(1, 181):
        stw = 1.0 if k <= 60 else 1.6
        sup.observe(float(k), p.forward(stw) + _noisy(k), stw + 0.25, heading, _NoOffer())
        if k == 60:  # a minute at one speed: no verdict, raw passes through
            assert "candidate_rejected" not in kinds and _applied(sup) is None
    assert _applied(sup) == p and kinds == ["fallback", "calibrated"]


def test_after_a_silence_the_calibrations_are_judged_in_the_new_sea() -> None:
    """A healthy log (gain 1.15) applied through ten minutes of turning in 0.1 m/s of
    current to the south; then five minutes of silence (the next capture, another sea)
    and a straight leg north in 0.12 m/s to the north. In the old sea raw would look
    right there (its error +0.24 m/s, the current's change along the hull 0.22 m/s); the
    sea memory forgets what came before the silence, the currents are fitted on the new
    leg, and the calibration (applied again as the leg starts, its re-check window empty)
    stays applied."""
    p = Params("EM3", m=0.15)
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True)
    sup, kinds = _sup(None, s)
    sup._apply(0.0, p, {"m": 0.01, "b": 0.01})
    for k in range(600):
        hd = math.radians(0.6 * k)
        ref = 1.6 - 0.1 * math.cos(hd)
        sup.observe(
            float(k),
            p.forward(1.6) + 0.2 * _noisy(k),
            ref,
            (math.cos(hd), math.sin(hd)),
            _NoOffer(),
        )
    assert _applied(sup) == p, kinds
    sup._apply(900.0, p, {"m": 0.01, "b": 0.01})  # validated on the old sea: re-check empty
    for k in range(900, 1500):
        sup.observe(float(k), p.forward(1.6) + 0.2 * _noisy(k), 1.6 + 0.12, (1.0, 0.0), _NoOffer())
    assert _applied(sup) == p, kinds


def _stepped_log(t: float, rng: random.Random) -> tuple[float, float]:
    """The reading and the reference at ``t`` of the 0.2-Hz tests below: the speed
    through the water swinging 1.4-2.2 m/s over 15 minutes, the reference wandering
    0.07 m/s over 3 minutes, 0.02 m/s of noise on each, the log's gain 1.15 until
    1200 s and 1.0 from then on."""
    stw = 1.8 + 0.4 * math.sin(2.0 * math.pi * t / 900.0)
    ref = stw + 0.07 * math.sin(2.0 * math.pi * t / 180.0) + rng.gauss(0.0, 0.02)
    gain = 1.15 if t < 1200.0 else 1.0
    return gain * stw + rng.gauss(0.0, 0.02), ref


def _stepped_log_applied() -> tuple[random.Random, Params, Supervisor, list[str]]:
    """The seeded noise of :func:`_stepped_log`, the log's calibration before its step
    (m 0.15), and a supervisor with it applied, with the kinds of its events."""
    p = Params("EM3", m=0.15)
    sup, kinds = _sup(None)
    sup._apply(0.0, p, {"m": 0.01, "b": 0.01})
    return random.Random(1), p, sup, kinds


def test_at_one_reading_every_5_s_a_calibration_wrong_after_a_step_is_withdrawn_soon() -> None:
    """A log read every 5 s (gain 1.15, applied) against a reference wandering 0.07 m/s
    over 3 minutes, in 0.02 m/s of seeded noise. The calibration is withdrawn at 1130 s
    and re-validates; at 1200 s the log's gain steps to 1.0, so the calibration is wrong
    from then on. Counted in samples, the re-validation (20 readings: 100 s) straddled
    the step and re-applied it at 1225 s, and the re-check (60 readings in a window of a
    300-s half-life: 8.5 minutes) withdrew it only at 1735 s; at the cadence's weight the
    re-validation ends before the step and the re-check withdraws it within 150 s of it."""
    rng, _, sup, kinds = _stepped_log_applied()
    wrong: list[float] = []
    for k in range(500):
        t = 5.0 * k
        if t == 1130.0:
            sup.withdraw(t, "a test", {})
        sup.observe(t, *_stepped_log(t, rng), None, _NoOffer())
        if t >= 1200.0 and _applied(sup) is not None:
            wrong.append(t)
    assert wrong and wrong[-1] - 1200.0 < 150.0, (wrong[:1], wrong[-1:], kinds)
    assert _applied(sup) is None and kinds[-1] == "candidate_rejected"


def test_at_one_reading_every_5_s_a_gain_step_after_an_alarm_of_the_sea_is_caught() -> None:
    """The log and reference of the test above, the calibration applied all along: the
    reference's wander alarms the change detector every 90 s or so, each alarm the sea's
    (the calibration beats raw over its run). At 1200 s, 10 s after such an alarm, the
    gain steps to 1.0. The baseline emptied at the alarm took 30 s of readings to fill
    and absorbed the step, and the shift test's 3-s windows held one reading each side, so
    the step's alarm was judged on the whole run (noise and raw's offset before the
    step) as the sea's: withdrawn by the re-check at 1680 s. Now the baseline starts from
    the alarm's run and the shift test holds two readings each side: withdrawn by the
    change detector within 30 s."""
    rng, p, sup, kinds = _stepped_log_applied()
    wrong: list[float] = []
    for k in range(300):
        t = 5.0 * k
        sup.observe(t, *_stepped_log(t, rng), None, _NoOffer())
        assert t >= 1200.0 or _applied(sup) == p, (t, kinds)  # no false withdrawal
        if t >= 1200.0 and _applied(sup) is not None:
            wrong.append(t)
    assert wrong and wrong[-1] - 1200.0 < 30.0, (wrong[:1], wrong[-1:], kinds)
    assert _applied(sup) is None and sup.counters.changes == 1, kinds


@pytest.mark.parametrize("current", [False, True])
def test_a_jump_of_the_reference_alone_keeps_the_calibration(current: bool) -> None:
    """A healthy log (gain 1.1, applied) on a straight leg at 2 m/s through the water,
    read at 1 Hz in 0.02 m/s of seeded noise; at 300 s the reference jumps by +0.2 m/s
    and stays (a tidal front, or a tack's new leeway along the hull) while the log reads
    as before. Over the alarm's run raw then fits the reference better than the
    calibration (its +0.2 m/s error cancels the jump): that is the sea's doing, not the
    sensor's, so the alarm is the sea's (the learner's current re-opens) and the
    calibration stays applied."""
    p = Params("EM3", m=0.1)
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=current)
    sup, kinds = _sup(None, s)
    sup._apply(0.0, p, {"m": 0.01, "b": 0.01})
    rng = random.Random(3)
    seen_sea = False
    for k in range(420):
        t = float(k)
        ref = 2.0 + (0.2 if t >= 300.0 else 0.0) + rng.gauss(0.0, 0.02)
        sup.observe(t, p.forward(2.0) + rng.gauss(0.0, 0.02), ref, (1.0, 0.0), _NoOffer())
        seen_sea = seen_sea or sup.sea_changed
        sup.sea_changed = False  # taken by the owner
    assert seen_sea and _applied(sup) == p and "fallback" not in kinds, kinds


TACKED = Params("EM3", m=0.1, b_mps=-0.6)
"""The calibration the two-heading tests apply: right for a log whose error it is,
wrong by 0.6 m/s less a tenth of the speed for an exact one."""


@pytest.mark.parametrize(("log", "withdrawn"), [(Params("EM3"), True), (TACKED, False)])
def test_a_calibration_the_sea_memory_refutes_goes_at_the_next_verdict(
    log: Params, withdrawn: bool
) -> None:
    """Two headings 90° apart, eight minutes each, either side of a 0.5-m/s current
    along their bisector (0.35 m/s along the hull on both), the speed through the water
    swinging 1.7-2.3 m/s. Applied to an exact log, :data:`TACKED`'s error is a current
    on each heading, so a current of its own (and raw judged in it) keeps it; but its
    error grows with the speed and no current follows the speed, so the sea memory
    tells raw from it: at the next new candidate's verdict it is withdrawn for cause
    (kept as the last good one). Applied to a log whose error it is, it stays."""
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True)
    sup, kinds = _sup(None, s)
    sup._apply(0.0, TACKED, {"m": 0.01, "b": 0.01})
    offer = _Offers(Params("EM3", m=0.1, b_mps=-0.5))
    for k in range(1200):
        t = float(k)
        h = math.radians(10.0 if (k // 480) % 2 == 0 else 100.0)
        stw = 2.0 + 0.3 * math.sin(2.0 * math.pi * t / 90.0)
        ref = stw + 0.5 * math.cos(h - math.radians(55.0))
        sup.observe(t, log.forward(stw) + 0.2 * _noisy(k), ref, (math.cos(h), math.sin(h)), offer)
    assert ("fallback" in kinds) is withdrawn, kinds
    assert (_applied(sup) is None) is withdrawn
    assert sup.kept is not None


def test_an_offer_the_sea_memory_refutes_is_not_applied() -> None:
    """The same two headings and current, nothing applied, an exact log offered
    :data:`TACKED`: after a current of each one's own (a current takes its error on
    each heading) it beats raw, but the sea memory tells raw from it (its error follows
    the speed): refused."""
    s = UutSettings(port="log", reference_port="dvl", lag_s=0.0, current=True)
    sup, kinds = _sup(None, s)
    offer = _Offers(TACKED)
    for k in range(1200):
        t = float(k)
        h = math.radians(10.0 if (k // 480) % 2 == 0 else 100.0)
        stw = 2.0 + 0.3 * math.sin(2.0 * math.pi * t / 90.0)
        ref = stw + 0.5 * math.cos(h - math.radians(55.0))
        sup.observe(t, stw + 0.2 * _noisy(k), ref, (math.cos(h), math.sin(h)), offer)
    assert "calibrated" not in kinds and "candidate_rejected" in kinds, kinds
    assert _applied(sup) is None
