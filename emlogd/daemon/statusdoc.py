"""The status the control socket answers: the pipeline's, with each port's state as the
daemon's sources see it (the pipeline knows what it decoded, not whether a port is open)."""

from __future__ import annotations

from collections.abc import Mapping

from drivers.io.port import SerialSource
from emlogd.pipeline.core import Pipeline


def status_document(
    pipeline: Pipeline,
    sources: Mapping[str, SerialSource],
    uut: str | None = None,
    echoes: Mapping[str, int] | None = None,
) -> dict[str, object]:
    """The pipeline's status with each port's ``open`` (and ``why_closed``) from its
    source and ``state``: ``not open``, ``never heard`` (open, not a byte decoded since
    the start: no age to give, and no sign yet that the device is there), ``stale`` or
    ``open``; a port not open is stale (no data can come); ``echoes``: its lines that were the daemon's own output, skipped
    (:mod:`emlogd.daemon.echo`). ``ports_not_open``: each port that is not open and why
    (a device missing or not a serial device at the start, lost since: its source tries it
    again with backoff, the daemon running on the rest). With ``uut``: that UUT and the
    ports it reads only."""
    status = pipeline.status()
    ports = status["ports"]
    assert isinstance(ports, dict)
    for name, port in ports.items():
        src = sources.get(name)
        opened = src is not None and src.is_open
        port["open"] = opened
        port["why_closed"] = None if opened else (src.why_closed if src else "no source")
        port["stale"] = bool(port.get("stale")) or not opened
        port["state"] = (
            "not open"
            if not opened
            else "stale"
            if port["stale"]
            else "never heard"
            if port.get("last_rx") is None
            else "open"
        )
        port["echoes"] = (echoes or {}).get(name, 0)
    if uut is not None:
        route = pipeline.uuts[uut]
        mine = {route.s.port, route.s.reference_port, route.heading_port}
        uuts = status["uuts"]
        assert isinstance(uuts, dict)
        status["uuts"] = {uut: uuts[uut]}
        ports = status["ports"] = {n: v for n, v in ports.items() if n in mine}
    status["ports_not_open"] = {n: v["why_closed"] for n, v in ports.items() if not v["open"]}
    return status
