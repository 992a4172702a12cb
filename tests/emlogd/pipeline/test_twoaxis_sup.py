"""The two-axis supervisor: learnt figures applied to the VBW only once the athwart
speed is not worse than raw, withdrawn when it becomes worse; the hull-frame inverse."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.models import Params, correct_array
from emlogd.pipeline.twoaxis_sup import (
    FORWARD_ONE_AXIS,
    FORWARD_OWN,
    FORWARD_RAW,
    Block,
    Figures,
    TwoAxisSupervisor,
    athwart_rmse,
    forward_rmse,
    lon_of_fit,
    noise_gain,
    one_axis_better,
)

Events = list[tuple[float, str, dict[str, object]]]


def _applied(sup: TwoAxisSupervisor) -> Figures | None:
    return sup.applied


def _candidate(sup: TwoAxisSupervisor) -> Figures | None:
    return sup.candidate


def _own(sup: TwoAxisSupervisor) -> bool:
    return sup.forward_own


def _early(sup: TwoAxisSupervisor) -> bool:
    return sup.early


LON = Params("EM3", m=-0.11, b_mps=-0.05)
"""The sensor's longitudinal error on its own axis in :func:`_blocks`."""


def _blocks(
    alpha_deg: float, n: int, t0: float = 0.0, one_axis_scale: float = 1.0, lon: Params = LON
) -> list[Block]:
    """Block means of a log turned ``alpha_deg`` (m_t −0.1, b_t 0.05, its forward axis
    ``lon``) swinging its sway in turns at a speed that varies, heading sweeping, a
    current (0.1, −0.2); the one-axis calibration's forward speed right (``u + w·tan
    α``) times ``one_axis_scale``."""
    out: list[Block] = []
    a = math.radians(alpha_deg)
    for k in range(n):
        t = t0 + k
        u = 2.0 + 0.5 * math.sin(2 * math.pi * t / 90.0)
        w = 0.3 * math.cos(2 * math.pi * t / 90.0)
        psi = (t * 3.0) % 360.0
        r = math.radians(psi)
        gs = w - 0.1 * math.sin(r) - 0.2 * math.cos(r)
        gf = u + 0.1 * math.cos(r) - 0.2 * math.sin(r)
        raw_t = 0.9 * (w * math.cos(a) - u * math.sin(a)) + 0.05
        raw_l = lon.forward(u * math.cos(a) + w * math.sin(a))
        out.append((t, one_axis_scale * (u + w * math.tan(a)), raw_t, gs, psi, raw_l, gf))
    return out


def _figures(
    alpha_deg: float, t: float = 0.0, alpha_std_deg: float = 0.1, lon: Params | None = None
) -> Figures:
    return Figures(alpha_deg, alpha_std_deg, -0.1, 0.01, 0.05, 0.01, t, lon)


def test_supervisor_applies_rejects_and_withdraws() -> None:
    """Figures worse than raw on the athwart axis are rejected; the right ones applied
    after ``validation_s``; when the sensor is turned (α 3° → 0°) the recheck finds them
    worse than raw and withdraws them."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: events.append((t, k, dict(d))))
    sup.offer(_figures(-6.0))
    for b in _blocks(3.0, 70):
        sup.observe(b)
    assert _applied(sup) is None and events[-1][1] == "two_axis_rejected"
    sup.offer(_figures(3.0, 70.0))
    for b in _blocks(3.0, 70, 71.0):
        sup.observe(b)
    assert _applied(sup) == _figures(3.0, 70.0) and events[-1][1] == "two_axis_applied"
    for b in _blocks(0.0, 130, 200.0):
        sup.observe(b)
    assert _applied(sup) is None and "two_axis_withdrawn" in [k for _, k, _ in events[-2:]]
    assert sup.kept == _figures(3.0, 70.0)  # the last good: re-validated, rejected again


def test_athwart_rmse_right_figures_reach_the_floor() -> None:
    """The right figures leave no athwart error after the current; raw keeps the
    misalignment's phantom leeway that a current cannot take (the speed varies)."""
    blocks = _blocks(3.0, 300)
    assert athwart_rmse(blocks, _figures(3.0)) == pytest.approx(0.0, abs=1e-9)
    assert athwart_rmse(blocks, None) > 0.01
    assert math.isnan(athwart_rmse([], None))


