"""The two-axis identifiability rule on windows built to pass or fail each rule."""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import ModelError
from calib.models import CURRENT
from calib.twoaxis_ident import TwoAxisRule, judge_two_axis, sway_apart_from_surge, unknowns_of
from calib.twoaxis_model import ALPHA, B_T, M_T

N = 600


def _window(
    speed_spread: float, sway_spread: float, headings: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Surge, sway, the longitudinal readings (the surge) and the headings."""
    phase = np.linspace(0.0, 6.0 * np.pi, N)
    u = 2.5 + speed_spread * np.sqrt(2.0) * np.sin(phase)
    w = sway_spread * np.sqrt(2.0) * np.sin(2.0 * phase)
    return u, w, u.copy(), headings


def test_unknowns_in_their_order() -> None:
    assert unknowns_of("EM3", True) == ("m", "b", ALPHA, M_T, B_T, CURRENT)
    assert unknowns_of("EM1", False) == ("b", ALPHA, M_T, B_T)


def test_sway_that_follows_the_surge_refuses_the_transverse_scale() -> None:
    """Circles one way: the sway spreads (0.07 m/s, past the 0.03 bound) but as a
    straight line in the surge, so the athwart reading gives one slope: the
    transverse scale and the misalignment are refused, the line in the reason."""
    u, _, raw, hd = _window(0.5, 0.0, np.linspace(0.0, 720.0, N) % 360.0)
    w = 0.02 - 0.1 * u
    assert np.std(w) > 0.03
    c, k, rest = sway_apart_from_surge(u, w)
    assert c == pytest.approx(0.02) and k == pytest.approx(-0.1) and rest < 1e-12
    ident = judge_two_axis("EM3", u, w, raw, hd, current=True)
    assert M_T in ident.unidentifiable and ALPHA in ident.unidentifiable
    assert "the sway follows the surge (w = +0.020 -0.1000·u m/s" in ident.reason
    assert "a fixed fraction of the forward speed, -0.100 of it" in ident.verdict(ALPHA).reason
    swung = w + 0.05 * np.sign(np.sin(np.linspace(0.0, 12.0 * np.pi, N)))
    assert M_T in judge_two_axis("EM3", u, swung, raw, hd, current=True).determined


def test_figure8_like_window_determines_everything() -> None:
    """Speed and sway vary, the heading turns through every sector: rules 1–4 pass."""
    u, w, raw, hd = _window(0.5, 0.2, np.linspace(0.0, 720.0, N) % 360.0)
    ident = judge_two_axis("EM3", u, w, raw, hd, current=True)
    assert ident.unidentifiable == ()
    assert ident.reason == ""
    assert not ident.nuisance_offset
    assert ident.heading_sectors == 8


def test_straight_run_refuses_current_biases_and_misalignment() -> None:
    """One heading at one speed: the current takes both biases with it (a nuisance
    offset per axis), the misalignment and the scale are refused with their reasons."""
    u, w, raw, hd = _window(0.0, 0.0, np.full(N, 45.0))
    ident = judge_two_axis("EM3", u, w, raw, hd, current=True)
    assert set(ident.unidentifiable) == {"m", "b", ALPHA, M_T, B_T, CURRENT}
    assert ident.nuisance_offset
    assert "heading covered 1 of 8 sectors" in ident.verdict(CURRENT).reason
    assert "transverse bias not separable" in ident.verdict(B_T).reason
    why = ident.verdict(ALPHA).reason
    assert why.startswith("misalignment not separable from the transverse bias and the current")
    assert "runs at different speeds tell them apart" in why


def test_circles_at_one_speed_refuse_misalignment_for_the_bias_not_the_current() -> None:
    """Circles one way at one throttle: the heading turns through every sector, so the
    current (turning with it in the hull frame) is determined, but at one speed the
    misalignment's sideways reading is one steady offset with the transverse bias:
    the reason names the bias, not the current, and says what separates them."""
    u, _, raw, hd = _window(0.0, 0.0, np.linspace(0.0, 720.0, N) % 360.0)
    w = -0.03 * u
    ident = judge_two_axis("EM3", u, w, raw, hd, current=True)
    assert CURRENT in ident.determined and ALPHA in ident.unidentifiable
    why = ident.verdict(ALPHA).reason
    assert why.startswith("misalignment not separable from the transverse bias:")
    assert "current across the hull" not in why and "is told apart" in why
    assert why.endswith("runs at different speeds tell them apart")


def test_misalignment_follows_the_transverse_scale() -> None:
    """The speed varies but the sway does not: the transverse scale is refused and
    the misalignment with it (rule 4), the rest determined."""
    u, w, raw, hd = _window(0.5, 0.0, np.linspace(0.0, 720.0, N) % 360.0)
    ident = judge_two_axis("EM3", u, w, raw, hd, current=True)
    assert ident.unidentifiable == (ALPHA, M_T)
    assert "misalignment and a transverse scale error" in ident.verdict(ALPHA).reason


def test_too_few_samples_refuses_all() -> None:
    """Twenty samples cannot carry six unknowns and their offsets."""
    u, w, raw, hd = _window(0.5, 0.2, np.linspace(0.0, 720.0, N) % 360.0)
    ident = judge_two_axis("EM3", u[::30], w[::30], raw[::30], hd[::30], current=True)
    assert ident.determined == ()
    assert "too few samples" in ident.reason


def test_rule_thresholds_checked() -> None:
    with pytest.raises(ValueError, match="non-negative"):
        TwoAxisRule(min_transverse_std_mps=-0.1)
    with pytest.raises(ValueError, match="max_std_m_t"):
        TwoAxisRule(max_std_m_t=0.0)
    u, w, raw, hd = _window(0.5, 0.2, np.linspace(0.0, 720.0, N) % 360.0)
    with pytest.raises(ModelError, match="not an unknown"):
        judge_two_axis("EM3", u, w, raw, hd, current=False).verdict(CURRENT)
