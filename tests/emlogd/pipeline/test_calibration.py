"""Whether a calibration record may be used."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.pipeline.calibration import Calibration, check, checker
from emlogd.pipeline.integrity import Envelope
from emlogd.pipeline.settings import UutSettings

GOOD = Calibration(
    "emlog1",
    Estimate(Params("EM3", m=0.05, b_mps=0.1), {"m": 0.01, "b": 0.02}),
    3.2,
    covariance=((1.0, 0.0, 0.0), (0.0, 1e-4, 0.0), (0.0, 0.0, 1e-4)),
)


def _with(**kw: object) -> Calibration:
    values = {f: getattr(GOOD, f) for f in GOOD.__dataclass_fields__}
    fields = ("params", "param_std", "current_mps", "current_std_mps")
    estimate: dict[str, Any] = {k: kw.pop(k) for k in fields if k in kw}
    values["estimate"] = dataclasses.replace(GOOD.estimate, **estimate)
    values.update(kw)
    return Calibration(**values)


class TestCheck:
    """check() refuses what is not a calibration, with a reason."""

    def test_a_good_record_passes(self) -> None:
        """Parameters in the envelope, SPD covariance, finite lag: usable."""
        assert check(GOOD, Envelope()) == ""

    @pytest.mark.parametrize(
        ("kw", "why"),
        [
            ({"params": Params("EM3", m=-2.0)}, "scale"),
            ({"params": Params("EM3", b_mps=1e6)}, "bias"),
            ({"lag_s": 1e9}, "lag"),
            ({"lag_s": math.nan}, "lag"),
            ({"covariance": ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))}, "positive"),
            ({"covariance": ((1.0, 0.5, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))}, "symmetric"),
            ({"covariance": ((1e300, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))}, "magnitudes"),
            ({"covariance": ((1.0,),)}, "shape"),
            ({"param_std": {"m": -1.0}}, "standard deviation"),
            ({"current": True, "current_mps": (5.0, 0.0), "covariance": ()}, "current"),
        ],
    )
    def test_poison_is_refused(self, kw: dict[str, object], why: str) -> None:
        """Every poisoned field is refused with a reason naming it."""
        assert why in check(_with(**kw), Envelope())

    def test_a_reset_record_is_always_usable(self) -> None:
        """A reset (no calibration) is a valid state to load."""
        assert check(_with(params=Params("EM3", m=-2.0), reset=True), Envelope()) == ""

    def test_checker_uses_each_uuts_envelope(self) -> None:
        """checker() applies the UUT's own envelope (a default one for an unknown UUT)."""
        tight = UutSettings(
            port="emlog1", reference_port="dvl", envelope=Envelope(max_abs_b_mps=0.05)
        )
        assert "bias" in checker([tight])(GOOD)
        assert checker([])(GOOD) == ""


TWO_AXIS = {
    "misalign_deg": -4.0,
    "misalign_std_deg": 0.1,
    "m_t": 0.2,
    "m_t_std": 0.01,
    "b_t_mps": -0.3,
    "b_t_std_mps": 0.01,
}
"""A record's two-axis figures within the envelope."""


def test_two_axis_figures_are_checked() -> None:
    """A record's two-axis figures: |α| ≤ 20°, |m_t| ≤ 0.5, |b_t| ≤ 1 m/s, σ ≥ 0, all six,
    finite — checked whatever else the record holds (a reset one too)."""
    good = dict(TWO_AXIS)
    base = Calibration("log", Estimate(Params("EM3"), {}), 0.5, two_axis=good)
    assert check(base, Envelope()) == ""
    for key, value, why in (
        ("misalign_deg", 25.0, "misalign_deg +25 outside ±20"),
        ("m_t", -0.7, "m_t -0.7 outside ±0.5"),
        ("b_t_mps", 1.5, "b_t_mps +1.5 outside ±1"),
        ("m_t_std", -0.1, "m_t_std is -0.1"),
        ("misalign_deg", math.inf, "misalign_deg is inf"),
    ):
        bad = dataclasses.replace(base, two_axis=good | {key: value})
        assert why in check(bad, Envelope())
        assert why in check(dataclasses.replace(bad, reset=True), Envelope())
    fewer = {k: v for k, v in good.items() if k != "b_t_std_mps"}
    assert "must be" in check(dataclasses.replace(base, two_axis=fewer), Envelope())


def test_two_axis_longitudinal_parameters_are_checked() -> None:
    """The longitudinal parameters a record's two-axis figures carry: all three or none,
    finite, within the envelope (|a| ≤ 0.1 s/m, |m| ≤ 0.5, |b| ≤ 1 m/s)."""
    good = TWO_AXIS | {"lon_a_spm": 0.0, "lon_m": -0.17, "lon_b_mps": 0.005}
    base = Calibration("log", Estimate(Params("EM3"), {}), 0.5, two_axis=good)
    assert check(base, Envelope()) == ""
    for key, value, why in (
        ("lon_m", -0.7, "lon_m -0.7 outside ±0.5"),
        ("lon_b_mps", 1.5, "lon_b_mps +1.5 outside ±1"),
        ("lon_a_spm", 0.2, "lon_a_spm +0.2 outside ±0.1"),
        ("lon_m", math.nan, "lon_m is nan"),
    ):
        assert why in check(dataclasses.replace(base, two_axis=good | {key: value}), Envelope())
    fewer = {k: v for k, v in good.items() if k != "lon_b_mps"}
    assert "all or none" in check(dataclasses.replace(base, two_axis=fewer), Envelope())