def test_hull_frame_inverts_the_sensor() -> None:
    """The forward speed a one-axis calibration gives (u + w·tan α) and the athwart
    reading on the sensor's axis turn back to (u, w) exactly."""
    f = _figures(4.0)
    a = math.radians(4.0)
    for u, w in ((3.0, 0.0), (1.5, -0.4), (0.5, 0.7)):
        raw_t = 0.9 * (w * math.cos(a) - u * math.sin(a)) + 0.05
        assert f.hull_frame(u + w * math.tan(a), raw_t) == pytest.approx((u, w), abs=1e-12)
    assert f.as_dict()["misalign_deg"] == 4.0


def test_a_sharper_estimate_replaces_the_figures_in_use() -> None:
    """An estimate within the σ of the figures applied is not validated (no churn),
    unless it determines α more sharply: then it validates and is applied, so the
    figures follow the window as it fills."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 600.0, lambda t, k, d: events.append((t, k, dict(d))))
    sup.offer(_figures(3.1, 0.0, alpha_std_deg=0.24))
    for b in _blocks(3.0, 70):
        sup.observe(b)
    assert _applied(sup) == _figures(3.1, 0.0, alpha_std_deg=0.24)
    sup.offer(_figures(3.05, 70.0, alpha_std_deg=0.23))  # within σ, hardly sharper
    assert _candidate(sup) is None
    sharper = _figures(3.0, 70.0, alpha_std_deg=0.15)
    sup.offer(sharper)
    assert _candidate(sup) == sharper
    for b in _blocks(3.0, 70, 71.0):
        sup.observe(b)
    assert _applied(sup) == sharper and events[-1][1] == "two_axis_applied"


def _validated(sup: TwoAxisSupervisor, figures: Figures, blocks: list[Block]) -> None:
    sup.offer(figures)
    for b in blocks:
        sup.observe(b)
    assert _applied(sup) == figures


def test_own_forward_speed_replaces_a_worse_one_axis_one() -> None:
    """Figures carrying the log's longitudinal parameters correct the forward speed
    themselves once the one-axis calibration's (5 % high here, the scale it traded
    with the current) is worse over the validation window; the VBW then turns back
    the figures' own forward speed, and the one-axis one is no longer used."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 600.0, lambda t, k, d: events.append((t, k, dict(d))))
    blocks = _blocks(3.0, 70, one_axis_scale=1.05)
    _validated(sup, _figures(3.0, lon=LON), blocks)
    assert sup.forward_own and events[-1][2]["forward"] == FORWARD_OWN
    r = sup.forward_scores
    assert r[FORWARD_OWN] == pytest.approx(0.0, abs=1e-9)
    assert r[FORWARD_OWN] < r[FORWARD_ONE_AXIS] < r[FORWARD_RAW]


