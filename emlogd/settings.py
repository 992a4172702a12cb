"""Glue between the config and the pipeline.

:func:`pipeline_from_config` turns a validated :class:`~emlogd.config.Config` into
the pipeline's settings.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from calib.excitation import ExcitationRule
from calib.kalman import KfConfig
from emlogd.config import Config, UutConfig
from emlogd.pipeline.core import REF_NOISE_MPS, PortSettings, UutSettings
from emlogd.pipeline.fusion import FusionSettings
from emlogd.pipeline.integrity import Envelope


def fusion_from_config(cfg: Config) -> FusionSettings | None:
    """The fused output's settings, or None when each log's sentences go out alone."""
    if cfg.outputs.speed == "each":
        return None
    return FusionSettings(only=cfg.outputs.speed == "fused", talker=cfg.outputs.fused_talker)


def pipeline_from_config(cfg: Config) -> tuple[list[PortSettings], list[UutSettings]]:
    """The pipeline's port and UUT settings for ``cfg``.

    A ``calibration`` key whose :class:`UutConfig` field has a :class:`UutSettings`
    field of the same name passes as it is; the filter's tuning and the envelope's
    speed range are built here, and the status sentence takes the ``outputs`` keys.
    """
    ports = [
        PortSettings(p.name, p.protocol, p.checksum, p.max_length, p.stale_timeout_s)
        for p in cfg.ports
    ]
    return ports, [_uut(cfg, u) for u in cfg.calibration]


_SAME = frozenset(f.name for f in dataclasses.fields(UutSettings)) & frozenset(
    f.name for f in dataclasses.fields(UutConfig)
)
"""The config fields that pass to the pipeline unchanged."""


def _uut(cfg: Config, u: UutConfig) -> UutSettings:
    same: dict[str, Any] = {name: getattr(u, name) for name in _SAME}
    same["max_param_std"] = dict(u.max_param_std)
    r_ref = u.r_ref_mps if u.r_ref_mps is not None else REF_NOISE_MPS[u.reference_field]
    return UutSettings(
        port=u.uut,
        reference_port=u.reference,
        ref_stale_s=cfg.port(u.reference).stale_timeout_s,
        kf_config=KfConfig(
            r_raw_mps2=u.r_raw_mps**2,
            r_ref_mps2=r_ref**2,
            p0=u.p0,
            q_params=u.q_params,
            current_psd_m2ps3=u.current_psd_m2ps3,
        ),
        envelope=dataclasses.replace(Envelope(), max_speed_mps=u.max_speed_mps),
        rule=ExcitationRule(),
        talker=cfg.outputs.talker,
        maker=cfg.outputs.maker,
        status_interval_s=cfg.outputs.status_interval_s,
        **same,
    )
