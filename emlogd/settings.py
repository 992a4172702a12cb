"""Glue between the config and the pipeline.

The loaded config holds the pipeline's settings themselves (every key declared once,
see :mod:`emlogd.config`); these functions hand them over.
"""

from __future__ import annotations

from emlogd.config import Config
from emlogd.pipeline.fusion import FusionSettings
from emlogd.pipeline.settings import PortSettings, UutSettings


def fusion_from_config(cfg: Config) -> FusionSettings | None:
    """The fused output's settings, or None when each log's sentences go out alone."""
    if cfg.outputs.speed == "each":
        return None
    return FusionSettings(only=cfg.outputs.speed == "fused", talker=cfg.outputs.fused_talker)


def pipeline_from_config(cfg: Config) -> tuple[list[PortSettings], list[UutSettings]]:
    """The pipeline's port and UUT settings for ``cfg``: the config's own objects."""
    return [p.settings for p in cfg.ports], [u.settings for u in cfg.calibration]
