"""Glue between the config and the pipeline.

The loaded config holds the pipeline's settings themselves (every key declared once,
see :mod:`emlogd.config`); these functions hand them over, and :func:`build_pipeline`
builds the pipeline ``emlogd run``, its reload and ``emlogd replay`` use.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping

from emlogd.config import Config
from emlogd.pipeline.calibration import Calibration
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.fusion import FusionSettings
from emlogd.pipeline.settings import PortSettings, UutSettings


def fusion_from_config(cfg: Config) -> FusionSettings | None:
    """The fused output's settings, or None when each log's sentences go out alone."""
    if cfg.outputs.speed == "each":
        return None
    o = cfg.outputs
    return FusionSettings(
        only=o.speed == "fused",
        talker=o.fused_talker,
        gate_chi2=o.fused_gate_chi2,
        hold_s=o.fused_hold_s,
        rejoin_s=o.fused_rejoin_s,
        max_current_mps=o.fused_max_current_mps,
    )


def pipeline_from_config(cfg: Config) -> tuple[list[PortSettings], list[UutSettings]]:
    """The pipeline's port and UUT settings for ``cfg``: the config's own objects."""
    return [p.settings for p in cfg.ports], [u.settings for u in cfg.calibration]


def build_pipeline(
    cfg: Config,
    calibrations: Mapping[str, Calibration] | None = None,
    others: Iterable[Calibration] = (),
    *,
    learn: bool | None = None,
) -> Pipeline:
    """The pipeline of ``cfg`` started from a state: what ``emlogd run`` starts with, what
    a reload builds (then :meth:`Pipeline.adopt` takes over what did not change) and
    what ``emlogd replay`` drives.

    Args:
        cfg: the loaded config.
        calibrations: the calibrations in use by UUT (a state file's, or at a reload
            the running pipeline's).
        others: the UUTs' calibrations of their other error models.
        learn: overrides every UUT's ``learn`` (``replay --learn/--no-learn``).

    Raises:
        ValueError: a UUT names a port the config does not have.
    """
    ports, uuts = pipeline_from_config(cfg)
    if learn is not None:
        uuts = [dataclasses.replace(u, learn=learn) for u in uuts]
    return Pipeline(ports, uuts, calibrations, fusion=fusion_from_config(cfg), others=others)
