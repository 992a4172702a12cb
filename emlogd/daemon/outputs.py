"""The daemon's outputs: the sinks the config names, and where each sentence goes.

A reload keeps an output whose settings are equal as it is (same pty, same clients):
outputs are keyed by what only a new one changes (a pty's path, a TCP output's address,
a UDP destination), and a pty's mode and group and a TCP output's limits are set on the
open one (:meth:`Outputs.sync`). A log given outputs of its own
(``calibration[].outputs``) writes its sentences there only; every other sentence goes
to the shared outputs. An output that cannot be opened (a file at the pty's path) costs
itself: the others open, and it is tried again every :data:`OUTPUT_RETRY_S`, its
reason in the status meanwhile.
"""

from __future__ import annotations

import contextlib
import functools
import selectors
from collections.abc import Callable
from typing import Any

from drivers.errors import DeviceError
from emlogd.config import Config
from emlogd.daemon.echo import EchoFilter
from emlogd.daemon.logsetup import CLIENT_EVENT_BURST, CLIENT_EVENTS, EventLimiter
from emlogd.daemon.sinks import PtySink, Sink, TcpLimits, TcpServerSink, stdout_sink
from emlogd.daemon.udpsink import UdpSink
from emlogd.pipeline.core import Emit

OUTPUT_RETRY_S = 2.0
"""How often an output that could not be opened is tried again, s."""


