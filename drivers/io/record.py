"""Record live ports into a capture v1 file (what ``emlogd record`` runs).

Each port is a :class:`~drivers.io.port.SerialSource`, so a device that goes away is
reopened as the daemon would (its events are handed to ``on_event``); every chunk is
stamped with its receive time on the recording's timeline: the wall time at its start
plus the monotonic time since, as the daemon stamps its data. A wall clock stepped
back or forward meanwhile (NTP or GNSS time setting a computer that booted with a wrong
clock, an operator) moves no stamp: stepped back an hour, every chunk of that hour took
the last time written before the step, an hour of data at one instant. A text port's
bytes are split into lines, each stored verbatim (a line not ended within
:data:`MAX_PARTIAL_BYTES` is stored as a chunk of what came so far, its rest after it);
a binary port's chunks are stored as they came. Times never go backwards in the file.
"""

from __future__ import annotations

import selectors
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from drivers import DeviceError, is_binary
from drivers.io.capture import CaptureWriter
from drivers.io.port import PortEvent, SerialSource

MAX_PARTIAL_BYTES = 4096
"""Most bytes of a text port's line kept waiting for its end: past it, what came is
written as a chunk at once (the replayed bytes the same). A port that sends no newline
(garbage, a wrong baud rate) was held whole and copied at every read: memory without
bound and each read's cost growing with it, every port's stamps late behind it."""

SELECT_TIMEOUT_S = 0.2
"""Longest wait for input: how often ``should_stop``, the deadline and the ports'
reopening are looked at."""


@dataclass(frozen=True, slots=True)
class PortSpec:
    """One port to record: its name in the capture, URL, baud rate and protocol."""

    name: str
    url: str
    baud: int
    protocol: str


def record(
    specs: Sequence[PortSpec],
    out: str | Path,
    *,
    duration_s: float | None = None,
    stale_timeout_s: float = 5.0,
    should_stop: Callable[[], bool] = lambda: False,
    on_event: Callable[[PortEvent], object] = lambda ev: None,
    on_progress: Callable[[dict[str, int]], object] = lambda counts: None,
    clock: Callable[[], float] = time.time,
    monotonic: Callable[[], float] = time.monotonic,
) -> dict[str, int]:
    """Record ``specs`` into ``out`` until ``should_stop()``, ``duration_s`` or Ctrl-C.

    Args:
        specs: the ports (unique names).
        out: the capture file (``.gz``: compressed).
        duration_s: stop after this long, s (None: until stopped).
        stale_timeout_s: a port silent this long is reported stale.
        should_stop: polled at least every :data:`SELECT_TIMEOUT_S`.
        on_event: each port event (opened, lost, stale…).
        on_progress: the records written so far per port, after each wait.
        clock: the wall clock, read once, at the start: it anchors the timeline.
        monotonic: the clock the timeline advances with.

    Returns:
        The records written per port.

    Raises:
        DeviceError: a port cannot be opened at the start (nothing is written).
        ValueError: bad port names for a capture, or names not unique.
    """
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ValueError("port names must be unique")
    epoch = clock() - monotonic()

    def timeline() -> float:
        return epoch + monotonic()

    sources = {
        s.name: SerialSource(
            s.name, s.url, baudrate=s.baud, stale_timeout_s=stale_timeout_s, clock=timeline
        )
        for s in specs
    }
    rec = _Recording(sources, {s.name: is_binary(s.protocol) for s in specs}, on_event)
    rec.clock = timeline
    t_end = None if duration_s is None else time.monotonic() + duration_s
    try:
        for name, src in sources.items():
            if not src.open():
                # a device missing at the start is a mistake on the command line, not an
                # outage to ride out: fail before writing anything
                why = "; ".join(ev.detail for ev in src.events()) or "cannot open"
                raise DeviceError(f"port {name}: {why}")
        with CaptureWriter(out, {s.name: s.protocol for s in specs}) as writer:
            while not should_stop() and (t_end is None or time.monotonic() < t_end):
                rec.watch()
                try:
                    ready = rec.sel.select(timeout=SELECT_TIMEOUT_S)
                except KeyboardInterrupt:
                    break
                for key, _ in ready:
                    rec.read(key.data, writer)
                on_progress(rec.counts)
            rec.finish(writer)
    finally:
        for src in sources.values():
            src.close()
        rec.sel.close()
    return rec.counts


class _Recording:
    """The ports being recorded: which are watched for input, each text port's partial
    line, the records written per port, the last time written."""

    def __init__(
        self,
        sources: dict[str, SerialSource],
        binary: dict[str, bool],
        on_event: Callable[[PortEvent], object],
    ) -> None:
        self.sources = sources
        self.binary = binary
        self.on_event = on_event
        self.partial = {name: bytearray() for name in sources}
        self.counts = dict.fromkeys(sources, 0)
        self.sel = selectors.DefaultSelector()
        self.registered: dict[str, int] = {}
        self.last_t = 0.0
        self.clock: Callable[[], float] = time.time
        """The recording's timeline (what the end's unterminated lines are stamped with)."""

    def watch(self) -> None:
        """Watch each port's current descriptor (a reopened port has a new one) and hand
        on its events."""
        for name, src in self.sources.items():
            fd = src.fileno()
            if self.registered.get(name) != fd:
                if name in self.registered:
                    self.sel.unregister(self.registered.pop(name))
                if fd is not None:
                    self.sel.register(fd, selectors.EVENT_READ, name)
                    self.registered[name] = fd
            for ev in src.poll() + src.events():
                self.on_event(ev)

    def read(self, name: str, writer: CaptureWriter) -> None:
        """What a ready port has, written: a binary chunk as it came, text as lines."""
        chunk = self.sources[name].read()
        if chunk is None:
            return
        t_read, data = chunk
        self.last_t = t = max(t_read, self.last_t)
        if self.binary[name]:
            writer.write_chunk(t, name, data)
            self.counts[name] += 1
            return
        buf = self.partial[name]
        buf += data
        *lines, rest = bytes(buf).split(b"\n")
        buf[:] = rest
        for line in lines:
            writer.write_line(t, name, line.rstrip(b"\r"))
            self.counts[name] += 1
        if len(buf) > MAX_PARTIAL_BYTES:
            writer.write_chunk(t, name, bytes(buf))
            self.counts[name] += 1
            buf.clear()

    def finish(self, writer: CaptureWriter) -> None:
        """Each text port's unterminated line written as a chunk."""
        for name, buf in self.partial.items():
            if buf:
                writer.write_chunk(max(self.clock(), self.last_t), name, bytes(buf))
