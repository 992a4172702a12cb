"""The EMlog error models EM1–EM4 of the paper (section III-A, eqs. (10)–(13)).

Every model says what the EMlog reads (``raw``) for a true speed through the water
``v`` (measured = f(true)), in m/s:

========  ==================================  ==========================
model     forward model f(v)                  parameters θ (paper order)
========  ==================================  ==========================
``EM1``   ``v + b``              (eq. 10)     ``[b]``
``EM2``   ``(1 + m)·v``          (eq. 11)     ``[m]``
``EM3``   ``(1 + m)·v + b``      (eq. 12)     ``[m, b]``
``EM4``   ``a·v² + (1 + m)·v + b`` (eq. 13)   ``[a, m, b]``
========  ==================================  ==========================

Units: ``b`` in m/s, ``m`` dimensionless, ``a`` in s/m (so ``a·v²`` is m/s).

The error ``raw − v`` is linear in θ: ``raw − v = h(v)·θ`` with the design row
``h(v)`` of the paper's LS design matrices (eqs. (18)–(21)): ``[1]``, ``[v]``,
``[v, 1]``, ``[v², v, 1]``. The least-squares and Kalman estimators build on that.

Correction applies the inverse of f. EM1–EM3 (and EM4 with ``a = 0``) are linear:
``v = (raw − b)/(1 + m)``. For EM4 the quadratic ``a·v² + (1+m)·v + (b − raw) = 0``
has two roots; the correction is always the root on the **increasing branch** of f
(where ``f'(v) = 2a·v + 1 + m > 0``), the one that tends to the linear solution as
``a → 0``, computed in the cancellation-free form
``v = 2·(raw − b) / ((1 + m) + √((1 + m)² + 4a·(raw − b)))``. Documented edge cases,
never an exception:

- no real root (the reading lies beyond the maximum of a parabola with ``a < 0``):
  the correction is the vertex ``−(1+m)/(2a)``, the speed whose modelled reading is
  closest to ``raw`` (a calibration inside the physical envelope never gets there
  within the sensor's range);
- a gain ``1 + m ≤ 0``: no increasing branch through the origin, the model cannot be
  inverted and the correction is ``nan``.

Must not import: drivers, emlogd, or any I/O module (numpy and the stdlib only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from calib.errors import ModelError

FloatArray = npt.NDArray[np.float64]
"""A float64 numpy array."""

HeadingCS = tuple[float, float] | None
"""A heading as ``(cos ψ, sin ψ)``, the row that projects a current (north, east) on the
hull's axis; None where no heading is known (taken as straight)."""

ModelName = Literal["EM1", "EM2", "EM3", "EM4"]
"""The four error models of the paper."""

MODEL_NAMES: tuple[ModelName, ...] = ("EM1", "EM2", "EM3", "EM4")

ParamName = Literal["a", "m", "b"]
"""Short parameter names as the paper writes them (JSON keys use them too)."""

PARAM_NAMES: dict[ModelName, tuple[ParamName, ...]] = {
    "EM1": ("b",),
    "EM2": ("m",),
    "EM3": ("m", "b"),
    "EM4": ("a", "m", "b"),
}
"""The parameter vector θ of each model, in the paper's order."""

AMB_STATES: dict[ModelName, tuple[int, int, int]] = {
    model: tuple(1 + names.index(k) if k in names else 0 for k in ("a", "m", "b"))  # type: ignore[misc]
    for model, names in PARAM_NAMES.items()
}
"""The filter state index of ``a``, ``m`` and ``b`` in each model (after the speed; 0:
not a parameter of the model)."""

UnknownName = Literal["a", "m", "b", "current"]
"""What a calibration can estimate: the model parameters and the sea current (both components)."""

CURRENT: Final = "current"
"""The unknown name of the sea current (north and east components)."""


def check_model(model: str) -> ModelName:
    """Validate a model name.

    Args:
        model: ``"EM1"``, ``"EM2"``, ``"EM3"`` or ``"EM4"``.

    Returns:
        The same name, typed as :data:`ModelName`.

    Raises:
        ModelError: for any other name (the message lists the valid ones).
    """
    if model not in MODEL_NAMES:
        raise ModelError(f"unknown error model {model!r}; expected one of {', '.join(MODEL_NAMES)}")
    return model


