"""The daemon's signals: which it handles and how.

SIGTERM and SIGINT stop the daemon (the good calibrations persisted), SIGHUP reloads
its config; the handlers only set flags, and every handled signal wakes the loop
through a self-pipe (``signal.set_wakeup_fd``). The other signals whose default action
ends a process and that no fault of the daemon's own raises (:data:`UNUSED_SIGNALS`)
mean nothing to it: one sent to it by mistake (a logrotate ``postrotate`` script's
``kill -USR1`` meant for another service, a ``systemctl kill`` of the wrong unit, a
UPS monitor's SIGPWR, a shell's ``kill -ALRM``) is counted and logged (:class:`Unused`)
and the daemon runs on:

- SIGUSR1, SIGUSR2: no use is made of them.
- SIGALRM, SIGVTALRM, SIGPROF: the daemon sets no timer (``alarm``, ``setitimer``), so
  one is from outside.
- SIGPWR: a power failure reported (by a UPS monitor, to init); a service is stopped
  with SIGTERM when the machine shuts down, and the calibrations are persisted as they
  change, so there is nothing to do at once.
- SIGXCPU: the soft CPU-time limit (``RLIMIT_CPU``) passed; the kernel sends it every
  second until the hard limit, then SIGKILL. Logged (the operators see the limit
  coming), the daemon serving until then.
- SIGIO (SIGPOLL), SIGSTKFLT and the real-time signals SIGRTMIN…SIGRTMAX: no
  descriptor is in ``O_ASYNC`` mode, no real-time signal is used.

Until the handlers are installed (:func:`install`, once the config is loaded and the
daemon built: a second or more after the process starts), SIGHUP and the unused signals
are held (:func:`hold_early`, the first thing ``emlogd run`` does): counted, and passed
on by :func:`install` (a SIGHUP then is one reload, which reads the config anew). Their
default action ended the starting daemon: a ``kill -HUP`` (a config tool's, a
``postrotate`` script's) in its first second was a restart under systemd.

SIGTTOU and SIGTTIN are ignored (:func:`ignore_terminal_stops`, before anything is
logged): a daemon started in the background of a terminal that has ``stty tostop`` set,
its log on that terminal, was stopped by SIGTTOU at its first log line, every output
and socket with it, until someone sent SIGCONT. Ignored, the write goes through. SIGTSTP
(Ctrl-Z at the terminal the daemon runs in the foreground of) is the operator's and
keeps its default action.

SIGPIPE and SIGXFSZ are ignored by the interpreter (a write to a peer that went away is
an ``EPIPE`` error, a write past ``RLIMIT_FSIZE`` an ``EFBIG`` one, both handled where
they happen). The signals of the daemon's own faults (SIGSEGV, SIGBUS, SIGFPE, SIGILL,
SIGABRT, SIGTRAP, SIGSYS) and SIGQUIT (a core dump asked for) keep their default action.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
from collections import Counter
from collections.abc import Callable
from types import FrameType
from typing import Any

Handler = Callable[[int, FrameType | None], None]

UNUSED_SIGNALS: tuple[int, ...] = (
    signal.SIGUSR1,
    signal.SIGUSR2,
    signal.SIGALRM,
    signal.SIGVTALRM,
    signal.SIGPROF,
    signal.SIGPWR,
    signal.SIGXCPU,
    signal.SIGIO,
    signal.SIGSTKFLT,
    *range(signal.SIGRTMIN, signal.SIGRTMAX + 1),
)
"""Signals whose default action ends the process and that the daemon has no use for."""


def signal_name(signum: int) -> str:
    """A signal's name: ``SIGUSR1``; a real-time one's ``SIGRTMIN+3``."""
    if signal.SIGRTMIN < signum < signal.SIGRTMAX:
        return f"SIGRTMIN+{signum - signal.SIGRTMIN}"
    return signal.Signals(signum).name


UNUSED_LOG_S = 10.0
"""Least time between two ``signal_ignored`` log lines, s: a storm of such signals is
one line per interval, with the count of each signal since the line before."""


class Unused:
    """The unused signals received: counted in the handler (no I/O there), logged by
    the loop (:meth:`log`)."""

    def __init__(self) -> None:
        self.pending: Counter[str] = Counter()
        """Each unused signal's count since the last log line, by name."""
        self.total = 0
        """Every unused signal received."""
        self.next_log = -math.inf

    def handler(self, signum: int, frame: FrameType | None) -> None:
        """The handler of :data:`UNUSED_SIGNALS`: count it."""
        self.pending[signal_name(signum)] += 1
        self.total += 1

    def log(self, log: Any, now: float) -> None:
        """Log the signals counted since the last line (``signal_ignored``), at most
        once per :data:`UNUSED_LOG_S` (``now``: monotonic, s)."""
        if not self.pending or now < self.next_log:
            return
        counts, self.pending = self.pending, Counter()
        self.next_log = now + UNUSED_LOG_S
        log.warning(
            "signal_ignored",
            signals=dict(counts),
            total=self.total,
            detail="emlogd has no use for it: SIGHUP reloads the config, SIGTERM stops",
        )


