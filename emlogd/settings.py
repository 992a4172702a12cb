"""Glue between the config, the pipeline and the state file.

:func:`pipeline_from_config` turns a validated :class:`~emlogd.config.Config` into
the pipeline's settings; :func:`snapshot_to_state` and :func:`state_to_snapshot`
convert between the pipeline's good calibration and the persisted state.
"""

from __future__ import annotations

import math

from calib.excitation import ExcitationRule
from calib.kalman import KfConfig
from calib.models import PARAM_NAMES, Params, check_model
from emlogd.config import Config
from emlogd.daemon.statefile import CalibrationState, now_iso
from emlogd.pipeline.core import PortSettings, Snapshot, UutSettings


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


def snapshot_to_state(s: Snapshot) -> CalibrationState:
    """The persisted form of a pipeline snapshot."""
    return CalibrationState(
        uut=s.uut,
        model=s.model,
        params=s.params.as_dict(),
        param_std=dict(s.param_std),
        covariance=s.covariance,
        t=s.t,
        n_samples=s.n_samples,
        lag_s=s.lag_s,
        excitation={k: float(v) for k, v in s.excitation.items()},
        nis_mean=s.nis_mean,
        saved_at=now_iso(),
    )


def state_to_snapshot(st: CalibrationState) -> Snapshot:
    """A pipeline snapshot from a persisted state (missing parameters count as 0).

    Raises:
        ModelError: an unknown model in the file.
    """
    model = check_model(st.model)
    theta = [float(st.params.get(name, 0.0)) for name in PARAM_NAMES[model]]
    return Snapshot(
        uut=st.uut,
        model=model,
        params=Params.from_theta(model, theta),
        param_std={k: v for k, v in st.param_std.items() if math.isfinite(v)},
        covariance=st.covariance,
        t=st.t,
        n_samples=st.n_samples,
        lag_s=st.lag_s,
        excitation=dict(st.excitation),
        nis_mean=st.nis_mean,
    )