@dataclass(frozen=True, slots=True)
class Params:
    """Parameters of one error model; those the model does not use are exactly 0.

    Attributes:
        model: which error model these parameters belong to.
        a_spm: quadratic coefficient ``a`` in s/m (EM4 only).
        m: scale-factor error ``m``, dimensionless (EM2, EM3, EM4).
        b_mps: bias ``b`` in m/s (EM1, EM3, EM4).

    Raises:
        ModelError: unknown model, a non-finite value, or a non-zero value for a
            parameter the model does not have.
    """

    model: ModelName
    a_spm: float = 0.0
    m: float = 0.0
    b_mps: float = 0.0

    def __post_init__(self) -> None:
        check_model(self.model)
        used = PARAM_NAMES[self.model]
        for name, value in (("a", self.a_spm), ("m", self.m), ("b", self.b_mps)):
            if not math.isfinite(value):
                raise ModelError(f"{self.model} parameter {name} is not finite: {value!r}")
            if name not in used and value != 0.0:
                raise ModelError(f"{self.model} has no parameter {name} (got {value!r})")

    @classmethod
    def from_theta(cls, model: str, theta: tuple[float, ...] | list[float] | FloatArray) -> Params:
        """Build parameters from the paper's vector θ.

        Args:
            model: the error model.
            theta: θ in the order of :data:`PARAM_NAMES` (``[a, m, b]`` for EM4), SI units.

        Returns:
            The parameters.

        Raises:
            ModelError: unknown model or θ of the wrong length.
        """
        name = check_model(model)
        names = PARAM_NAMES[name]
        values = [float(v) for v in theta]
        if len(values) != len(names):
            raise ModelError(f"{name} takes {len(names)} parameters {names}, got {len(values)}")
        kw = dict(zip(names, values, strict=True))
        return cls(name, a_spm=kw.get("a", 0.0), m=kw.get("m", 0.0), b_mps=kw.get("b", 0.0))

    @property
    def theta(self) -> tuple[float, ...]:
        """θ in the paper's order (see :data:`PARAM_NAMES`)."""
        values = {"a": self.a_spm, "m": self.m, "b": self.b_mps}
        return tuple(values[n] for n in PARAM_NAMES[self.model])

    def as_dict(self) -> dict[str, float]:
        """The model's parameters by short name, e.g. ``{"m": 0.05, "b": -0.1}`` (SI units)."""
        return dict(zip(PARAM_NAMES[self.model], self.theta, strict=True))

    def forward(self, v_mps: float) -> float:
        """What the EMlog reads at true speed ``v_mps`` (eqs. (10)–(13)), noise-free.

        Args:
            v_mps: true speed through the water in m/s.

        Returns:
            The modelled reading in m/s.
        """
        return (self.a_spm * v_mps + 1.0 + self.m) * v_mps + self.b_mps

    def correct(self, raw_mps: float) -> float:
        """The true speed for a raw reading: the inverse of :meth:`forward`.

        See the module docstring for the EM4 root choice and the edge cases.

        Args:
            raw_mps: the EMlog reading in m/s.

        Returns:
            The corrected speed in m/s (``nan`` only for a zero gain).
        """
        return invert(self.a_spm, self.m, self.b_mps, raw_mps)


def invert(a_spm: float, m: float, b_mps: float, raw_mps: float) -> float:
    """Invert ``raw = a·v² + (1+m)·v + b`` for v (scalar fast path of :meth:`Params.correct`).

    Args:
        a_spm: quadratic coefficient in s/m (0 for EM1–EM3).
        m: scale-factor error, dimensionless.
        b_mps: bias in m/s.
        raw_mps: the EMlog reading in m/s.

    Returns:
        The corrected speed in m/s: the root on the increasing branch of f, the vertex
        without a real root, ``nan`` for a gain ``1 + m ≤ 0``.
    """
    gain = 1.0 + m
    if not gain > 0.0:
        return math.nan
    rhs = raw_mps - b_mps
    a = a_spm
    if a == 0.0:
        return rhs / gain
    disc = gain * gain + 4.0 * a * rhs
    if disc < 0.0:
        return -gain / (2.0 * a)
    return 2.0 * rhs / (gain + math.sqrt(disc))


def zero_params(model: str) -> Params:
    """The ideal sensor of a model: every parameter 0 (the paper's KF initial state).

    Args:
        model: the error model.

    Returns:
        Parameters with ``a = m = b = 0``.
    """
    return Params(check_model(model))


def n_params(model: str) -> int:
    """Number of parameters p of a model (1, 1, 2, 3).

    Args:
        model: the error model.

    Returns:
        The length of θ.
    """
    return len(PARAM_NAMES[check_model(model)])


