"""The two-axis supervisor: learnt figures applied to the VBW only once the athwart
speed is not worse than raw, withdrawn when it becomes worse; the hull-frame inverse."""

from __future__ import annotations

import math

import pytest

from emlogd.pipeline.twoaxis_sup import Block, Figures, TwoAxisSupervisor, athwart_rmse

Events = list[tuple[float, str, dict[str, object]]]


def _applied(sup: TwoAxisSupervisor) -> Figures | None:
    return sup.applied


def _candidate(sup: TwoAxisSupervisor) -> Figures | None:
    return sup.candidate


def _blocks(alpha_deg: float, n: int, t0: float = 0.0) -> list[Block]:
    """Block means of a log turned ``alpha_deg`` (m_t −0.1, b_t 0.05) swinging its sway
    in turns at a speed that varies, heading sweeping, a current (0.1, −0.2)."""
    out: list[Block] = []
    a = math.radians(alpha_deg)
    for k in range(n):
        t = t0 + k
        u = 2.0 + 0.5 * math.sin(2 * math.pi * t / 90.0)
        w = 0.3 * math.cos(2 * math.pi * t / 90.0)
        psi = (t * 3.0) % 360.0
        r = math.radians(psi)
        gs = w - 0.1 * math.sin(r) - 0.2 * math.cos(r)
        raw_t = 0.9 * (w * math.cos(a) - u * math.sin(a)) + 0.05
        out.append((t, u + w * math.tan(a), raw_t, gs, psi))
    return out


def _figures(alpha_deg: float, t: float = 0.0, alpha_std_deg: float = 0.1) -> Figures:
    return Figures(alpha_deg, alpha_std_deg, -0.1, 0.01, 0.05, 0.01, t)


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
