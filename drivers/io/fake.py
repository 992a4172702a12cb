"""Fake serial devices: the ports of a capture served on virtual serial ports.

The bytes real sensors sent (as recorded in a capture) are written to
:class:`~drivers.io.vpty.VirtualPort` s with the capture's timing, scaled by ``speed``
(``None``: as fast as the readers take them). Text lines go out with CR LF, binary
chunks verbatim.

:class:`FakeCapture` serves several ports of one capture from one pass over it, on
one clock: the capture's first record (whatever its port) is time zero, so the ports
keep the offsets they had when they were recorded, and ``loop`` replays the whole
capture again on the same clock, the next pass starting one mean record interval
after the last record. :class:`FakeDevice` is the one-port case.

By default serving waits until every link has a reader, so a test sees every byte;
after that a device behaves like a real one and never waits (a reader that goes away
loses what is sent meanwhile), except at ``speed=None`` where each chunk waits for
its reader to take it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TypedDict, Unpack

from drivers.io.capture import CaptureReader
from drivers.io.vpty import VirtualPort


class ServeOptions(TypedDict, total=False):
    """How a fake device serves, by keyword (:class:`FakeCapture`'s arguments after
    ``links``, which give the defaults)."""

    speed: float | None
    loop: bool
    wait_for_reader: bool
    settle_s: float
    linger: bool
    sleep: Callable[[float], None]
    on_end: Callable[[], None] | None


class FakeCapture:
    """Serve the ports of ``capture`` named in ``links``, each at its link, on one clock.

    Args:
        capture: capture v1 file.
        links: port of the capture -> symlink path of its virtual serial port.
        speed: multiple of real time, or None for as fast as possible.
        loop: start the whole capture again at its end, until stopped.
        wait_for_reader: do not start before every link has a reader.
        settle_s: then wait this long before the first byte, so that the readers have
            finished opening: pyserial's open ends by flushing the input queue, and a
            byte written before that flush is lost.
        linger: after the capture ends, stay open (silent, like idle sensors) until
            :meth:`stop`; closing at once would hang up the readers before they have
            read the last bytes.
        sleep: the sleep function (tests).
        on_end: called once when the capture has been served to its end (not with
            ``loop``, nor when stopped before), before lingering: the caller can say so.

    Raises:
        ValueError: no ports, a port the capture lacks, or a non-positive speed.
        CaptureFormatError: a malformed capture.
        DeviceError: a virtual port cannot be created.
    """

    def __init__(
        self,
        capture: str | Path,
        links: Mapping[str, str | Path],
        *,
        speed: float | None = 1.0,
        loop: bool = False,
        wait_for_reader: bool = True,
        settle_s: float = 0.05,
        linger: bool = True,
        sleep: Callable[[float], None] = time.sleep,
        on_end: Callable[[], None] | None = None,
    ) -> None:
        self.reader = CaptureReader(capture)
        self.on_end = on_end
        if not links:
            raise ValueError("no port to serve")
        for port in links:
            if port not in self.reader.ports:
                raise ValueError(
                    f"{capture} has no port {port!r} (has {', '.join(self.reader.ports)})"
                )
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be positive, not {speed}")
        self.speed = speed
        self.loop = loop
        self.wait_for_reader = wait_for_reader
        self.settle_s = settle_s
        self.linger = linger
        self.finished = threading.Event()
        self.sleep = sleep
        self.links = {port: Path(link) for port, link in links.items()}
        self.vports: dict[str, VirtualPort] = {}
        try:
            for port, link in self.links.items():
                # no backlog limit: like a real serial port, the kernel queues what the
                # reader has not read yet (a slow test reader still gets every byte)
                self.vports[port] = VirtualPort(link, max_backlog=None)
        except BaseException:
            for vp in self.vports.values():
                vp.close()
            raise
        self.sent = dict.fromkeys(self.links, 0)
        self.passes = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def sent_records(self) -> int:
        """Records written so far, all ports together."""
        return sum(self.sent.values())

    def stop(self) -> None:
        """Ask :meth:`run` to return (thread- and signal-safe)."""
        self._stop.set()

    @property
    def stopped(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._stop.is_set()

    def run(self) -> None:
        """Serve until the capture ends (or forever with ``loop``) or :meth:`stop`."""
        try:
            if self.wait_for_reader:
                while not self._stop.is_set() and not all(
                    vp.has_reader() for vp in self.vports.values()
                ):
                    self.sleep(0.01)
                self.sleep(self.settle_s)
            clock: tuple[float, float] | None = None  # (capture time, monotonic) of time zero
            offset = 0.0  # capture time added by the passes already served
            while not self._stop.is_set():
                clock, span, n = self._serve_once(clock, offset)
                self.passes += 1
                if not self.loop or n == 0:
                    break
                offset += span + (span / (n - 1) if n > 1 else 1.0)
            self.finished.set()
            if self.on_end is not None and not self._stop.is_set():
                self.on_end()
            while self.linger and not self._stop.is_set():
                for vp in self.vports.values():
                    vp.has_reader()  # drains anything the reader writes back
                self.sleep(0.05)
        finally:
            self.finished.set()
            for vp in self.vports.values():
                vp.close()

    def _serve_once(
        self, clock: tuple[float, float] | None, offset: float
    ) -> tuple[tuple[float, float] | None, float, int]:
        """One pass over the capture; returns the clock, the pass's span and its records."""
        first: float | None = None
        last = 0.0
        n = 0
        for rec in self.reader:
            if self._stop.is_set():
                break
            if first is None:
                first = rec.t
            last = rec.t
            n += 1
            if clock is None and self.speed is not None:
                # the capture's clock starts at its first record, whatever its port:
                # the ports of one capture keep their offsets
                clock = (rec.t, time.monotonic())
            vport = self.vports.get(rec.port)
            if vport is None:
                continue
            data = rec.data
            if self.speed is None or clock is None:
                while not self._stop.is_set() and data:
                    if not vport.wait_writable(0.1):
                        continue
                    written = vport.write(data)
                    data = data[written:]
            else:
                t0, m0 = clock
                due = m0 + (offset + rec.t - t0) / self.speed
                while not self._stop.is_set():
                    wait = due - time.monotonic()
                    if wait <= 0:
                        break
                    self.sleep(min(wait, 0.1))
                vport.write(data)
            self.sent[rec.port] += 1
        return clock, (last - first if first is not None else 0.0), n

    def start(self) -> FakeCapture:
        """Run in a background thread (tests)."""
        self._thread = threading.Thread(
            target=self.run, name=f"fake-{'+'.join(self.links)}", daemon=True
        )
        self._thread.start()
        return self

    def join(self, timeout: float | None = None) -> None:
        """Wait for the background thread (call :meth:`stop` first when lingering)."""
        if self._thread is not None:
            self._thread.join(timeout)


class FakeDevice(FakeCapture):
    """Serve one ``port`` of ``capture`` at ``link`` (:class:`FakeCapture` with one port).

    Two FakeDevices of one capture each have their own clock, started when their own
    reader appears: serve the ports of one capture with one :class:`FakeCapture` to
    keep their offsets.
    """

    def __init__(
        self, capture: str | Path, port: str, link: str | Path, **options: Unpack[ServeOptions]
    ) -> None:
        super().__init__(capture, {port: link}, **options)
        self.port = port
        self.link = Path(link)
        self.vport = self.vports[port]

    def start(self) -> FakeDevice:
        """Run in a background thread (tests)."""
        super().start()
        return self
