"""The two-axis figures learnt online (``axes: 2``): misalignment, transverse scale and
bias from a VBW log against a DVL's two axes, refused where the data cannot separate
them, and applied only once the athwart speed is not worse than raw."""

from __future__ import annotations

import dataclasses
import math

import pynmea2
import pytest

from calib.estimate import Estimate
from calib.models import Params
from calib.twoaxis import TwoAxisParams, fit_two_axis
from drivers.framing import with_checksum
from drivers.records import KNOT_MPS as KNOT
from emlogd.cli.common import two_axis_line
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.twoaxis_learn import (
    FALLBACK_REASON,
    NO_TWO_AXIS_REFERENCE,
    TwoAxisLearner,
    encode_two_axis_status,
)
from emlogd.pipeline.twoaxis_sup import CHOICE_S, OFFER_SHARPER, Figures, Guard, noise_gain
from tests.synth import TWO_AXIS_FIGURES, TWO_AXIS_TRUTH, two_axis_series, two_axis_trial

SETTINGS = UutSettings(
    port="log", reference_port="dvl", uut_source="VBW", axes=2, current=True, validation_s=30.0
)
ALIGNED = TwoAxisParams(Params("EM3", m=-0.11, b_mps=-0.05), 0.0, -0.09, 0.04)


Events = list[tuple[float, str, dict[str, object]]]


def _learn(
    kind: str, truth: TwoAxisParams, seed: int, n: int = 16200
) -> tuple[TwoAxisLearner, Events]:
    """A learner fed one synthetic manoeuvre at 10 Hz (lag 0, the heading exact), the
    forward reading as a one-axis calibration learnt against the hull reads it."""
    d = two_axis_trial(kind, truth, seed, n=n)
    events: Events = []
    lr = TwoAxisLearner(SETTINGS, lambda t, k, det: events.append((t, k, dict(det))))
    heading = dict(zip(d["t"].tolist(), d["hd"].tolist(), strict=True))
    fwd = d["u"] + d["w"] * math.tan(truth.misalign_rad)
    rows = zip(
        d["t"].tolist(),
        d["gf"].tolist(),
        d["gs"].tolist(),
        fwd.tolist(),
        d["rl"].tolist(),
        d["rt"].tolist(),
        strict=True,
    )
    for t, gf, gs, v, rl, rt in rows:
        lr.reference(t, gf, gs, True)
        lr.reading(t, v, rl, rt)
        lr.drain(t, 0.0, heading.get, True)
    lr.drain(float(d["t"][-1]), 0.0, heading.get, True, final=True)
    return lr, events


@pytest.fixture(scope="module")
def figure8() -> tuple[TwoAxisLearner, Events]:
    return _learn("figure-8", TWO_AXIS_TRUTH, 3)


def test_figure8_learns_and_applies(figure8: tuple[TwoAxisLearner, Events]) -> None:
    """On a figure-8 the window determines α (3°) within 0.3°, m_t and b_t near the
    truth; the figures validate against raw and correct the VBW; the status and the
    $PEMLT sentence (read by pynmea2) carry them."""
    lr, events = figure8
    est = lr.estimate
    assert est is not None
    assert est.misalign_deg == pytest.approx(3.0, abs=0.3)
    assert 0.0 < est.misalign_std_deg <= 0.15
    assert est.m_t == pytest.approx(TWO_AXIS_TRUTH.m_t, abs=0.02)
    assert est.b_t_mps == pytest.approx(TWO_AXIS_TRUTH.b_t_mps, abs=0.02)
    kinds = [k for _, k, _ in events]
    assert "two_axis_applied" in kinds
    assert kinds.index("two_axis_learnt") < kinds.index("two_axis_applied")
    st = lr.status()
    assert st["state"] == "applied" and st["refused"] is None
    applied = lr.sup.applied
    assert applied is not None
    u, w = 2.0, 0.3
    a = math.radians(3.0)
    raw_t = (1.0 + TWO_AXIS_TRUTH.m_t) * (
        w * math.cos(a) - u * math.sin(a)
    ) + TWO_AXIS_TRUTH.b_t_mps
    out = lr.correct(0.0, u + w * math.tan(a), raw_t)
    assert out is not None
    assert out == pytest.approx((u, w), abs=0.02)
    msg = pynmea2.parse(encode_two_axis_status("log", "EML", lr), check=True)
    assert msg.data[:4] == ["T", "log", "A", f"{applied.misalign_deg:+.2f}"]


