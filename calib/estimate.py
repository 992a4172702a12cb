"""One estimate of an error model, the value every calibration result carries.

Least squares (:class:`calib.lsq.LsFit`), the filter run over a series
(:class:`calib.kalman.batch.KfRun`), an estimator trained in cross-validation
(:class:`calib.crossval.TrainedEstimator`), the offline result
(``emlogd.offline.jobs.CalibrationResult``) and the calibration record
(``emlogd.pipeline.calibration.Calibration``) each hold one :class:`Estimate` as their
``estimate`` and read its fields through :class:`Estimated`: the parameters, their
standard deviations and the sea current are declared here once.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from calib.models import ModelName, Params


@dataclass(frozen=True, slots=True)
class Estimate:
    """An error model's parameters with their standard deviations, and the sea current.

    Attributes:
        params: θ̂ (the model is ``params.model``); an unknown the data do not determine
            is at its prior.
        param_std: the standard deviation (standard error) of each parameter by short
            name; None where the data do not determine it.
        current_mps: the current (north, east), m/s; None when not estimated or not
            determined.
        current_std_mps: its standard deviations, m/s.
    """

    params: Params
    param_std: Mapping[str, float | None]
    current_mps: tuple[float, float] | None = None
    current_std_mps: tuple[float, float] | None = None

    @property
    def model(self) -> ModelName:
        """The error model."""
        return self.params.model


class Estimated:
    """The fields of a value's ``estimate`` read as its own (``fit.params`` is
    ``fit.estimate.params``)."""

    __slots__ = ()
    estimate: Estimate

    @property
    def params(self) -> Params:
        """θ̂ (:attr:`Estimate.params`)."""
        return self.estimate.params

    @property
    def param_std(self) -> Mapping[str, float | None]:
        """The parameters' standard deviations (:attr:`Estimate.param_std`)."""
        return self.estimate.param_std

    @property
    def current_mps(self) -> tuple[float, float] | None:
        """The current (north, east), m/s (:attr:`Estimate.current_mps`)."""
        return self.estimate.current_mps

    @property
    def current_std_mps(self) -> tuple[float, float] | None:
        """The current's standard deviations, m/s (:attr:`Estimate.current_std_mps`)."""
        return self.estimate.current_std_mps

    @property
    def model(self) -> ModelName:
        """The error model (:attr:`Estimate.model`)."""
        return self.estimate.model
