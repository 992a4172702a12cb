"""Containment of a failure while one record is handled: counted, kept, rate-limited."""

from __future__ import annotations

from emlogd.contain import MAX_KEPT, Containment
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings


def test_a_failure_is_an_internal_reject_of_its_port_logged_at_most_once_per_interval() -> None:
    """Each failure counts one internal reject of its port and one in the total; the first of a
    (port, exception type) is to be logged, the next within 10 s are not, and the line after the
    interval says how many were left out; another port or type is not held back."""
    p = Pipeline([PortSettings("compass", "nmea0183"), PortSettings("dvl", "pd6")], [])
    c = Containment(10.0)
    boom = ValueError("math domain error")
    first = c.failed(p, "compass", b"$HCHDG,10.0,1e308,E*73\r\n", boom, 0.0)
    assert first is not None and first.error == "ValueError: math domain error"
    assert first.data == "$HCHDG,10.0,1e308,E*73\\r\\n" and first.suppressed == 0
    assert c.failed(p, "compass", b"x", boom, 1.0) is None
    assert c.failed(p, "compass", b"x", boom, 9.9) is None
    assert c.failed(p, "dvl", b"\xff", boom, 2.0) is not None  # another port
    assert c.failed(p, "compass", b"x", KeyError("k"), 2.0) is not None  # another type
    later = c.failed(p, "compass", b"x", boom, 10.5)
    assert later is not None and later.suppressed == 2
    assert p.decoders["compass"].counters.rejects["internal"] == 5
    assert p.decoders["dvl"].counters.rejects["internal"] == 1
    assert p.port_status()["compass"]["rejects"]["internal"] == 5  # type: ignore[index]
    rep = c.report()
    assert rep["count"] == 6 and len(rep["first"]) == 6  # type: ignore[arg-type]
    for k in range(2 * MAX_KEPT):
        c.failed(None, "", b"", boom, 100.0 + k)  # no pipeline (a tick): counted all the same
    assert c.count == 6 + 2 * MAX_KEPT and len(c.first) == MAX_KEPT