def test_the_figures_applied_follow_the_sharpest_estimate(
    figure8: tuple[TwoAxisLearner, Events],
) -> None:
    """α is first determined before the whole figure-8 is in the window, with a σ
    near the rule's bound; the figures applied at the end are the window's sharpest
    (within :data:`OFFER_SHARPER` of the last estimate's σ), not the first learnt."""
    lr, events = figure8
    est, applied = lr.estimate, lr.sup.applied
    assert est is not None and applied is not None
    assert applied.misalign_std_deg <= est.misalign_std_deg / OFFER_SHARPER
    first = next(d for _, k, d in events if k == "two_axis_applied")
    assert float(str(first["misalign_deg"])) != pytest.approx(applied.misalign_deg, abs=1e-3)


def _estimate(lr: TwoAxisLearner) -> Figures | None:
    return lr.estimate


def _candidate(lr: TwoAxisLearner) -> Figures | None:
    return lr.sup.candidate


def test_an_estimate_whose_sigma_is_above_the_bound_is_refused() -> None:
    """A fit that determines α but reports it ±0.4° (its residuals correlated: the model
    does not fit the window) is refused with that reason and offered to no one; the
    same fit at its own σ is taken and offered."""
    fit = fit_two_axis("EM3", two_axis_series(two_axis_trial("figure-8", TWO_AXIS_TRUTH, 3)))
    assert fit.stderr["misalign_deg"] is not None and fit.stderr["misalign_deg"] < 0.25
    lr = TwoAxisLearner(SETTINGS, lambda t, k, det: None)
    loose = dataclasses.replace(fit, stderr={**fit.stderr, "misalign_deg": 0.4})
    lr._take(loose, 100.0)
    assert lr.estimate is None and lr.sup.candidate is None
    assert "±0.40°" in lr.refused and "above 0.25°" in lr.refused
    lr._take(fit, 220.0)
    est = _estimate(lr)
    assert est is not None and _candidate(lr) == est and not lr.refused


def test_straight_run_refuses_alpha() -> None:
    """A straight run at one speed: α refused with the reason (the forward speed nearly
    constant), nothing offered or applied, the VBW left as read."""
    lr, events = _learn("straight", TWO_AXIS_TRUTH, 4, n=7000)
    assert lr.estimate is None and lr.sup.applied is None
    assert "speed through water nearly constant" in lr.refused
    assert lr.correct(0.0, 2.0, 0.1) is None
    assert [k for _, k, _ in events] == ["two_axis_refused"]
    assert encode_two_axis_status("log", "EML", lr).split(",")[-1].startswith("R*")


def test_circles_one_way_refuse_alpha_in_words_an_operator_reads() -> None:
    """Steady circles one way: the sway is a fixed fraction of the surge, so α is refused
    and the status, its JSON and the status line say why in plain words (the sideways
    speed a fixed fraction of the forward speed, the turns one way) and what determines
    it (turns to both sides, a figure-8); nothing is applied, the VBW left as read."""
    lr, events = _learn("circles", TWO_AXIS_TRUTH, 5, n=7000)
    assert lr.estimate is None and lr.sup.applied is None and lr.correct(0.0, 2.0, 0.1) is None
    why = str(lr.status()["refused"])
    assert why.startswith("misalignment not determinable: ")
    assert "sideways speed through the water is a fixed fraction of the forward speed" in why
    assert (
        "one steady turn (one turn rate throughout, one way)" in why
        and "turns to both sides (a figure-8)" in why
    )
    assert [d["why"] for _, k, d in events if k == "two_axis_refused"][-1] == why
    assert why in two_axis_line(lr.status())