def test_own_forward_speed_refused_where_worse_than_the_one_axis_one() -> None:
    """Longitudinal parameters that are wrong (no scale error where the log reads 11 %
    low) leave the forward speed to the one-axis calibration; the athwart figures are
    applied all the same. Figures without them never correct the forward speed."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 600.0, lambda t, k, d: events.append((t, k, dict(d))))
    _validated(sup, _figures(3.0, lon=Params("EM3", b_mps=-0.05)), _blocks(3.0, 70))
    assert not sup.forward_own and events[-1][2]["forward"] == FORWARD_ONE_AXIS
    sup = TwoAxisSupervisor(60.0, 600.0, lambda t, k, d: None)
    _validated(sup, _figures(3.0), _blocks(3.0, 70, one_axis_scale=1.05))
    assert not sup.forward_own and FORWARD_OWN not in sup.forward_scores


def test_recheck_gives_the_forward_speed_back_to_the_one_axis_calibration() -> None:
    """When the log's forward axis changes (fouled: 8 % lower) and the one-axis
    calibration follows it, the recheck finds the figures' own forward speed worse and
    goes back to the one-axis one, the athwart figures staying applied; when the
    one-axis calibration is worse again by the margin, the figures' own returns."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: events.append((t, k, dict(d))))
    _validated(sup, _figures(3.0, lon=LON), _blocks(3.0, 70, one_axis_scale=1.05))
    assert _own(sup)
    fouled = Params("EM3", m=-0.19, b_mps=-0.05)
    for b in _blocks(3.0, 130, 71.0, lon=fouled):
        sup.observe(b)
    assert not _own(sup) and sup.applied is not None
    assert events[-1][1] == "two_axis_forward_withdrawn"
    for b in _blocks(3.0, 130, 202.0, one_axis_scale=1.1):
        sup.observe(b)
    assert _own(sup) and events[-1][1] == "two_axis_forward_applied"


def test_forward_speed_set_aside_by_a_fallback_returns_at_the_next_recheck() -> None:
    """Set aside for the one-axis supervisor's fallback (no evidence against it, as
    ``TwoAxisLearner.answers`` does), the figures' own forward speed returns at the
    next recheck where it is not worse than the one-axis one, though that is not worse
    by the margin (3 mm/s against 5.5); set aside by a recheck that found it worse, it
    waits for the margin."""
    events: Events = []
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: events.append((t, k, dict(d))))
    _validated(sup, _figures(3.0, lon=LON), _blocks(3.0, 62, one_axis_scale=1.05))
    close = Params("EM3", m=-0.1113, b_mps=-0.05)  # the figures' own 3 mm/s off
    sup.forward_own = False  # the one-axis supervisor fell back
    for b in _blocks(3.0, 130, 71.0, lon=close):
        sup.observe(b)
    r = sup.forward_scores
    assert r[FORWARD_OWN] < r[FORWARD_ONE_AXIS] < r[FORWARD_OWN] * 1.05 + 0.005
    assert _own(sup) and events[-1][1] == "two_axis_forward_applied"
    for b in _blocks(3.0, 130, 202.0, lon=Params("EM3", m=-0.19, b_mps=-0.05)):
        sup.observe(b)
    assert not _own(sup) and events[-1][1] == "two_axis_forward_withdrawn"
    for b in _blocks(3.0, 130, 333.0, lon=close):
        sup.observe(b)
    assert not _own(sup)


def test_why_the_own_forward_speed_is_not_let_out_is_said() -> None:
    """Each judgement that keeps the figures' own forward speed out says why, with its
    scores: worse than the one-axis calibration's over the validation, no longitudinal
    parameters, worse at a recheck, then waiting for the one-axis one to be worse by
    the margin; let out again, nothing is said."""
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: None)
    _validated(sup, _figures(3.0, lon=Params("EM3", b_mps=-0.05)), _blocks(3.0, 70))
    r = sup.forward_scores
    assert sup.forward_why == (
        "the two-axis fit's own forward speed was worse than the one-axis calibration's "
        f"({r[FORWARD_OWN]:.4f} against {r[FORWARD_ONE_AXIS]:.4f} m/s after a current of "
        "its own)"
    )
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: None)
    _validated(sup, _figures(3.0), _blocks(3.0, 70))
    assert sup.forward_why == "the two-axis fit did not determine the forward scale and offset"
    sup = TwoAxisSupervisor(60.0, 120.0, lambda t, k, d: None)
    _validated(sup, _figures(3.0, lon=LON), _blocks(3.0, 70, one_axis_scale=1.05))
    assert _own(sup) and sup.forward_why == ""
    for b in _blocks(3.0, 130, 71.0, lon=Params("EM3", m=-0.19, b_mps=-0.05)):
        sup.observe(b)
    assert not _own(sup)
    assert sup.forward_why.startswith(
        "the two-axis fit's own forward speed was worse than the one-axis calibration's ("
    )
    close = Params("EM3", m=-0.1113, b_mps=-0.05)  # the figures' own 3 mm/s off
    for b in _blocks(3.0, 260, 202.0, lon=close):  # the recheck's second window all close
        sup.observe(b)
    assert (
        not _own(sup)
        and "returns once the one-axis calibration's is worse than it by the margin"
        in sup.forward_why
    )
    for b in _blocks(3.0, 130, 463.0, one_axis_scale=1.1):
        sup.observe(b)
    assert _own(sup) and sup.forward_why == ""