class Outputs:
    """The open outputs of the daemon.

    Args:
        selector: where a TCP output registers its listening and client sockets.
        log: a structlog-style logger (``log.info(event, **kw)``).
        monotonic: the clock of the sinks' schedules (stalls, error lines).
    """

    def __init__(
        self, selector: selectors.BaseSelector, log: Any, monotonic: Callable[[], float]
    ) -> None:
        self.sel = selector
        self.log = log
        self.monotonic = monotonic
        self.sinks: dict[tuple[object, ...], Sink] = {}
        """The open outputs, keyed as :meth:`specs` keys them."""
        self.failed: dict[tuple[object, ...], tuple[Callable[[], Sink], str]] = {}
        """The outputs that could not be opened: how to open each, and why it failed."""
        self.next_retry = 0.0
        """When those are tried again (monotonic s)."""
        self.access: tuple[int, str | None] | None = None
        """The ptys' mode and group as last set (None: none set yet)."""
        self.routes: dict[str, list[Sink]] = {}
        """The logs with outputs of their own, and those outputs."""
        self.shared: list[Sink] = []
        """The outputs of every other sentence."""
        self.client_events = EventLimiter(kinds=CLIENT_EVENTS, burst=CLIENT_EVENT_BURST)
        """The TCP outputs' lines about their clients, limited per output and event."""
        self.echo = EchoFilter(
            monotonic, lambda port: log.warning("output_read_back", port=port, skipped="echoes")
        )
        """What comes back of the sentences written (an input wired to the outputs)."""

    def _client_event(self, address: str, kind: str, peer: str) -> None:
        """A TCP output's event about one client: logged within :data:`CLIENT_EVENT_BURST`
        lines per output and event per interval (the next line says how many were left out;
        the output's counters count every client)."""
        suppressed = self.client_events.allow(address, kind, self.monotonic())
        if suppressed is not None:
            extra = {"suppressed": suppressed} if suppressed else {}
            self.log.info(kind, sink="tcp", peer=peer, **extra)

    def _pty_event(self, kind: str, detail: str) -> None:
        """A pty output's event about its link (rare: at most one per link check)."""
        self.log.warning(kind, sink="pty", detail=detail)

    def specs(self, cfg: Config) -> dict[tuple[object, ...], Callable[[], Sink]]:
        """The outputs ``cfg`` asks for: how to open each, keyed by what only a new one
        changes (a pty's path, a TCP output's address: not its mode, group or limits,
        which :meth:`_tune` gives an open one in place)."""
        out = cfg.outputs
        specs: dict[tuple[object, ...], Callable[[], Sink]] = {}
        if out.pty:
            pty, mode, group = out.pty, out.pty_mode, out.pty_group
            specs[("pty", pty)] = lambda: PtySink(
                pty, mode=mode, group=group, on_event=self._pty_event, monotonic=self.monotonic
            )
        limits = TcpLimits(out.tcp_max_clients, out.tcp_max_pending_bytes, out.tcp_stall_s)
        if out.tcp:
            tcp = out.tcp
            specs[("tcp", tcp)] = lambda: TcpServerSink(
                tcp,
                selector=self.sel,
                on_event=functools.partial(self._client_event, tcp),
                monotonic=self.monotonic,
                limits=limits,
            )
        if out.udp:
            udp = out.udp
            specs[("udp", udp)] = lambda: UdpSink(
                udp,
                on_event=lambda kind, detail: self.log.warning(kind, sink="udp", detail=detail),
                monotonic=self.monotonic,
            )
        if out.stdout:
            specs[("stdout",)] = stdout_sink
        for c in cfg.calibration:  # a log's own outputs, keyed ("uut", name, ...)
            name, u = c.uut, c.outputs
            if u.pty:
                specs[("uut", name, "pty", u.pty)] = functools.partial(
                    PtySink,
                    u.pty,
                    mode=out.pty_mode,
                    group=out.pty_group,
                    on_event=self._pty_event,
                    monotonic=self.monotonic,
                )
            if u.tcp:
                specs[("uut", name, "tcp", u.tcp)] = functools.partial(
                    TcpServerSink,
                    u.tcp,
                    selector=self.sel,
                    on_event=functools.partial(self._client_event, u.tcp),
                    monotonic=self.monotonic,
                    limits=limits,
                )
            if u.udp:
                specs[("uut", name, "udp", u.udp)] = functools.partial(
                    UdpSink,
                    u.udp,
                    on_event=lambda kind, detail: self.log.warning(kind, sink="udp", detail=detail),
                    monotonic=self.monotonic,
                )
        return specs

    def sync(self, cfg: Config) -> tuple[list[str], list[str]]:
        """Close the outputs ``cfg`` no longer names, open the new ones; keep the rest.

        Returns the names of the outputs (closed, opened). An output that cannot be
        opened costs itself: the others are opened and routed all the same (one that
        failed made every output after it in the config stay closed), then the first
        failure is raised.

        Raises:
            DeviceError: an output could not be opened (the rest are in place).
        """
        self.echo.configure(cfg)
        specs = self.specs(cfg)
        closed = [self.sinks[key].name for key in self.sinks if key not in specs]
        for key in [k for k in self.sinks if k not in specs]:
            with contextlib.suppress(OSError):
                self.sinks.pop(key).close()
        self.failed = {k: v for k, v in self.failed.items() if k in specs}
        tuning = self._tune(cfg)
        opened, failed = self._open({k: m for k, m in specs.items() if k not in self.sinks})
        failed = failed or tuning
        if failed is not None:
            raise failed
        return closed, opened

    def _tune(self, cfg: Config) -> DeviceError | None:
        """Give the open outputs the settings a reload may change in place: the ptys'
        mode and group (a reader reads on), the TCP outputs' limits (the clients stay).
        A pty was closed and another published for a new mode or group, the readers of
        the old one hung up, and a TCP output rebound for new limits, every client
        dropped. Returns the first failure (an unknown group), the rest tuned."""
        out = cfg.outputs
        limits = TcpLimits(out.tcp_max_clients, out.tcp_max_pending_bytes, out.tcp_stall_s)
        access = (out.pty_mode, out.pty_group)
        failed: DeviceError | None = None
        for sink in self.sinks.values():
            if isinstance(sink, TcpServerSink):
                sink.limits = limits
            elif isinstance(sink, PtySink) and access != self.access:
                try:
                    sink.port.set_access(*access)
                except DeviceError as exc:
                    failed = failed or exc
        if failed is None:  # else set again at the next sync
            self.access = access
        return failed

    def _open(
        self, specs: dict[tuple[object, ...], Callable[[], Sink]]
    ) -> tuple[list[str], DeviceError | None]:
        """Open ``specs`` (each failure kept in :attr:`failed`, the others opened all the
        same) and route the open outputs; the names opened, and the first failure."""
        opened: list[str] = []
        failed: DeviceError | None = None
        for key, make in specs.items():
            try:
                self.sinks[key] = sink = make()
            except (DeviceError, OSError) as exc:
                error = exc if isinstance(exc, DeviceError) else DeviceError(f"{key}: {exc}")
                self.failed[key] = (make, str(error))
                failed = failed or error
                continue
            self.failed.pop(key, None)
            opened.append(sink.name)
        # a log given outputs of its own writes to those that are open, never to the
        # shared ones: its own not open, the shared output's reader got a second log's
        # sentences between its own log's (two speeds on one line)
        self.routes = {str(k[1]): [] for k in [*self.sinks, *self.failed] if k[0] == "uut"}
        for key, sink in self.sinks.items():
            if key[0] == "uut":
                self.routes[str(key[1])].append(sink)
        self.shared = [s for k, s in self.sinks.items() if k[0] != "uut"]
        self.next_retry = self.monotonic() + OUTPUT_RETRY_S
        return opened, failed

    def close(self) -> None:
        """Close every output."""
        for sink in self.sinks.values():
            with contextlib.suppress(OSError):
                sink.close()
        self.sinks.clear()
        self.failed.clear()

    def housekeep(self) -> None:
        """Each output's periodic work: retries, and a TCP output's checks of its clients;
        the outputs that could not be opened tried again when due."""
        for sink in self.sinks.values():
            sink.housekeep()
        if self.failed and self.monotonic() >= self.next_retry:
            opened, _ = self._open({k: make for k, (make, _) in self.failed.items()})
            for name in opened:
                self.log.info("output_opened", output=name)

    def deliver(self, emits: list[Emit]) -> None:
        """Write sentences to their outputs: a log with outputs of its own writes to those
        that are open (none open: nowhere), every other sentence to the shared ones."""
        data = b"".join(e.sentence.encode("ascii") + b"\r\n" for e in emits)
        self.echo.wrote(data)
        if not self.routes:
            for sink in self.shared:
                sink.write(data)
            return
        shared: list[bytes] = []
        for e in emits:
            line = e.sentence.encode("ascii") + b"\r\n"
            own = self.routes.get(e.port)
            if own is None:
                shared.append(line)
            else:
                for sink in own:
                    sink.write(line)
        if shared:
            data = b"".join(shared)
            for sink in self.shared:
                sink.write(data)

    def status(self) -> dict[str, dict[str, object]]:
        """Per output: its counters and ``state`` (``open``, or why not); an output that
        could not be opened, named by its key, ``state`` why."""
        doc = {s.name: {**s.counters.as_dict(), "state": s.state} for s in self.sinks.values()}
        for key, (_, why) in self.failed.items():
            kind, dest = (key[2], key[3]) if key[0] == "uut" else (key[0], key[1])
            doc[f"{kind}:{dest}"] = {"state": f"not open: {why}"}
        return doc
