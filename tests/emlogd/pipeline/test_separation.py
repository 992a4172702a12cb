"""Whether a window tells raw from a calibration whatever the current."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.models import Params
from emlogd.pipeline.evidence import CUSUM_MAX_GAP_S, SeaMemory
from emlogd.pipeline.revalidation import Candidate, judge_withdrawn
from emlogd.pipeline.separation import Separation

CAL = Params("EM3", m=0.2, b_mps=0.03)


def _noise(k: int) -> float:
    """A reading's noise, m/s: a fixed sequence of ±0.05."""
    return 0.05 * math.sin(1.7 * k * k)


def _window(truth: str, speeds: list[float], headings: list[float]) -> Separation:
    """One sample a second at each (speed, heading) pair in turn, in a current of
    (0.15, −0.2) m/s; the log reads through ``CAL`` when ``truth`` is "cal", else reads
    the speed through the water."""
    sep = Separation()
    k = 0
    for v in speeds:
        for psi in headings:
            for _ in range(30):
                cs = (math.cos(psi), math.sin(psi))
                ref = v + 0.15 * cs[0] - 0.2 * cs[1]
                raw = (CAL.forward(v) if truth == "cal" else v) + _noise(k)
                sep.add(float(k), raw - ref, CAL.forward(ref) - ref, cs)
                k += 1
    return sep


@pytest.mark.parametrize("truth", ["cal", "raw"])
def test_one_heading_and_one_speed_tell_nothing(truth: str) -> None:
    """The current takes either one's offset: no verdict either way."""
    assert _window(truth, [1.2], [0.4, 0.4, 0.4]).verdict() is None


@pytest.mark.parametrize(
    ("speeds", "headings"), [([1.0, 1.8], [0.4]), ([1.2], [0.0, 1.2, 2.4, 3.6])]
)
@pytest.mark.parametrize("truth", ["cal", "raw"])
def test_a_speed_change_or_a_turn_tells_them_apart(
    truth: str, speeds: list[float], headings: list[float]
) -> None:
    """A change of the speed at one heading, or a turn at one speed: the one that reads
    the log right wins, whatever the current."""
    detail: dict[str, object] = {}
    assert _window(truth, speeds, headings).verdict(detail) is (truth == "cal")
    assert isinstance(detail["separation_w"], float)


def test_the_memory_before_a_silence_is_another_sea() -> None:
    """Seeded from the sea memory, only the samples since its last long silence count."""
    mem = SeaMemory()
    for k in range(200):  # before the silence: a speed change that would separate
        v = 1.0 if k < 100 else 1.8
        mem.add(float(k), CAL.forward(v) + _noise(k), v, (1.0, 0.0))
    t1 = 200.0 + 2.0 * CUSUM_MAX_GAP_S
    for k in range(60):  # after it: one heading, one speed
        mem.add(t1 + k, CAL.forward(1.2) + _noise(k), 1.2, (1.0, 0.0))
    sep = Separation()
    sep.add_memory(mem, CAL, t1 + 60.0)
    assert sep.n == 60 and sep.verdict() is None


@pytest.mark.parametrize(("times", "verdict"), [(3.0, None), (-3.0, False)])
def test_errors_neither_one_explains(times: float, verdict: bool | None) -> None:
    """A log ``times`` as wrong as the calibration says (``w`` near it, far from both
    raw's 0 and its 1): three times re-applies nothing (the window measures something
    else, not that the calibration is right); minus three refuses it (raw is the safe
    one)."""
    sep = Separation()
    for k in range(120):
        v = 1.0 if k < 60 else 1.8
        raw = v + times * (CAL.forward(v) - v) + _noise(k)
        sep.add(float(k), raw - v, CAL.forward(v) - v, (1.0, 0.0))
    w, se = sep.w()
    assert abs(w - times) < 0.5 and se < 0.3 and sep.verdict() is verdict


