"""The two-axis model: the readings of a misaligned log, their inverse, the water frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import ModelError
from calib.models import Params
from calib.twoaxis_model import TwoAxisParams, leeway_deg, water_velocity


class TestModel:
    def test_correct_inverts_forward(self) -> None:
        """Correcting the modelled readings gives back the water velocity, EM4 too."""
        p = TwoAxisParams(Params("EM4", 0.02, -0.1, 0.05), math.radians(-4.0), 0.07, -0.03)
        u = np.linspace(0.3, 5.0, 50)
        w = np.linspace(-0.4, 0.4, 50)
        cu, cw = p.correct(*p.forward(u, w))
        np.testing.assert_allclose(cu, u, atol=1e-12)
        np.testing.assert_allclose(cw, w, atol=1e-12)

    def test_misalignment_leaks_forward_speed_to_port(self) -> None:
        """3° to starboard at 3 m/s: −0.157 m/s on the transverse axis (phantom leeway)."""
        p = TwoAxisParams(Params("EM1"), math.radians(3.0))
        lon, tr = p.forward(np.array([3.0]), np.array([0.0]))
        assert tr[0] == pytest.approx(-3.0 * math.sin(math.radians(3.0)))
        assert lon[0] == pytest.approx(3.0 * math.cos(math.radians(3.0)))

    def test_misalignment_beyond_envelope_refused(self) -> None:
        with pytest.raises(ModelError, match="misalignment"):
            TwoAxisParams(Params("EM1"), math.radians(25.0))
        with pytest.raises(ModelError, match="not finite"):
            TwoAxisParams(Params("EM1"), 0.0, math.nan)

    def test_water_velocity_and_leeway(self) -> None:
        """The current projected on each hull axis: heading east, a north current is to port."""
        u, w = water_velocity([2.0], [0.0], [90.0], (0.5, 0.0))
        assert u[0] == pytest.approx(2.0)
        assert w[0] == pytest.approx(0.5)
        assert leeway_deg(np.array([1.0]), np.array([1.0]))[0] == pytest.approx(45.0)