def test_the_status_says_why_the_forward_speed_is_the_one_axis_calibrations() -> None:
    """``forward_reason`` in the status (and its line) whenever the forward speed is not
    the applied figures' own: α refused by the latest window, figures validating, figures
    without longitudinal parameters, set aside after the one-axis supervisor's
    fallback, ``apply`` off; null while it is theirs."""
    lr, _ = _learn("straight", TWO_AXIS_TRUTH, 4, n=7000)
    st = lr.status()
    assert st["forward"] == "one_axis"
    assert (
        st["forward_reason"]
        == f"the one-axis calibration's: the misalignment is refused ({lr.refused})"
    )
    assert two_axis_line(st).count(lr.refused) == 1
    lon = Params("EM3", m=-0.2, b_mps=0.1)
    fig = Figures(3.0, 0.1, -0.08, 0.01, 0.04, 0.01, 0.0, lon)
    lr.sup.candidate = fig
    assert "two-axis figures validating" in str(lr.status()["forward_reason"])
    lr.sup.candidate, lr.sup.applied = None, dataclasses.replace(fig, lon=None)
    assert lr.status()["forward_reason"] == (
        "the one-axis calibration's: the two-axis fit did not determine the forward scale "
        "and offset"
    )
    lr.sup.applied, lr.sup.forward_own = fig, True
    assert lr.status()["forward"] == "two_axis" and lr.status()["forward_reason"] is None
    assert lr.answers(Guard(lr.fallbacks + 1, False, None))
    reason = lr.status()["forward_reason"]
    assert reason == f"the one-axis calibration's: {FALLBACK_REASON}"
    assert f"; forward speed: {reason}" in two_axis_line(lr.status())
    lr.sup.forward_own = True
    lr.s = dataclasses.replace(lr.s, apply=False)
    assert "apply is off" in str(lr.status()["forward_reason"])


def test_aligned_sensor_gives_zero_within_its_sigma() -> None:
    """A sensor on the keel line: α within two of its σ of 0."""
    lr, _ = _learn("figure-8", ALIGNED, 5)
    est = lr.estimate
    assert est is not None
    assert abs(est.misalign_deg) <= 2.0 * est.misalign_std_deg


def test_a_reference_without_an_athwart_speed_is_said() -> None:
    """A reference that gives no athwart speed (GNSS, a one-axis log): nothing learnt,
    the status says why."""
    lr = TwoAxisLearner(SETTINGS, lambda t, k, det: None)
    for k in range(50):
        t = 0.1 * k
        lr.reference(t, 2.0, None, True)
        lr.reading(t, 2.0, 2.0, 0.1)
        lr.drain(t, 0.0, lambda _: 90.0, True)
    st = lr.status()
    assert st["refused"] == NO_TWO_AXIS_REFERENCE and st["window_s"] == 0.0
    assert lr.counts["no_reference"] > 40