TERMINAL_STOPS = (signal.SIGTTOU, signal.SIGTTIN)
"""Signals that stop a process of a background process group for using its terminal."""


def ignore_terminal_stops() -> None:
    """Ignore :data:`TERMINAL_STOPS`: a write to the terminal goes through, a read fails
    (``EIO``) rather than stopping the daemon."""
    for sig in TERMINAL_STOPS:
        signal.signal(sig, signal.SIG_IGN)


HELD: tuple[int, ...] = (signal.SIGHUP, *UNUSED_SIGNALS)
"""The signals :func:`hold_early` holds until :func:`install`."""

_held: Counter[int] = Counter()
"""Each held signal received before :func:`install`, by number."""


def _hold(signum: int, frame: FrameType | None) -> None:
    _held[signum] += 1


def hold_early() -> None:
    """Hold :data:`HELD` until :func:`install`: each received meanwhile is counted (no
    I/O in the handler) and :func:`install` passes it on."""
    for sig in HELD:
        signal.signal(sig, _hold)


def install(on_stop: Handler, on_hup: Handler, unused: Unused, wake_fd: int) -> dict[int, Any]:
    """Install the daemon's handlers and the wake-up descriptor, and pass on what
    :func:`hold_early` held (a SIGHUP: ``on_hup`` once; the unused signals: counted in
    ``unused``); the handlers they replaced, by signal (:func:`restore` puts them back)."""
    old: dict[int, Any] = {
        signal.SIGTERM: signal.signal(signal.SIGTERM, on_stop),
        signal.SIGINT: signal.signal(signal.SIGINT, on_stop),
        signal.SIGHUP: signal.signal(signal.SIGHUP, on_hup),
    }
    for sig in UNUSED_SIGNALS:
        old[sig] = signal.signal(sig, unused.handler)
    signal.set_wakeup_fd(wake_fd, warn_on_full_buffer=False)
    held = dict(_held)  # after the handlers: nothing is held from here on
    _held.clear()
    for sig, n in held.items():
        if sig == signal.SIGHUP:
            on_hup(sig, None)
        else:
            unused.pending[signal_name(sig)] += n
            unused.total += n
    return old


def restore(old: dict[int, Any]) -> None:
    """Put back the handlers :func:`install` replaced; no wake-up descriptor."""
    for sig, handler in old.items():
        signal.signal(sig, handler)
    signal.set_wakeup_fd(-1)


def drain(fd: int) -> None:
    """Empty the (non-blocking) wake-up pipe's read end ``fd``."""
    with contextlib.suppress(BlockingIOError, InterruptedError):
        while os.read(fd, 512):
            pass
