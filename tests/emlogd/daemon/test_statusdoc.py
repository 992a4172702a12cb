"""The control socket's status document (emlogd/daemon/statusdoc.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

from emlogd.config import parse_config
from emlogd.daemon.statusdoc import status_document
from emlogd.settings import build_pipeline

CONFIG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: emlog2, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
  - {uut: emlog2, reference: dvl, talker: VD}
"""


@dataclass
class _Source:
    """What the document reads of a port's source."""

    is_open: bool
    why_closed: str | None = None


def test_each_port_says_whether_it_is_open_and_why_not() -> None:
    """An open port never heard is ``never heard``, ``open`` once it sent; a closed one ``not open`` and stale, with
    its source's reason; a port without a source says so; ``uut`` keeps that UUT and
    the ports it reads."""
    pipeline = build_pipeline(parse_config(CONFIG), {}, [])
    sources = {"emlog1": _Source(True), "dvl": _Source(False, "links/dvl: gone")}
    doc = status_document(pipeline, cast(Any, sources))
    ports = cast(dict[str, dict[str, object]], doc["ports"])
    assert ports["emlog1"]["state"] == "never heard" and ports["emlog1"]["why_closed"] is None
    pipeline.feed(1.0, "emlog1", b"$VWVHW,,T,,M,5.00,N,,K*4F\r\n")
    doc = status_document(pipeline, cast(Any, sources))
    ports = cast(dict[str, dict[str, object]], doc["ports"])
    assert ports["emlog1"]["state"] == "open" and ports["emlog1"]["stale"] is False
    assert ports["dvl"]["state"] == "not open" and ports["dvl"]["stale"] is True
    assert ports["dvl"]["why_closed"] == "links/dvl: gone"
    assert ports["emlog2"]["why_closed"] == "no source"
    one = status_document(pipeline, cast(Any, sources), "emlog1")
    assert set(cast(dict[str, object], one["uuts"])) == {"emlog1"}
    assert set(cast(dict[str, object], one["ports"])) == {"emlog1", "dvl"}
