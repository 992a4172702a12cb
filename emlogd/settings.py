"""Glue between the config and the pipeline.

:func:`pipeline_from_config` turns a validated :class:`~emlogd.config.Config` into
the pipeline's settings.
"""

from __future__ import annotations

from calib.excitation import ExcitationRule
from calib.kalman import KfConfig
from emlogd.config import Config
from emlogd.pipeline.core import PortSettings, UutSettings


def pipeline_from_config(cfg: Config) -> tuple[list[PortSettings], list[UutSettings]]:
    """The pipeline's port and UUT settings for ``cfg``."""
    ports = [
        PortSettings(p.name, p.protocol, p.checksum, p.max_length, p.stale_timeout_s)
        for p in cfg.ports
    ]
    uuts = [
        UutSettings(
            port=u.uut,
            model=u.model,
            reference_port=u.reference,
            ref_stale_s=cfg.port(u.reference).stale_timeout_s,
            reference_field=u.reference_field,
            lag_s=u.lag_s,
            lag_window_s=u.lag_window_s,
            max_lag_s=u.max_lag_s,
            learn=u.learn,
            apply=u.apply,
            min_ref_speed_mps=u.min_ref_speed_mps,
            max_param_std=dict(u.max_param_std),
            excitation_half_life_samples=u.excitation_half_life_samples,
            persist_interval_s=u.persist_interval_s,
            persist_min_change_sigma=u.persist_min_change_sigma,
            persist_min_change_abs=u.persist_min_change_abs,
            validation_s=u.validation_s,
            recheck_s=u.recheck_s,
            kf=KfConfig(
                r_raw_mps2=u.r_raw_mps**2,
                r_ref_mps2=u.r_ref_mps**2,
                p0=u.p0,
                q_params=u.q_params,
            ),
            rule=ExcitationRule(),
            uut_source=u.uut_source,
            talker=cfg.outputs.talker,
            maker=cfg.outputs.maker,
            status_interval_s=cfg.outputs.status_interval_s,
        )
        for u in cfg.calibration
    ]
    return ports, uuts
