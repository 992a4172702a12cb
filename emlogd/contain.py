"""Containment of a failure while handling one record (docs/RELIABILITY.md).

The decoders reject bad input with a reason; whatever still fails while one record goes
through the pipeline (an exception no check foresaw) must cost that record only. The
daemon loop and the offline commands wrap their per-record call to the pipeline and hand
any exception to :class:`Containment`, which counts it as an ``internal`` reject of the
port (in the port's decoder counters, beside the other reasons), keeps the first
failures for a report, and says when one is worth a log line: at most one per
:data:`LOG_INTERVAL_S` per (port, exception type), the next line telling how many were
left out. The run goes on.

Used by both emlogd.daemon and emlogd.offline (neither imports the other).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from emlogd.pipeline.core import Pipeline

LOG_INTERVAL_S = 10.0
"""Least time (s) between two log lines of the same (port, exception type)."""

MAX_KEPT = 10
"""How many failures :attr:`Containment.first` keeps (the first ones)."""

RAW_SHOWN = 120
"""How many bytes of the record a report shows."""


@dataclass(frozen=True, slots=True)
class Failure:
    """One contained failure: the port, the exception (``Type: message``), the record's
    bytes (the first :data:`RAW_SHOWN`, as in a Python bytes literal) and how many failures of the
    same port and type were left out of the log since the last line."""

    port: str
    error: str
    data: str
    suppressed: int = 0

    def as_dict(self) -> dict[str, object]:
        """JSON-ready."""
        return {"port": self.port, "error": self.error, "data": self.data}


@dataclass(slots=True)
class Containment:
    """Counts, keeps and rate-limits the failures of one run (see the module docstring).

    Attributes:
        interval_s: least time between two log lines of one (port, exception type).
        count: failures contained.
        first: the first :data:`MAX_KEPT` failures.
    """

    interval_s: float = LOG_INTERVAL_S
    count: int = 0
    first: list[Failure] = field(default_factory=list)
    _last: dict[tuple[str, str], float] = field(default_factory=dict)
    _left_out: dict[tuple[str, str], int] = field(default_factory=dict)

    def failed(
        self, pipeline: Pipeline | None, port: str, data: bytes, exc: Exception, now: float
    ) -> Failure | None:
        """Contain ``exc``, raised while ``pipeline`` handled ``data`` of ``port`` at ``now``
        (any monotonic time, s): count it, and return it when it is to be logged (None
        when a line for its port and type was logged less than :attr:`interval_s` ago)."""
        self.count += 1
        if pipeline is not None:
            dec = pipeline.decoders.get(port)
            if dec is not None:
                dec.counters.rejects["internal"] += 1
        kind = type(exc).__name__
        failure = Failure(port, f"{kind}: {exc}", repr(data[:RAW_SHOWN])[2:-1])
        if len(self.first) < MAX_KEPT:
            self.first.append(failure)
        key = (port, kind)
        last = self._last.get(key)
        if last is not None and now - last < self.interval_s:
            self._left_out[key] = self._left_out.get(key, 0) + 1
            return None
        self._last[key] = now
        return Failure(failure.port, failure.error, failure.data, self._left_out.pop(key, 0))

    def report(self) -> dict[str, object]:
        """``{"count": n, "first": [{"port", "error", "data"}]}``."""
        return {"count": self.count, "first": [f.as_dict() for f in self.first]}
