"""The calibration file: one format for the state file and calibrate --save."""

from __future__ import annotations

import dataclasses

import pytest

from calib.estimate import Estimate
from calib.models import Params
from emlogd.calfile import CalibrationFileError, dumps, loads
from emlogd.pipeline.calibration import Calibration
from tests.synth import TWO_AXIS_FIGURES

FULL = Calibration(
    estimate=Estimate(
        Params("EM4", 0.01, -0.1, 0.05),
        {"a": 0.001, "m": None, "b": 0.003},
        current_mps=(-0.09, 0.07),
        current_std_mps=(0.004, 0.005),
    ),
    uut="emlog2",
    lag_s=0.45,
    current=True,
    covariance=tuple(tuple(1e-4 if i == j else 0.0 for j in range(6)) for i in range(6)),
    method="kf",
    t=1.75e9,
    n_samples=12,
    reference={"port": "dvl", "field": "bottom"},
    unidentifiable=("m",),
    nis_mean=1.02,
)


class TestRoundTrip:
    """What is written reads back the same."""

    def test_every_field_round_trips(self) -> None:
        """A record with every field set, and its extra notes, read back equal."""
        cals, extras = loads(dumps({"emlog2": FULL}, {"emlog2": {"rmse_cal": 0.05}}))
        assert cals == {"emlog2": FULL}
        assert extras == {"emlog2": {"rmse_cal": 0.05}}

    def test_a_reset_record(self) -> None:
        """A reset UUT is a record too (so a reset survives a restart)."""
        reset = Calibration("emlog1", Estimate(Params("EM3"), {}), 3.2, reset=True)
        assert loads(dumps({"emlog1": reset}))[0]["emlog1"].reset


class TestStrictParsing:
    """A damaged file names what is wrong."""

    @pytest.mark.parametrize(
        ("edit", "match"),
        [
            (lambda t: t.replace("kind: emlogd-calibration", "kind: other"), "not an emlogd"),
            (lambda t: t.replace("schema: 2", "schema: 1"), "schema 1"),
            (lambda t: t.replace("end: true", ""), "truncated"),
            (lambda t: t.replace("model: EM4", "model: EM7"), "model"),
            (lambda t: t.replace("a: 0.01", "z: 0.01", 1), "params"),
            (lambda t: t.replace("method: kf", "method: magic"), "method"),
            (lambda t: t.replace("n_samples: 12", "n_samples: -1"), "n_samples"),
            (lambda t: t.replace("north: -0.09", "north: yes"), "current_mps.north"),
            (lambda t: t.replace("lag_s: 0.45", "lag_s: .inf"), "lag_s"),
            (lambda t: "{", "YAML"),
        ],
    )
    def test_damage_is_named(self, edit: object, match: str) -> None:
        """Each kind of damage raises CalibrationFileError naming the key."""
        text = dumps({"emlog2": FULL})
        bad = edit(text)  # type: ignore[operator]
        assert bad != text
        with pytest.raises(CalibrationFileError, match=match):
            loads(bad)


FIGURES = TWO_AXIS_FIGURES


def test_two_axis_figures_round_trip_and_are_absent_otherwise() -> None:
    """A record with two-axis figures keeps them through the file; one without has no
    ``two_axis`` key (a one-axis file is as before); a figure missing or not a number
    is an error naming the key."""
    two = dataclasses.replace(FULL, two_axis=FIGURES)
    text = dumps({"emlog2": two})
    assert loads(text)[0]["emlog2"] == two
    assert "two_axis" not in dumps({"emlog2": FULL})
    with pytest.raises(CalibrationFileError, match="two_axis"):
        loads(text.replace("    b_t_std_mps: 0.004\n", ""))
    with pytest.raises(CalibrationFileError, match=r"two_axis\.m_t"):
        loads(text.replace("m_t: -0.08", "m_t: .nan"))


def test_two_axis_longitudinal_parameters_round_trip_all_or_none() -> None:
    """The two-axis fit's longitudinal parameters go through the file with the figures;
    one of the three missing is an error naming the keys, and a file without any of
    them (written before they were kept) still loads."""
    lon = {"lon_a_spm": 0.0, "lon_m": -0.17, "lon_b_mps": 0.005}
    two = dataclasses.replace(FULL, two_axis=FIGURES | lon)
    text = dumps({"emlog2": two})
    assert loads(text)[0]["emlog2"] == two
    with pytest.raises(CalibrationFileError, match="lon_a_spm, lon_m, lon_b_mps"):
        loads(text.replace("lon_b_mps: 0.005", "other: 0.005"))
    with pytest.raises(CalibrationFileError, match=r"two_axis\.lon_m"):
        loads(text.replace("lon_m: -0.17", "lon_m: .inf"))
    assert loads(dumps({"emlog2": dataclasses.replace(FULL, two_axis=FIGURES)}))[0]
