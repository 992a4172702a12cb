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


HEADING_PROTOCOLS = frozenset({"pd6", "pd13", "pd0", "pd5"})
"""DVL outputs that carry the heading with the bottom and water track."""


def heading_expected(cfg: Config, u: UutConfig) -> bool:
    """A heading is known to come for ``u``: a heading port is named, the reference is a
    DVL output that carries one, or the reference is GNSS (which needs one anyway).

    ``current: auto`` estimates the current exactly then: in the water frame the
    calibration is the sensor's (without it a current ends up in the scale and bias);
    without a heading the current cannot be observed at all.
    """
    if u.heading != "auto" or u.reference_field == "gnss":
        return True
    return (
        u.reference_field in ("bottom", "water")
        and cfg.port(u.reference).protocol in HEADING_PROTOCOLS
    )


def _uut(cfg: Config, u: UutConfig) -> UutSettings:
    same: dict[str, Any] = {name: getattr(u, name) for name in _SAME - {"talker"}}
    if u.current == "auto":
        same["current"] = heading_expected(cfg, u)
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
        talker=u.talker or cfg.outputs.talker,
        maker=cfg.outputs.maker,
        status_interval_s=cfg.outputs.status_interval_s,
        **same,
    )