def _pipeline(fig: dict[str, float], sea: tuple[float, float] | None = None) -> Pipeline:
    """A pipeline with a log learning two axes, started from a record with ``fig`` (and
    the current ``sea`` saved with it at t = 100 s)."""
    s = UutSettings(port="log", reference_port="dvl", uut_source="VBW", axes=2)
    est = Estimate(Params("EM3"), {}, current_mps=sea)
    rec = Calibration("log", est, 0.5, sea is not None, t=100.0, reset=True, two_axis=fig)
    return Pipeline(
        [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")], [s], {"log": rec}
    )


def test_saved_figures_are_restored_checked_and_reset() -> None:
    """Saved figures come back as a candidate that validates again (not applied yet),
    with the sea saved with them where the record has one;
    figures the record's check refuses (α beyond 20°) are not restored; a reset clears
    them and says so, and the record persisted then has none."""
    p = _pipeline(TWO_AXIS_FIGURES)
    two = p.status()["uuts"]["log"]["two_axis"]  # type: ignore[index]
    assert two["state"] == "validating" and two["applied"] is None
    assert p.two_axis["log"].sup.kept == Figures.from_dict(TWO_AXIS_FIGURES)
    assert p.calibrations()[0].two_axis == TWO_AXIS_FIGURES
    done = p.reset("log")
    assert "two-axis figures" in done["log"]["cleared"]  # type: ignore[operator]
    assert p.two_axis["log"].sup.candidate is None and p.calibrations()[0].two_axis is None
    refused = _pipeline(TWO_AXIS_FIGURES | {"misalign_deg": 25.0})
    assert refused.two_axis["log"].sup.candidate is None
    assert p.two_axis["log"].sup.sea is None  # saved without a current
    with_sea = _pipeline(TWO_AXIS_FIGURES, (0.1, -0.2))
    assert with_sea.two_axis["log"].sup.sea == (0.1, -0.2, 100.0)  # the early evidence's


def test_vhw_and_vbw_take_the_figures_own_forward_speed() -> None:
    """Once the supervisor lets the applied figures correct the forward speed, the VBW's
    forward speed and a VHW's are theirs (the VHW turned back with the VBW's athwart
    reading just before it); a VHW without a fresh VBW before it, or figures not let
    correct the forward speed, keep the one-axis calibration's. The one-axis
    supervisor's word stands over them: while its change detector holds raw, and after
    a fallback of its until the two-axis recheck lets the forward speed again, the
    one-axis output goes out (a change it detects withdraws both)."""
    p = _pipeline(TWO_AXIS_FIGURES)
    ax, cal = p.two_axis["log"], p.uuts["log"].cal
    lon = Params("EM3", m=-0.2, b_mps=0.1)
    fig = Figures(3.0, 0.1, -0.08, 0.01, 0.04, 0.01, 0.0, lon)
    ax.sup.applied, ax.sup.forward_own = fig, True

    def sent(t: float, body: str) -> list[str]:
        out = p.feed(t, "log", with_checksum(body).encode() + b"\r\n")
        return [e.sentence for e in out.emits if e.sentence[3:6] in ("VBW", "VHW")]

    def vhw_kn(t: float) -> float:
        sent(t - 0.05, "VMVBW,3.89,-0.19,A,,,V")
        return float(pynmea2.parse(sent(t, "VMVHW,,T,,M,3.89,N,7.20,K")[0]).water_speed_knots)

    vbw = pynmea2.parse(sent(1.0, "VMVBW,3.89,-0.19,A,,,V")[0])
    u, w = fig.hull_frame_own(3.89 * KNOT, -0.19 * KNOT)
    assert float(vbw.lon_water_spd) * KNOT == pytest.approx(u, abs=0.006)
    assert float(vbw.trans_water_spd) * KNOT == pytest.approx(w, abs=0.006)
    vhw = pynmea2.parse(sent(1.5, "VMVHW,,T,,M,3.89,N,7.20,K")[0])
    assert float(vhw.water_speed_knots) * KNOT == pytest.approx(u, abs=0.006)
    stale = pynmea2.parse(sent(3.0, "VMVHW,,T,,M,3.89,N,7.20,K")[0])
    assert float(stale.water_speed_knots) == pytest.approx(3.89)  # one-axis: uncalibrated
    cal.sup.change.held = True  # the change detector's hold: the one-axis output (raw)
    assert vhw_kn(3.2) == pytest.approx(3.89)
    cal.sup.change.held = False
    assert vhw_kn(3.4) * KNOT == pytest.approx(u, abs=0.006)
    cal.sup.counters.fallbacks += 1  # a fallback: withdrawn until the recheck lets it
    assert vhw_kn(3.6) == pytest.approx(3.89) and not ax.sup.forward_own
    ax.sup.forward_own = True  # the two-axis recheck judged it good since
    assert vhw_kn(3.8) * KNOT == pytest.approx(u, abs=0.006)
    ax.sup.forward_own = False
    assert vhw_kn(4.0) == pytest.approx(3.89)


def test_readings_above_the_range_go_out_raw_on_both_axes() -> None:
    """A reading above the log's range (8 m/s, up to twice it) goes out raw on the
    two-axis path as on the one-axis one: the VBW's forward and athwart speeds and the
    VHW's as read, not turned back nor corrected by the applied figures (learnt or
    configured) and not queued for the two-axis learner; counted ``over_range``. The
    same readings within the range are corrected."""
    p = _pipeline(TWO_AXIS_FIGURES)
    ax = p.two_axis["log"]
    lon = Params("EM3", m=-0.2, b_mps=0.1)
    ax.sup.applied = Figures(3.0, 0.1, -0.08, 0.01, 0.04, 0.01, 0.0, lon)
    ax.sup.forward_own = True
    configured = Pipeline(
        [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")],
        [UutSettings(port="log", reference_port="dvl", uut_source="VBW", misalign_deg=3.0)],
    )

    def sent(q: Pipeline, t: float, body: str) -> list[float]:
        out = q.feed(t, "log", with_checksum(body).encode() + b"\r\n")
        (line,) = [e.sentence for e in out.emits if e.sentence[3:6] in ("VBW", "VHW")]
        msg = pynmea2.parse(line)
        if msg.sentence_type == "VHW":
            return [float(msg.water_speed_knots)]
        return [float(msg.lon_water_spd), float(msg.trans_water_spd)]

    for q in (p, configured):
        assert sent(q, 1.0, "VMVBW,15.40,-0.80,A,,,V") != pytest.approx([15.4, -0.8])
        assert sent(q, 2.0, "VMVBW,15.80,-0.80,A,,,V") == pytest.approx([15.8, -0.8])
        assert sent(q, 2.5, "VMVHW,,T,,M,15.80,N,29.26,K") == pytest.approx([15.8])
        counters = q.status()["uuts"]["log"]["counters"]  # type: ignore[index]
        assert counters["over_range"] == 2
    assert len(ax.pending) == 1  # the reading within the range alone


def test_the_reading_noise_is_measured_inside_the_blocks(
    figure8: tuple[TwoAxisLearner, Events],
) -> None:
    """The forward reading's noise is the scatter about each block's mean (0.05 m/s on
    the synthetic log, whose figure-8 changes its speed inside a second by far less)."""
    var = figure8[0].noise_var()
    assert var is not None and math.sqrt(var) == pytest.approx(0.05, rel=0.03)
    assert TwoAxisLearner(SETTINGS, lambda *_: None).noise_var() is None


def test_a_reading_goes_out_by_the_correction_of_the_smaller_expected_error() -> None:
    """With the figures' own forward speed let out, a reading still goes out by the
    one-axis calibration (turned back by α) where that one agrees with the figures' own
    at this speed and divides the noise by more (its scale nearer 0): the smaller
    expected squared error, on the VBW and the VHW alike; by the figures' own where the
    one-axis offset there is larger than the noise it spares, and before the noise is
    measured."""
    p = _pipeline(TWO_AXIS_FIGURES)
    ax, cal = p.two_axis["log"], p.uuts["log"].cal
    lon = Params("EM3", m=-0.2, b_mps=0.1)
    fig = Figures(3.0, 0.1, -0.08, 0.01, 0.04, 0.01, 0.0, lon)
    ax.sup.applied, ax.sup.forward_own = fig, True
    raw, ath = 3.89 * KNOT, -0.19 * KNOT
    ca = math.cos(math.radians(3.0))
    # the one-axis correction (learnt against the hull: u_s/cos α) 15 mm/s above the
    # figures' own once turned back, under the 21 mm/s of noise its gain spares; 40 above
    v = (lon.correct(raw) + 0.015 / ca) / ca
    agree = Params("EM3", m=-0.15, b_mps=raw - 0.85 * v)
    off = Params("EM3", m=-0.15, b_mps=raw - 0.85 * (v + 0.025 / ca**2))

    def sent(t: float, one: Params) -> tuple[float, float]:
        cal.sup.applied = one
        out = []
        for dt, body in ((0.0, "VMVBW,3.89,-0.19,A,,,V"), (0.05, "VMVHW,,T,,M,3.89,N,7.20,K")):
            emits = p.feed(t + dt, "log", with_checksum(body).encode() + b"\r\n").emits
            line = next(e.sentence for e in emits if e.sentence[3:6] in ("VBW", "VHW"))
            msg = pynmea2.parse(line)
            kn = msg.lon_water_spd if body[2:5] == "VBW" else msg.water_speed_knots
            out.append(float(kn) * KNOT)
        return out[0], out[1]

    own = fig.hull_frame_own(raw, ath)[0]
    assert sent(1.0, agree) == pytest.approx((own, own), abs=0.003)  # noise not measured
    ax._scatter_sum[:] = [0.0025 * 1000, 1000]
    one = fig.hull_frame(v, ath)[0]
    assert one - own == pytest.approx(0.015) and v - own > 0.01
    assert sent(2.0, agree) == pytest.approx((one, v), abs=0.003)
    assert sent(3.0, off) == pytest.approx((own, own), abs=0.003)
    assert ax.forward_by == {"own": 4, "one_axis": 2}


def test_a_reading_s_choice_is_weighed_on_the_readings_before_it() -> None:
    """The choice between the two corrections weighs the one-axis offset as its mean over
    the readings of the last ``CHOICE_S`` (2 s), not the reading's own: readings
    alternating by ±0.1 m/s of noise about a speed where the one-axis offset (15 mm/s)
    is inside the 21 mm/s its gain spares go out by the one-axis correction from the
    second reading on, though every other reading's own offset (22 mm/s) is outside it;
    a reading less than ``CHOICE_S`` after the last is weighed with it, one after a
    longer gap weighs itself alone."""
    lr = TwoAxisLearner(SETTINGS, lambda *_: None)
    lon = Params("EM3", m=-0.2, b_mps=0.1)
    fig = Figures(3.0, 0.1, -0.08, 0.01, 0.04, 0.01, 0.0, lon)
    lr.sup.applied, lr.sup.forward_own = fig, True
    lr._scatter_sum[:] = [0.0025 * 1000, 1000]
    raw, ath = 2.0, -0.1
    ca = math.cos(math.radians(3.0))
    v = (lon.correct(raw) + 0.015 / ca) / ca
    one = Params("EM3", m=-0.15, b_mps=raw - 0.85 * v)
    guard = Guard(0, False, one)

    def by_one_axis(t: float, r: float) -> bool:
        out = lr.correct(t, one.correct(r), ath, r, guard)
        assert out is not None
        return out[0] == pytest.approx(fig.hull_frame(one.correct(r), ath)[0], abs=1e-12)

    own_gain = ca * noise_gain(lon, lon.correct(raw))
    one_gain = ca * ca * noise_gain(one, v)
    bound = math.sqrt((own_gain**2 - one_gain**2) * 0.0025)
    offsets = [
        fig.hull_frame(one.correct(r), ath)[0] - fig.hull_frame_own(r, ath)[0]
        for r in (raw - 0.1, raw + 0.1)
    ]
    assert abs(offsets[0]) > bound > abs(offsets[1]) and abs(sum(offsets) / 2) < bound
    chosen = [by_one_axis(0.1 * k, raw + (0.1 if k % 2 else -0.1)) for k in range(20)]
    assert chosen == [False] + [True] * 19
    assert CHOICE_S == 2.0
    t = 1.9 + CHOICE_S - 0.1
    assert by_one_axis(t, raw - 0.1)  # with the reading at 1.9 s (+0.1)
    assert not by_one_axis(t + CHOICE_S + 0.1, raw - 0.1)
