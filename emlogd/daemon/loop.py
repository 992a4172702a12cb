"""``emlogd run``: the daemon loop around the pipeline.

One process, one loop thread, one epoll loop (beside it only the state file's writer
and a reloaded config's parse): a readable port runs its callback
straight from ``epoll.poll`` (the sockets of the control server and the TCP output
sit in a ``selectors`` selector nested in it). The loop owns the file
descriptors (serial sources, output sinks, control socket, a self-pipe for
signals), the clock, sd_notify and the state file; everything else happens in
:class:`~emlogd.pipeline.core.Pipeline`, the same object ``emlogd replay`` drives.

Signals (:mod:`emlogd.daemon.signals`): SIGTERM/SIGINT persist the good calibrations,
close everything and exit 0; SIGHUP reloads the config (a bad new config is logged and
the old one kept); SIGUSR1/SIGUSR2 are logged and change nothing.
A sensor missing at start is a status, not a crash: its source retries with
backoff and is opened when it appears. Bad input is counted by the decoders; a
failure while the pipeline handles one chunk is contained (:mod:`emlogd.contain`:
counted as an ``internal`` reject of the port, logged at most once per 10 s per port
and exception type) and the loop goes on: no input stops the daemon. The state file is
written beside the loop (:mod:`emlogd.daemon.saver`): a slow disk holds no output; a
``freeze`` or ``reset`` is answered once its save has landed, the other clients served
meanwhile. A state file that cannot be written is reported and the previous file stays
intact.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import select
import selectors
import time
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

from drivers.errors import DeviceError
from drivers.io.port import PortEvent, SerialSource
from emlogd.config import Config, load_config
from emlogd.contain import Containment
from emlogd.daemon import logsetup, signals
from emlogd.daemon.configload import ConfigLoad, why_not_loaded
from emlogd.daemon.control import Deferred
from emlogd.daemon.controls import Controls
from emlogd.daemon.logsetup import EventLimiter, flush_log, is_console, lost_lines, status_line
from emlogd.daemon.notify import Notifier
from emlogd.daemon.outputs import OUTPUT_RETRY_S, Outputs
from emlogd.daemon.saver import Saves
from emlogd.daemon.statefile import StateStore, max_state_bytes
from emlogd.daemon.statusdoc import status_document
from emlogd.pipeline.calibration import checker
from emlogd.pipeline.core import Output, Pipeline
from emlogd.settings import build_pipeline, pipeline_from_config

SELECT_TIMEOUT_S = 0.2
"""Longest wait of the loop: bounds the reaction to stale ports and the watchdog."""

HOUSEKEEPING_S = 0.1
"""Least time between two rounds of reconnects, stale checks, status and watchdog."""

RELOAD_MIN_S = 0.25
"""Least time between two reloads: SIGHUPs sent faster (a script in a loop) are one
reload when it is due, which reads the newest config."""

REST_MERGE_S = 0.02
"""How much later than the end of its rest a resting port may be read: at the loop's first
wake-up after it (a UUT's sentence, another port's burst), so that the read seldom costs a
wake-up of its own; ``rest_s`` plus this must stay under the gap between bursts."""

_ONE_READ = select.EPOLLIN | select.EPOLLONESHOT
"""How a resting port is registered: one readiness, then disarmed until re-armed."""


class Daemon:
    """The running service.

    Args:
        config_path: the YAML config.
        log: a structlog-style logger (``log.info(event, **kw)``).
        state_path: override of the config's state file.
        clock: the wall clock, read once, at start: it anchors the data timeline.
        monotonic: the clock of every schedule (housekeeping, watchdog, status,
            rest, reconnects) and of the data timeline.

    Data are stamped on a timeline that starts at the wall time of the start and
    advances with the monotonic clock (:meth:`timeline`): a wall clock stepped
    back or forward (NTP, GNSS time, an operator) moves no schedule, no staleness
    and no persistence interval. Stamps that leave the process otherwise (the log's
    timestamps, the state file's ``saved_at``) are wall time.
    """

    def __init__(
        self,
        config_path: str | Path,
        log: Any,
        *,
        state_path: str | Path | None = None,
        clock: Callable[[], float] = time.time,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config_path = Path(config_path)
        self.log = log
        self.state_override = Path(state_path) if state_path is not None else None
        self.clock = clock
        self.monotonic = monotonic
        self._epoch = clock() - monotonic()
        self.config: Config = load_config(self.config_path)
        self.poll = select.epoll()
        """What the loop waits on: the ports, the signal pipe and :attr:`sel`; each
        descriptor's callback is in :attr:`calls` (a data wake-up runs one callback, no
        selector layer). Resting ports are registered one-shot: readiness disarms a
        port without a call, and one modify() arms it again after its read."""
        self.calls: dict[int, Callable[[], None]] = {}
        self.sel = selectors.EpollSelector()
        """The sockets (control, TCP output), registered by their servers; in :attr:`poll`."""
        self.sources: dict[str, SerialSource] = {}
        self.registered: dict[str, int] = {}
        self.unselectable: list[str] = []
        self.resting: dict[str, float] = {}
        self.rest_fds: dict[int, str] = {}
        """The resting ports' descriptors (registered one-shot) and their names."""
        self._watch(self.sel.fileno(), self._serve)
        self.event_limiter = EventLimiter()
        self.control_log = logsetup.ControlLog(log, monotonic)
        self.contain = Containment()
        self.rest_s: dict[str, float] = {}
        self.outputs = Outputs(self.sel, log, monotonic)
        self.controls = Controls(
            self.sel, self._control, lambda k, d: self.log.warning(k, detail=d), monotonic
        )
        """The control socket and the read-only status socket."""
        self.store: StateStore | None = None
        self.pipeline: Pipeline | None = None
        self.notifier = Notifier.from_env()
        self.stop = False
        self.reload = False
        self.unused = signals.Unused()
        self.next_reload = -math.inf
        self.loading: ConfigLoad | None = None
        """The reloaded config being parsed beside the loop (None: no reload under way)."""
        self.started = False
        """Everything opened: a stop persists (a start that failed writes nothing)."""
        self.saves: Saves | None = None
        """The state file's saves, in a writer thread (started with the daemon)."""
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)

    @property
    def state_errors(self) -> int:
        """Saves of the state file that failed."""
        return self.saves.state_errors if self.saves is not None else 0

    @property
    def persists(self) -> int:
        """Saves of the state file that landed."""
        return self.saves.persists if self.saves is not None else 0

    def timeline(self) -> float:
        """The data time: the wall time at start plus the monotonic time since, s."""
        return self._epoch + self.monotonic()

    # -- lifecycle -------------------------------------------------------------

    def run(self) -> int:
        """Run until SIGTERM/SIGINT; return the exit code.

        Raises:
            StateLockedError: another instance runs on the same state file (nothing of
                it is touched).
        """
        lock = self._state_store().lock()  # before any output or socket is created
        if lock is None:
            self.log.warning("state_lock_unavailable", path=str(self._state_store().lock_path))
        try:
            return self._run()
        finally:
            if lock is not None:
                os.close(lock)

    def _state_store(self) -> StateStore:
        if self.store is None:
            path = self.state_override or Path(self.config.state_path)
            self.store = StateStore(path, uuts=len(self.config.calibration))
        return self.store

    def _run(self) -> int:
        old = self._install_signals()
        try:
            self._start()
            self.notifier.ready()
            self._notify_status()
            self.log.info("ready", config=str(self.config_path), pid=os.getpid())
            self._loop()
        finally:
            self._shutdown()
            signals.restore(old)
            os.close(self._wake_r)
            os.close(self._wake_w)
        return 0

    def _install_signals(self) -> dict[int, Any]:
        def on_stop(signum: int, frame: FrameType | None) -> None:
            self.stop = True

        def on_hup(signum: int, frame: FrameType | None) -> None:
            self.reload = True

        old = signals.install(on_stop, on_hup, self.unused, self._wake_w)
        self._watch(self._wake_r, functools.partial(signals.drain, self._wake_r))
        return old

    def _start(self) -> None:
        cfg = self.config
        store = self._state_store()
        state_path = store.path
        _, uuts = pipeline_from_config(cfg)
        cals, others, report = store.load_state(check=checker(uuts))
        for line in report:
            self.log.warning("state_file", detail=line, path=str(state_path))
        for uut, cal in cals.items():
            self.log.info(
                "calibration_loaded",
                uut=uut,
                model=cal.params.model,
                reset=cal.reset,
                lag_s=cal.lag_s,
                **cal.params.as_dict(),
            )
        self.pipeline = build_pipeline(cfg, cals, others)
        self.saves = Saves(store, self.log, self.monotonic)
        self._watch(self.saves.wake_fd, self.saves.landed)
        # the control socket first: it refuses to replace another live instance's
        self._sync_controls()
        try:  # one that cannot be opened costs itself, tried again (Outputs.housekeep)
            self.outputs.sync(cfg)
        except DeviceError as exc:
            self.log.error("outputs_failed", error=str(exc), retry_s=OUTPUT_RETRY_S)
        self._open_sources(cfg)
        self.started = True

    def _open_sources(self, cfg: Config) -> None:
        """Open the ports of ``cfg`` that have no source yet."""
        for p in cfg.ports:
            if p.name in self.sources:
                continue
            src = SerialSource(
                p.name,
                p.url,
                baudrate=p.baud,
                stale_timeout_s=math.inf,  # staleness is the pipeline's (its events)
                clock=self.timeline,
                monotonic=self.monotonic,
            )
            src.open()
            self.sources[p.name] = src
            self.rest_s[p.name] = p.rest_s
            self._log_port_events(src.events())
        self._sync_registrations()

    def _close_source(self, name: str) -> None:
        self._unregister(name)
        self.sources.pop(name).close()
        self.resting.pop(name, None)
        self.rest_s.pop(name, None)

    def _close_sources(self) -> None:
        for name in list(self.sources):
            self._close_source(name)

    def _sync_controls(self) -> None:
        """Open the control and status sockets the config names (:class:`Controls`).

        Raises:
            DeviceError: a socket cannot be created (the others are still synced).
        """
        cfg = self.config
        self.controls.sync(cfg.control_socket, cfg.status_socket, started=self.started)

    def _shutdown(self) -> None:
        self.notifier.stopping()
        if self.started:
            self._persist(final=True)
        self._finish_saves()
        self._close_sources()
        self.controls.close()
        self.outputs.close()
        self.sel.close()
        self.poll.close()
        self.log.info("stopped", persists=self.persists, state_errors=self.state_errors)

    # -- the loop ---------------------------------------------------------------

    def _loop(self) -> None:
        cfg = self.config
        next_status = self.monotonic() + cfg.status_log_interval_s
        wd = self.notifier.watchdog_interval_s
        next_watchdog = self.monotonic() + wd if wd else None
        next_housekeeping = -math.inf
        while not self.stop:
            self._round(self._wait_s())
            now = self.monotonic()
            for name in self.unselectable:
                self._read(name)  # a source without a file descriptor (loop://)
            if self.reload and now >= self.next_reload and self.loading is None:
                self.reload, self.next_reload = False, now + RELOAD_MIN_S
                self.loading = ConfigLoad(self.config_path)
            if self.loading is not None and self.loading.done.is_set():
                loaded, self.loading = self.loading.result, None
                self._reload(loaded)
            if now < next_housekeeping:
                continue  # data wake-ups do no more than read, decode and emit
            next_housekeeping = now + HOUSEKEEPING_S
            self._housekeep()
            if now >= next_status:
                next_status = now + self.config.status_log_interval_s
                self._status_event()
            if next_watchdog is not None and now >= next_watchdog:
                self.notifier.watchdog()
                next_watchdog = now + (wd or 1.0)

    def _housekeep(self) -> None:
        """Every :data:`HOUSEKEEPING_S`: the ports' events (a port opened or lost selected
        again on its new descriptor), the control servers' and outputs' upkeep, the
        pipeline's tick."""
        changed = False  # a port opened or lost: its descriptor changed
        for src in self.sources.values():
            events = src.poll()
            if events:
                changed = True
                self._log_port_events(events)
        if changed:
            self._sync_registrations()
        self.controls.housekeep()
        self.outputs.housekeep()
        if self.saves is not None and self.monotonic() >= self.saves.retry_at:
            self._persist()
        self.unused.log(self.log, self.monotonic())
        flush_log(0.0)  # log lines a slow reader left behind
        self._tick()

    def _watch(self, fd: int, call: Callable[[], None]) -> None:
        """Wait for ``fd`` to be readable in the loop, then call ``call``."""
        self.poll.register(fd, select.EPOLLIN)
        self.calls[fd] = call

    def _wait_s(self) -> float:
        """The loop's wait: until a resting port is due at the latest (the end of its rest
        plus :data:`REST_MERGE_S`), at most :data:`SELECT_TIMEOUT_S`."""
        if not self.resting:
            return SELECT_TIMEOUT_S
        late = min(self.resting.values()) + REST_MERGE_S - self.monotonic()
        return min(SELECT_TIMEOUT_S, max(late, 0.0))

    def _round(self, timeout: float) -> None:
        """Wait up to ``timeout`` s; read the resting ports whose rest is over, then run the
        callback of each descriptor that is readable (a rested burst came first, and the
        pipeline gets the data in the order of their stamps)."""
        ready = self.poll.poll(timeout)
        if self.resting:
            self._wake_rested(self.monotonic())
        for fd, _ in ready:
            call = self.calls.get(fd)
            if call is not None:
                call()
            if self.stop:
                break

    def _serve(self) -> None:
        """The sockets that are readable: control requests, TCP output clients."""
        for key, _ in self.sel.select(0):
            key.data()

    def _sync_registrations(self) -> None:
        for name in self.sources:
            if name not in self.resting:
                self._register(name)
        self.unselectable = [
            name
            for name, src in self.sources.items()
            if src.is_open and name not in self.registered and name not in self.resting
        ]

    def _register(self, name: str) -> None:
        """Select a port on its current descriptor (re-registered if it changed)."""
        fd = self.sources[name].fileno()
        if self.registered.get(name) == fd:
            return
        self._unregister(name)
        if fd is None:
            return
        assert self.pipeline is not None
        if self.rest_s.get(name, 0.0) > 0.0 and name not in self.pipeline.uuts:
            self.poll.register(fd, _ONE_READ)
            self.calls[fd] = functools.partial(self._rest, name)
            self.rest_fds[fd] = name
        else:
            self._watch(fd, functools.partial(self._read, name))
        self.registered[name] = fd

    def _unregister(self, name: str) -> None:
        fd = self.registered.pop(name, None)
        if fd is None:
            return
        self.rest_fds.pop(fd, None)
        if self.calls.pop(fd, None) is not None:
            with contextlib.suppress(OSError, ValueError):
                self.poll.unregister(fd)  # gone already if the descriptor was closed

    def _rest(self, name: str) -> None:
        """A reference or aux port became readable: read it ``rest_s`` later (at the latest
        :data:`REST_MERGE_S` after that), stamped with the end of its rest. Until then its
        one-shot registration stays disarmed: a burst (the DVL's six lines per ensemble, 3 ms
        apart) is one read, not a wake-up per line. UUT ports never rest: their latency is
        the output's. ``rest_s: 0`` turns resting off."""
        self.resting[name] = self.monotonic() + self.rest_s[name]

    def _read(self, name: str, stamp: float | None = None) -> None:
        """Read one port and feed the pipeline (the data stamped ``stamp``, else when read)."""
        src = self.sources[name]
        chunk = src.read()
        if src.has_events:
            self._log_port_events(src.events())
        if chunk is None:
            self._sync_registrations()
            return
        t, data = chunk
        self._feed(t if stamp is None else stamp, name, data)

    def _feed(self, t: float, name: str, data: bytes) -> None:
        """Run the pipeline on one chunk of ``name``; a failure costs that chunk only."""
        assert self.pipeline is not None
        data = self.outputs.echo.read(name, data)  # less the daemon's own output read back
        if not data:  # all of it was (or a line not ended yet, held until it is)
            return
        try:
            out = self.pipeline.feed(t, name, data)
        except Exception as exc:  # contained: no input stops the daemon
            self._contained(name, data, exc)
            return
        self._handle(out)

    def _tick(self) -> None:
        """Advance the pipeline without data; a failure is contained like a chunk's."""
        assert self.pipeline is not None
        try:
            out = self.pipeline.tick(self.timeline())
        except Exception as exc:
            self._contained("", b"", exc)
            return
        self._handle(out)

    def _contained(self, name: str, data: bytes, exc: Exception) -> None:
        failure = self.contain.failed(self.pipeline, name, data, exc, self.monotonic())
        if failure is not None:
            extra = {"suppressed": failure.suppressed} if failure.suppressed else {}
            self.log.warning("internal", port=name, error=failure.error, data=failure.data, **extra)

    def _wake_rested(self, now: float) -> None:
        """Read the ports whose rest is over at ``now`` (monotonic), each stamped with the
        end of its rest, and arm them again."""
        due = [(name, t) for name, t in self.resting.items() if now >= t]
        for name, t in due:
            del self.resting[name]
            if name in self.sources:
                self._read(name, self._epoch + t)
                fd = self.registered.get(name)
                if fd is not None and fd in self.rest_fds:
                    with contextlib.suppress(OSError):
                        self.poll.modify(fd, _ONE_READ)

    def _handle(self, out: Output) -> None:
        """Deliver what a pipeline call returned: its sentences to the outputs, its
        events to the log, and a persist when it asks for one."""
        if out.emits:
            self.outputs.deliver(out.emits)
        for ev in out.events:
            suppressed = self.event_limiter.allow(ev.port, ev.kind, self.monotonic())
            if suppressed is not None:
                extra = {"suppressed": suppressed} if suppressed else {}
                level = self.log.warning if ev.kind == "stale" else self.log.info
                level(ev.kind, port=ev.port, **dict(ev.detail), **extra)
        if out.persist:
            self._persist()

    def _persist(self, *, final: bool = False, operator: bool = False) -> int | None:
        """Hand the calibrations to the writer thread (:meth:`Saves.persist`): the number
        of the save that will hold them, or None when the file holds them already."""
        assert self.pipeline is not None and self.saves is not None
        snaps = self.pipeline.calibrations()
        others = self.pipeline.other_calibrations() if snaps else []
        return self.saves.persist(snaps, others, final=final, operator=operator)

    def _finish_saves(self) -> None:
        """At the stop: the saves waited for (:meth:`Saves.finish`), the thread ended."""
        if self.saves is None:
            return
        with contextlib.suppress(OSError, ValueError, KeyError):
            self.poll.unregister(self.saves.wake_fd)
        self.calls.pop(self.saves.wake_fd, None)
        self.saves.finish()

    def _log_port_events(self, events: list[PortEvent]) -> None:
        for ev in events:
            warn = ev.kind in ("disconnected", "stale", "error", "modes_restored")
            (self.log.warning if warn else self.log.info)(
                f"port_{ev.kind}", port=ev.port, detail=ev.detail
            )

    def _status_event(self) -> None:
        assert self.pipeline is not None
        status = self.pipeline.status()
        if is_console():
            # a person reads a terminal: one line, the full figures are in `emlogd status`
            self.log.info("status", **status_line(status), state_errors=self.state_errors)
            return
        # a port's staleness is the pipeline's (``ports``): the daemon's sources run none
        sources = {name: src.counters_dict(stale=False) for name, src in self.sources.items()}
        sinks = self.outputs.status()
        sections = {"ports": status["ports"], "uuts": status["uuts"]}
        sections.update(sources=sources, sinks=sinks)
        self.log.info(
            "status", **logsetup.capped_sections(sections), state_errors=self.state_errors
        )
        self._notify_status()

    def _status(self, uut: str | None) -> dict[str, object]:
        assert self.pipeline is not None
        return status_document(self.pipeline, self.sources, uut, self.outputs.echo.echoes)

    def _notify_status(self) -> None:
        if self.pipeline is not None:
            self.notifier.status(self.pipeline.summary()[:200])

    # -- control and reload -------------------------------------------------------

    def _control(self, req: dict[str, object]) -> dict[str, object] | Deferred:
        assert self.pipeline is not None and self.saves is not None
        cmd = req["cmd"]
        port = req.get("port")
        if port is not None and port not in self.pipeline.uuts:
            raise ValueError(f"no UUT {port!r}; UUTs: {', '.join(self.pipeline.uuts)}")
        p = port if isinstance(port, str) else None
        if cmd == "status":
            return {
                "status": self._status(p),
                "outputs": self.outputs.status(),
                "state_file": str(self.store.path) if self.store else None,
                "state_errors": self.state_errors,
                "persists": self.persists,
                "log_lines_lost": lost_lines(),
            }
        if cmd == "freeze":
            done = self.pipeline.set_learning(False, p)
            states = {n: self.pipeline.uuts[n].cal.state for n in done}

            def frozen(err: str | None) -> dict[str, object]:
                self.control_log.info("control_freeze", uuts=done, persisted=err is None)
                if err is not None:
                    raise ValueError(
                        f"learning stopped for {', '.join(done)}, but the calibration "
                        f"was not saved: {err}"
                    )
                return {"uuts": done, "learning": False, "persisted": True, "states": states}

            return self.saves.after(self._persist(operator=True), frozen)
        if cmd == "learn":
            on = req.get("on", True)
            if not isinstance(on, bool):
                raise ValueError('learn needs "on": true or false')
            done = self.pipeline.set_learning(on, p)
            self.control_log.info("control_learn", uuts=done, on=on)
            return {"uuts": done, "learning": on}
        if cmd == "reset":
            reset = self.pipeline.reset(p)

            def cleared(err: str | None) -> dict[str, object]:
                self.control_log.warning("control_reset", uuts=reset, persisted=err is None)
                if err is not None:
                    raise ValueError(
                        f"{', '.join(reset)} reset, but the state file was not written "
                        f"({err}): the old calibration would load after a restart"
                    )
                return {"uuts": list(reset), "reset": reset, "persisted": True}

            return self.saves.after(self._persist(operator=True), cleared)
        raise ValueError(f"unknown cmd {cmd!r}")

    def _sync_outputs(self, cfg: Config) -> tuple[list[str], list[str], DeviceError | None]:
        """:meth:`Outputs.sync`: the outputs closed and opened, and the first that failed."""
        try:
            closed, opened = self.outputs.sync(cfg)
        except DeviceError as exc:
            return [], [], exc
        return closed, opened, None

    def _reload(self, loaded: Config | Exception | None = None) -> None:
        """Apply a new config, touching only what changed (docs/DEPLOY.md, "Reload").

        A port, an output or the control socket whose settings are equal is kept as
        it is (same descriptor, same pty, same clients); a UUT whose settings are equal
        keeps its calibration object (:meth:`Pipeline.adopt`). A config that does not
        load, or whose pipeline cannot be built, changes nothing. ``loaded``: the config
        as :class:`ConfigLoad` loaded it, or its failure; None: load it now.
        """
        if loaded is None:
            try:
                loaded = load_config(self.config_path)
            except Exception as exc:  # contained: no config file stops the daemon
                loaded = exc
        if isinstance(loaded, Exception):
            self.log.error("reload_failed", error=why_not_loaded(loaded), kept="previous config")
            return
        new = loaded
        old_pipeline, old = self.pipeline, self.config
        assert old_pipeline is not None
        self._persist()
        snapshots = {s.uut: s for s in old_pipeline.calibrations()}
        try:
            pipeline = build_pipeline(new, snapshots, old_pipeline.other_calibrations())
        except Exception as exc:  # contained, as above
            self.log.error("reload_failed", error=why_not_loaded(exc), kept="previous config")
            return
        kept_uuts = pipeline.adopt(old_pipeline)
        self.config, self.pipeline = new, pipeline
        if self.store is not None:  # a save of the new UUTs must load at the next start
            self.store.max_bytes = max_state_bytes(len(new.calibration))
        before = {p.name: p for p in old.ports}
        after = {p.name: p for p in new.ports}
        changed_ports = [n for n in self.sources if before.get(n) != after.get(n)]
        for name in changed_ports:
            self._close_source(name)
        self._open_sources(new)
        logsetup.follow_config(new.log_format, new.log_level, new.outputs.stdout)
        closed, opened, failed = self._sync_outputs(new)
        try:
            self._sync_controls()
        except DeviceError as exc:
            self.log.error("reload_control_failed", error=str(exc))
        if failed is not None:  # once more: a path the old control socket held is free now
            _, more, failed = self._sync_outputs(new)
            opened += more
        if failed is not None:
            self.log.error("reload_outputs_failed", error=str(failed))
        state_path = Path(new.state_path)
        if self.state_override is None and self.store is not None and state_path != self.store.path:
            self.log.warning(
                "reload_state_file_ignored", path=str(state_path), kept=str(self.store.path)
            )
        self.log.info(
            "reloaded",
            config=str(self.config_path),
            uuts_kept=kept_uuts,
            uuts_restarted=[u for u in pipeline.uuts if u not in kept_uuts],
            ports_reopened=[n for n in changed_ports if n in after],
            ports_closed=[n for n in changed_ports if n not in after],
            outputs_closed=closed,
            outputs_opened=opened,
        )
        self._notify_status()
