"""A fake serial device: one port of a capture served on a virtual serial port.

The bytes a real sensor sent (as recorded in a capture) are written to a
:class:`~drivers.io.vpty.VirtualPort` at ``link`` with the capture's timing, scaled by
``speed`` (``None``: as fast as the reader takes them). Text lines go out with
CR LF, binary chunks verbatim. By default the device waits for a reader to open
the link before it starts, so a test sees every byte; after that it behaves like a
real device and never waits (a reader that goes away loses what is sent meanwhile),
except at ``speed=None`` where it waits for the reader to take each chunk.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

from drivers.io.capture import CaptureReader
from drivers.io.vpty import VirtualPort


class FakeDevice:
    """Serve ``port`` of ``capture`` at ``link``.

    Args:
        capture: capture v1 file.
        port: the port of the capture to serve.
        link: symlink path of the virtual serial port.
        speed: multiple of real time, or None for as fast as possible.
        loop: start again at the end, until stopped.
        wait_for_reader: do not start before a reader has opened the link.
        settle_s: then wait this long before the first byte, so that the reader has
            finished opening: pyserial's open ends by flushing the input queue, and a
            byte written before that flush is lost.
        linger: after the capture ends, stay open (silent, like an idle sensor) until
            :meth:`stop`; closing at once would hang up the reader before it has read
            the last bytes.
        sleep: the sleep function (tests).

    Raises:
        ValueError: the capture has no such port, or a non-positive speed.
        CaptureFormatError: a malformed capture.
        DeviceError: the virtual port cannot be created.
    """

    def __init__(
        self,
        capture: str | Path,
        port: str,
        link: str | Path,
        *,
        speed: float | None = 1.0,
        loop: bool = False,
        wait_for_reader: bool = True,
        settle_s: float = 0.05,
        linger: bool = True,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.reader = CaptureReader(capture)
        if port not in self.reader.ports:
            raise ValueError(f"{capture} has no port {port!r} (has {', '.join(self.reader.ports)})")
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be positive, not {speed}")
        self.port = port
        self.speed = speed
        self.loop = loop
        self.wait_for_reader = wait_for_reader
        self.settle_s = settle_s
        self.linger = linger
        self.finished = threading.Event()
        self.sleep = sleep
        # no backlog limit: like a real serial port, the kernel queues what the reader
        # has not read yet (a slow test reader still gets every byte)
        self.vport = VirtualPort(link, max_backlog=None)
        self.link = Path(link)
        self.sent_records = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

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
                while not self._stop.is_set() and not self.vport.has_reader():
                    self.sleep(0.01)
                self.sleep(self.settle_s)
            while not self._stop.is_set():
                self._serve_once()
                if not self.loop:
                    break
            self.finished.set()
            while self.linger and not self._stop.is_set():
                self.vport.has_reader()  # drains anything the reader writes back
                self.sleep(0.05)
        finally:
            self.finished.set()
            self.vport.close()

    def _serve_once(self) -> None:
        start: tuple[float, float] | None = None
        for rec in self.reader:
            if self._stop.is_set():
                return
            if start is None and self.speed is not None:
                # the capture's clock starts at its first record, whatever its port:
                # the ports of one capture keep their offsets
                start = (rec.t, time.monotonic())
            if rec.port != self.port:
                continue
            data = rec.data
            if self.speed is None:
                while not self._stop.is_set() and data:
                    if not self.vport.wait_writable(0.1):
                        continue
                    n = self.vport.write(data)
                    data = data[n:]
            else:
                t0, m0 = start if start is not None else (rec.t, time.monotonic())
                due = m0 + (rec.t - t0) / self.speed
                while not self._stop.is_set():
                    wait = due - time.monotonic()
                    if wait <= 0:
                        break
                    self.sleep(min(wait, 0.1))
                self.vport.write(data)
            self.sent_records += 1

    def start(self) -> FakeDevice:
        """Run in a background thread (tests)."""
        self._thread = threading.Thread(target=self.run, name=f"fake-{self.port}", daemon=True)
        self._thread.start()
        return self

    def join(self, timeout: float | None = None) -> None:
        """Wait for the background thread (call :meth:`stop` first when lingering)."""
        if self._thread is not None:
            self._thread.join(timeout)
