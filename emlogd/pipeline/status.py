"""The pipeline's status, assembled from its parts: what ``emlogd status`` shows, what the
daemon logs and hands to sd_notify, and the fields of the ``$PEMLS`` sentence.

Everything here reads and nothing changes: the UUTs' routing state
(:class:`~emlogd.pipeline.routing.UutRoute`), the decoders' counters and the ports'
staleness (:class:`~emlogd.pipeline.staleness.Liveness`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from drivers.base import Decoder
from emlogd.pipeline.fusion import Fused
from emlogd.pipeline.routing import Headings, UutRoute
from emlogd.pipeline.sentences import StatusFields
from emlogd.pipeline.staleness import Liveness, silent


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


def heading_reason(u: UutRoute, headings: Headings) -> str | None:
    """Why the UUT has no heading to trust, its sources disagreeing unresolved; or why a
    GNSS reference projects nothing, when the heading is the cause: none, a magnetic one
    without a variation, or one the course check flagged."""
    if u.sources_why:
        return u.sources_why
    if u.s.reference_field != "gnss" or u.cal.ref_state == "valid":
        return None
    if u.heading_check.suspect:
        return u.heading_check.reason()
    check = u.course_check
    if check.flagged():
        return f"heading {check.offset_deg():+.1f}° off the course over ground: not used"
    if u.heading_port is not None:
        return None
    refused = sum(ph.refused_magnetic for ph in headings.rings.values())
    if refused:
        return (
            f"heading magnetic without a variation ({refused} refused): "
            "set magnetic_variation_deg or give GNSS positions"
        )
    return (
        "no heading for the GNSS reference"
        if u.gnss or u.cal.learner.t_ref_last > -math.inf
        else None
    )


def heading_status(u: UutRoute, headings: Headings) -> dict[str, object]:
    """A UUT's heading: its port, the variation used and from where (``log``,
    ``config``, ``model``), the magnetic headings refused for want of one, the
    heading-against-course check and the GNSS fixes it refused."""
    port = u.heading_port
    var, source = headings.variation_source(port if port is not None else u.s.reference_port)
    ph = headings.rings.get(port) if port is not None else None
    if ph is None or not ph.magnetic:
        var = source = None  # a true heading: no variation used
    refused = sum(p.refused_magnetic for p in headings.rings.values())
    return {
        "port": port,
        "variation_deg": None if var is None else round(var, 2),
        "variation_source": source,
        "refused_magnetic": refused,
        "check": u.course_check.as_dict(),
        "refused_by_check": u.course_refused,
        "sources": headings.sources.status(),
    }


def _age(last: float | None, now: float) -> float | None:
    if last is None or not math.isfinite(last) or not math.isfinite(now):
        return None
    return round(max(now - last, 0.0), 1)


def reference_state(u: UutRoute, now: float) -> str:
    """The reference's state as the log sees it at ``now``: the learner's (set when a
    reading is aligned), but ``stale`` once no reference has reached the log for its stale
    time — with the log's own readings stopped too, nothing else would say so."""
    learner = u.cal.learner
    state: str = learner.ref_state
    if state in ("none", "stale"):
        return state
    gap = max(learner.s.ref_stale_s, learner.ref.gap_s)
    return "stale" if silent(learner.t_ref_last, now, gap) else state


def input_freshness(
    u: UutRoute, liveness: Liveness | None, now: float
) -> dict[str, dict[str, object]]:
    """How fresh the log's inputs are at ``now``: for its reading, its reference and its
    heading, the port, the seconds since the port was last heard (None: never) and
    whether it is stale; for the reference also the seconds since one reached the log."""
    ports = {
        "reading": u.s.port,
        "reference": u.s.reference_port,
        "heading": u.heading_port,
    }
    out: dict[str, dict[str, object]] = {}
    for role, port in ports.items():
        last = liveness.last.get(port) if liveness is not None and port is not None else None
        out[role] = {
            "port": port,
            "age_s": _age(last, now),
            "stale": bool(liveness.stale.get(port, False))
            if liveness is not None and port is not None
            else False,
        }
    out["reference"]["used_age_s"] = _age(u.cal.learner.t_ref_last, now)
    return out


def uut_status(
    u: UutRoute,
    headings: Headings,
    liveness: Liveness | None = None,
    now: float = math.nan,
) -> dict[str, object]:
    """A UUT's JSON-ready status (README: the ``emlogd status --json`` keys) at ``now``
    (the pipeline's latest time; nan: the reference's state as the learner left it)."""
    cal = u.cal
    kf = cal.kf
    ident = cal.ident
    cur = kf.current_mps
    cur_std = kf.current_std_mps
    return {
        "state": cal.state,
        "reason": heading_reason(u, headings) or cal.reason,
        "reference": reference_state(u, now) if math.isfinite(now) else cal.ref_state,
        "inputs": input_freshness(u, liveness, now),
        "heading_port": u.heading_port,
        "heading": heading_status(u, headings),
        "heading_suspect": u.heading_check.reason() or u.sources_why,
        "learning_enabled": cal.learn_on,
        "model": u.s.model,
        "params": cal.applied.as_dict() if cal.applied is not None else None,
        "param_std": dict(cal.applied_std) if cal.applied is not None else None,
        # the calibration kept for this model: the applied one, else the last good one
        # (restored and awaiting validation, or withdrawn for cause and re-validating)
        "kept": cal.sup.kept.as_dict() if cal.sup.kept is not None else None,
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
        # IMO A.824(19) against the reference as the status's RMSE: raw and emitted
        "imo": dict(zip(("raw", "corrected"), (v.as_dict() for v in cal.score.imo()), strict=True)),
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