def _correlated_window(seed: int, tau_s: float) -> Separation:
    """Twenty minutes at 1 Hz on one heading, the speed through the water changing
    between 1.0 and 1.8 m/s every 100 s; the log reads it (raw is right, ``w`` is 0) and
    the reference's error is AR(1) with time constant ``tau_s`` (0: white), 0.05 m/s."""
    rng = np.random.default_rng(seed)
    phi = math.exp(-1.0 / tau_s) if tau_s > 0.0 else 0.0
    e, sep = 0.0, Separation()
    for k in range(1200):
        v = 1.0 if (k // 100) % 2 else 1.8
        e = phi * e + math.sqrt(1.0 - phi * phi) * 0.05 * float(rng.standard_normal())
        ref = v + 0.1 + e
        sep.add(float(k), v - ref, CAL.forward(ref) - ref, (1.0, 0.0))
    return sep


def test_the_standard_error_is_honest_about_correlated_residuals(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A reference whose errors are correlated over 20 s (GNSS): counting one sample a
    second, ``w`` lands beyond 3 standard errors of its true 0 in most windows; from the
    blocks' scatter in few. White errors: the blocks leave the standard error as it was
    (within their own scatter)."""
    from emlogd.pipeline import separation

    def z_and_se(seed: int, tau_s: float) -> tuple[float, float]:
        w, se = _correlated_window(seed, tau_s).w()
        return abs(w) / se, se

    honest = [z_and_se(seed, 20.0) for seed in range(20)]
    white = [z_and_se(seed, 0.0)[1] for seed in range(20)]
    monkeypatch.setattr(separation, "SEPARATION_MIN_BLOCKS", 10**9)  # one a second alone
    naive = [z_and_se(seed, 20.0) for seed in range(20)]
    white_naive = [z_and_se(seed, 0.0)[1] for seed in range(20)]
    assert sum(z > 3.0 for z, _ in naive) >= 8
    assert sum(z > 3.0 for z, _ in honest) <= 2
    assert all(h[1] >= 2.0 * n[1] for h, n in zip(honest, naive, strict=True))
    assert all(a <= 1.5 * b for a, b in zip(white, white_naive, strict=True))


@pytest.mark.parametrize(("times", "partial"), [(0.65, True), (1.0, False), (3.0, False)])
def test_errors_a_fraction_of_the_calibrations_are_partial(times: float, partial: bool) -> None:
    """A log ``times`` as wrong as the calibration says: at 0.65 (between raw's 0 and its
    1, too near ½ to be told from either by 3 standard errors of the noise and the
    current) the window is :meth:`~Separation.partial`, and ``judge_withdrawn``
    re-applies nothing on it, however the RMSEs after currents fitted to it stand (a
    part of the error neither raw's nor the calibration's, which those currents take);
    the calibration right, or ``w`` beyond 1, is no such window."""
    sep = Separation()
    for k in range(120):
        v = 1.0 if k < 60 else 1.3
        raw = v + times * (CAL.forward(v) - v) + _noise(k)
        sep.add(float(k), raw - v, CAL.forward(v) - v, (1.0, 0.0))
    assert sep.partial() is partial
    if not partial:
        return
    assert sep.verdict() is None
    cand = Candidate(CAL, 0.0, "revalidate", separation=sep, raw=1.0, cand=0.01, n=100)
    assert judge_withdrawn(cand, {}, final=False) is None
    assert judge_withdrawn(cand, {}, final=True) is False
    cand.separation = None  # the RMSEs alone would re-apply it
    assert judge_withdrawn(cand, {}) is True


@pytest.mark.parametrize("truth", ["cal", "raw"])
def test_the_references_noise_does_not_pull_w(truth: str) -> None:
    """A GNSS reference with 0.1 m/s of white noise, a calibration of m −0.05 (the
    reference's noise is in ``d`` and, times m, in ``G``: computed per sample, ``w`` is
    pulled towards −1/m: 1.40 and 0.42 here), one heading and a speed that swings by
    ±0.8 m/s over four minutes: the one that reads the log right wins."""
    cal = Params("EM3", m=-0.05, b_mps=0.02)
    rng = np.random.default_rng(7)
    sep = Separation()
    cs = (math.cos(0.4), math.sin(0.4))
    for k in range(1200):
        v = 2.0 + 0.8 * math.sin(2.0 * math.pi * k / 240.0)
        ref = v + 0.15 * cs[0] - 0.2 * cs[1] + 0.1 * float(rng.standard_normal())
        raw = (cal.forward(v) if truth == "cal" else v) + _noise(k) * 0.4
        sep.add(float(k), raw - ref, cal.forward(ref) - ref, cs)
    w, _ = sep.w()
    assert abs(w - (1.0 if truth == "cal" else 0.0)) < 0.25
    assert sep.verdict() is (truth == "cal")