def design_row(model: ModelName, v_mps: float) -> tuple[float, ...]:
    """The design row h(v) with ``raw − v = h(v)·θ`` (rows of eqs. (18)–(21)).

    Scalar fast path for the per-sample filters (no numpy).

    Args:
        model: the error model (assumed valid: no check on the fast path).
        v_mps: the operating-point speed in m/s (the reference speed, pseudo-linear).

    Returns:
        ``(1,)``, ``(v,)``, ``(v, 1)`` or ``(v², v, 1)``.
    """
    if model == "EM3":
        return (v_mps, 1.0)
    if model == "EM1":
        return (1.0,)
    if model == "EM2":
        return (v_mps,)
    return (v_mps * v_mps, v_mps, 1.0)


def design_matrix(model: str, v_mps: npt.ArrayLike) -> FloatArray:
    """The paper's LS design matrix H for a speed series (eqs. (18)–(21)).

    Args:
        model: the error model.
        v_mps: reference speeds in m/s, shape (N,).

    Returns:
        H, shape (N, p), rows h(v_k).

    Raises:
        ModelError: unknown model.
    """
    name = check_model(model)
    v = np.asarray(v_mps, dtype=np.float64).reshape(-1)
    ones = np.ones_like(v)
    columns = {"EM1": (ones,), "EM2": (v,), "EM3": (v, ones), "EM4": (v * v, v, ones)}[name]
    return np.column_stack(columns)


def forward_array(params: Params, v_mps: npt.ArrayLike) -> FloatArray:
    """Vectorised :meth:`Params.forward`.

    Args:
        params: the error-model parameters.
        v_mps: true speeds in m/s, shape (N,).

    Returns:
        Modelled readings in m/s, shape (N,).
    """
    v = np.asarray(v_mps, dtype=np.float64)
    return np.asarray((params.a_spm * v + 1.0 + params.m) * v + params.b_mps, dtype=np.float64)


def correct_array(params: Params, raw_mps: npt.ArrayLike) -> FloatArray:
    """Vectorised :meth:`Params.correct` (same branch and edge cases).

    Args:
        params: the error-model parameters.
        raw_mps: raw EMlog readings in m/s, shape (N,).

    Returns:
        Corrected speeds in m/s, shape (N,).
    """
    raw = np.asarray(raw_mps, dtype=np.float64)
    gain = 1.0 + params.m
    if not gain > 0.0:
        return np.full_like(raw, np.nan)
    rhs = raw - params.b_mps
    a = params.a_spm
    if a == 0.0:
        return np.asarray(rhs / gain, dtype=np.float64)
    disc = gain * gain + 4.0 * a * rhs
    real = disc >= 0.0
    root = 2.0 * rhs / (gain + np.sqrt(np.where(real, disc, 0.0)))
    return np.asarray(np.where(real, root, -gain / (2.0 * a)), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class Layout:
    """The state vector of one filter: ``[v, θ…, (c_N, c_E)]``.

    Attributes:
        model: the error model.
        current: whether the two current states are present.
    """

    model: ModelName
    current: bool = False

    @property
    def params(self) -> tuple[str, ...]:
        """The model's parameter names θ, in the paper's order."""
        return PARAM_NAMES[self.model]

    @property
    def unknowns(self) -> tuple[UnknownName, ...]:
        """Every unknown the filter estimates (parameters, then ``"current"``)."""
        names: tuple[UnknownName, ...] = PARAM_NAMES[self.model]
        return (*names, CURRENT) if self.current else names

    @property
    def states(self) -> tuple[str, ...]:
        """State names: ``v_mps``, the parameters, ``c_north_mps``, ``c_east_mps``."""
        cur = ("c_north_mps", "c_east_mps") if self.current else ()
        return ("v_mps", *self.params, *cur)

    @property
    def n(self) -> int:
        """Number of states."""
        return 1 + len(self.params) + (2 if self.current else 0)

    def indices(self, unknown: str) -> tuple[int, ...]:
        """State indices of one unknown (two for the current).

        Raises:
            ModelError: not an unknown of this layout.
        """
        if unknown == CURRENT and self.current:
            p = len(self.params)
            return (1 + p, 2 + p)
        if unknown in self.params:
            return (1 + self.params.index(unknown),)
        raise ModelError(
            f"{unknown!r} is not an unknown of {self.model}{' + current' * self.current}"
        )