def test_restored_figures_applied_early_in_their_saved_sea() -> None:
    """Restored with the sea saved with them (the current the blocks see), the figures
    are applied after 5 blocks, where raw's phantom leeway is worse than theirs in that
    sea, and validated in place; without the sea, or with a sea older than an hour,
    they wait for the restored window (20 s)."""
    events: Events = []
    sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: events.append((t, k, dict(d))))
    sup.restore(_figures(3.0), (0.1, -0.2, -10.0))
    blocks = _blocks(3.0, 25, 1.0)
    for b in blocks[:5]:
        sup.observe(b)
    assert _applied(sup) == _figures(3.0) and _early(sup)
    assert events[-1][2]["kind"] == "restored-early" and _candidate(sup) == _figures(3.0)
    for b in blocks[5:]:
        sup.observe(b)
    assert _applied(sup) == _figures(3.0) and _candidate(sup) is None and not _early(sup)
    for sea in (None, (0.1, -0.2, -3700.0)):
        sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: None)
        sup.restore(_figures(3.0), sea)
        for b in blocks[:19]:
            sup.observe(b)
        assert _applied(sup) is None
        for b in blocks[19:]:
            sup.observe(b)
        assert _applied(sup) == _figures(3.0)


def test_restored_figures_applied_early_are_withdrawn_when_the_window_fails() -> None:
    """Applied on their first blocks, restored figures whose window then reads worse
    than raw (the log knocked to −10° after 5 s) are withdrawn at the window's end;
    figures raw beats in the saved sea are not applied early."""
    events: Events = []
    sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: events.append((t, k, dict(d))))
    sup.restore(_figures(3.0), (0.1, -0.2, 0.0))
    for b in _blocks(3.0, 5, 1.0) + _blocks(-10.0, 20, 6.0):
        sup.observe(b)
    assert _applied(sup) is None and not _early(sup)
    assert events[-1][1] == "two_axis_rejected" and "withdrawn" in sup.note
    sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: None)
    sup.restore(_figures(-3.0), (0.1, -0.2, 0.0))
    for b in _blocks(3.0, 10):
        sup.observe(b)
    assert _applied(sup) is None and _candidate(sup) == _figures(-3.0)


def test_restored_figures_validate_over_the_restored_window() -> None:
    """Figures from the state file (validated before) are applied after 20 s of blocks
    (the restored one-axis calibration's window), where a new offer waits for
    ``validation_s``: raw's phantom leeway goes out for 20 s after a restart, not 2
    minutes."""
    sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: None)
    sup.restore(_figures(3.0))
    for b in _blocks(3.0, 22):
        sup.observe(b)
    assert _applied(sup) == _figures(3.0)
    sup = TwoAxisSupervisor(120.0, 600.0, lambda t, k, d: None)
    sup.offer(_figures(3.0))
    for b in _blocks(3.0, 100):
        sup.observe(b)
    assert _applied(sup) is None and _candidate(sup) == _figures(3.0)
    for b in _blocks(3.0, 30, 100.0):
        sup.observe(b)
    assert _applied(sup) == _figures(3.0)


