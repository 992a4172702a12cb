"""The pipeline's status, assembled from its parts: what ``emlogd status`` shows, what the
daemon logs and hands to sd_notify, and the fields of the ``$PEMLS`` sentence.

Everything here reads and nothing changes: the UUTs' routing state
(:class:`~emlogd.pipeline.routing.UutRoute`), the decoders' counters and the ports'
staleness (:class:`~emlogd.pipeline.staleness.Liveness`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from drivers.base import Decoder
from emlogd.pipeline.fusion import Fused
from emlogd.pipeline.routing import UutRoute
from emlogd.pipeline.sentences import StatusFields
from emlogd.pipeline.staleness import Liveness


def status_fields(u: UutRoute) -> StatusFields:
    """The fields of a UUT's ``$PEMLS`` status sentence."""
    cal = u.cal
    p = cal.applied
    return StatusFields(
        port=u.s.port,
        maker=u.s.maker,
        state=cal.state,
        model=u.s.model,
        params=p.as_dict() if p is not None else {},
        std={k: v for k, v in cal.applied_std.items() if v is not None} if p is not None else {},
        nis_mean=cal.nis_mean(),
        ref_state=cal.ref_state,
    )


def port_status(
    decoders: Mapping[str, Decoder[Any]], liveness: Liveness
) -> dict[str, dict[str, object]]:
    """Per port: decoded records, rejects by reason, staleness, last receive time."""
    return {
        name: {
            **dec.counters.as_dict(),
            "stale": liveness.stale[name],
            "last_rx": liveness.last.get(name),
        }
        for name, dec in decoders.items()
    }


def fused_status(last: Fused | None) -> dict[str, object] | None:
    """The fused speed last sent, or None."""
    if last is None:
        return None
    return {
        "valid": last.valid,
        "speed_mps": last.speed_mps if last.valid else None,
        "std_mps": last.std_mps if last.valid else None,
        "sources": last.sources,
        "excluded": dict(last.excluded),
    }


def uut_status(u: UutRoute) -> dict[str, object]:
    """A UUT's JSON-ready status (README: the ``emlogd status --json`` keys)."""
    cal = u.cal
    kf = cal.kf
    ident = cal.ident
    cur = kf.current_mps
    cur_std = kf.current_std_mps
    return {
        "state": cal.state,
        "reason": cal.reason,
        "reference": cal.ref_state,
        "heading_port": u.heading_port,
        "heading_suspect": u.heading_check.reason(),
        "learning_enabled": cal.learn_on,
        "model": u.s.model,
        "params": cal.applied.as_dict() if cal.applied is not None else None,
        "param_std": dict(cal.applied_std) if cal.applied is not None else None,
        "estimate": kf.params.as_dict(),
        "estimate_std": kf.param_std,
        "current": None
        if cur is None or cur_std is None
        else {
            "north_mps": cur[0],
            "east_mps": cur[1],
            "std_north_mps": cur_std[0],
            "std_east_mps": cur_std[1],
            "determined": cal.ident_current(),
        },
        "lag_s": cal.lag_s,
        "determined": list(ident.determined) if ident is not None else [],
        "unidentifiable": list(ident.unidentifiable) if ident is not None else [],
        "identifiability": ident.reason if ident is not None else "",
        "nis_mean": cal.nis_mean(),
        "samples_learnt": cal.n_learnt,
        "freezes": cal.freezes,
        "counters": {**cal.counters.as_dict(), **u.implausible},
        "scored_samples": cal.score.n,
        "rmse_raw": cal.score.rmse_raw,
        "rmse_corrected": cal.score.rmse_corrected,
    }


def summary(uuts: Mapping[str, UutRoute]) -> str:
    """One line for sd_notify STATUS=: each UUT's state, calibration and reference."""
    parts = []
    for name, u in uuts.items():
        cal = u.cal
        if cal.applied is not None:
            pv = " ".join(f"{k}={v:+.3f}" for k, v in cal.applied.as_dict().items())
            parts.append(f"{name} {cal.state} {u.s.model} {pv} ref {cal.ref_state}")
        else:
            parts.append(f"{name} {cal.state} ref {cal.ref_state}")
    return "; ".join(parts)
