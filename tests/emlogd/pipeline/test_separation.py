"""Whether a window tells raw from a calibration whatever the current."""

from __future__ import annotations

import math

import pytest

from calib.models import Params
from emlogd.pipeline.evidence import CUSUM_MAX_GAP_S, SeaMemory
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
