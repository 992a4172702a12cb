"""Glue between the config and the pipeline.

The loaded config holds the pipeline's settings themselves (every key declared once,
see :mod:`emlogd.config`); these functions hand them over.
"""

from __future__ import annotations

from emlogd.config import Config
from emlogd.pipeline.core import PortSettings, UutSettings
from emlogd.pipeline.fusion import FusionSettings


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