def test_hull_frame_own_inverts_the_sensor_and_round_trips() -> None:
    """The raw readings corrected by the figures' own longitudinal parameters and
    transverse scale and bias turn back to (u, w) exactly; the parameters go to the
    state's keys and back (none without the model, or for another model's)."""
    f = _figures(4.0, lon=LON)
    a = math.radians(4.0)
    for u, w in ((3.0, 0.0), (1.5, -0.4), (0.5, 0.7)):
        raw_t = 0.9 * (w * math.cos(a) - u * math.sin(a)) + 0.05
        raw_l = LON.forward(u * math.cos(a) + w * math.sin(a))
        assert f.hull_frame_own(raw_l, raw_t) == pytest.approx((u, w), abs=1e-12)
    d = f.as_dict()
    assert d["lon_m"] == -0.11 and d["lon_b_mps"] == -0.05 and d["lon_a_spm"] == 0.0
    assert Figures.from_dict(d, "EM3").lon == LON
    assert Figures.from_dict(d).lon is None
    assert Figures.from_dict(d, "EM1").lon is None  # EM1 has no scale
    assert "lon_m" not in _figures(4.0).as_dict()
    with pytest.raises(ValueError, match="without longitudinal"):
        _figures(4.0).hull_frame_own(2.0, 0.0)


def test_lon_of_fit_needs_every_longitudinal_parameter_determined() -> None:
    assert lon_of_fit("EM3", LON, {"m": 0.01, "b": 0.01}) == LON
    assert lon_of_fit("EM3", LON, {"m": 0.01, "b": None}) is None


def test_forward_rmse_of_no_blocks() -> None:
    assert forward_rmse([], None) == {}


def test_noise_gain_is_the_inverse_local_slope() -> None:
    """A correction passes a reading's noise times ``1/f'(v)``: 1 for raw, ``1/(1 + m)``
    for a linear model, ``1/(2a·v + 1 + m)`` for EM4; inf where the slope is not
    positive."""
    assert noise_gain(None, 2.0) == 1.0
    assert noise_gain(Params("EM3", m=-0.2, b_mps=0.1), 2.0) == pytest.approx(1.25)
    assert noise_gain(Params("EM4", a_spm=0.02, m=-0.2, b_mps=0.1), 2.5) == pytest.approx(1 / 0.9)
    assert noise_gain(Params("EM4", a_spm=-0.2, m=-0.2, b_mps=0.0), 2.5) == math.inf


def test_one_axis_better_where_its_expected_squared_error_is_smaller() -> None:
    """At one speed, a reading ``f(u) + n`` corrected by the sensor's own model (unbiased,
    gain 1/0.8) and by a one-axis model of a scale nearer 0 (gain 1/0.85) offset by
    ``d``: the rule picks the one-axis correction exactly where its mean squared error
    over many readings is the smaller (``d² < (g_own² − g_one²)·σ²``, 2.1 cm/s here),
    never one of a larger gain, and nothing without a finite gain."""
    rng = np.random.default_rng(5)
    sigma, u = 0.05, 2.0
    own = Params("EM3", m=-0.2, b_mps=0.1)
    raw = own.forward(u) + rng.normal(0.0, sigma, 200_000)
    g_own = noise_gain(own, u)
    for d in (0.0, 0.01, 0.02, 0.025, 0.03, -0.015, -0.025):
        one = Params("EM3", m=-0.15, b_mps=own.forward(u) - 0.85 * (u + d))
        g_one = noise_gain(one, u)
        mse_own = float(np.mean((correct_array(own, raw) - u) ** 2))
        mse_one = float(np.mean((correct_array(one, raw) - u) ** 2))
        picked = one_axis_better(d, g_own, g_one, sigma * sigma)
        assert picked == (mse_one < mse_own), d
    assert one_axis_better(0.0, 1.0 / 0.85, 1.25, 0.0025) is False  # a larger gain
    assert one_axis_better(0.0, math.inf, 1.0, 0.0025) is False
