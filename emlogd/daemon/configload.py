"""A reloaded config, loaded in a thread beside the daemon's loop, once its file has
settled."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from drivers.errors import ConfigError
from emlogd.config import Config, load_config

SETTLE_S = 0.2
"""How long the config file must keep the same size, modification time and inode before
a reload parses it, s: an editor or a deployment tool writing it as the SIGHUP comes (a
``cp`` over it, a script's ``echo >>`` lines) is let finish. A half-written file was read
as it stood: refused (``reload_failed``), or — cut after a whole line — applied as a
config that lacked its end."""

SETTLE_MAX_S = 1.0
"""The longest a reload waits for the file to settle, s; a file still changing then is
parsed as it stands (a script rewriting it in a loop would hold reloads for ever)."""


def _stamp(path: Path) -> tuple[int, int, int] | None:
    """The file's size, modification time (ns) and inode; None if it cannot be read."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_size, st.st_mtime_ns, st.st_ino)


def wait_settled(
    path: Path, settle_s: float = SETTLE_S, max_s: float = SETTLE_MAX_S
) -> tuple[int, int, int] | None:
    """Wait until ``path`` has not changed for ``settle_s`` (at most ``max_s``); return
    its stamp then."""
    deadline = time.monotonic() + max_s
    last = _stamp(path)
    while time.monotonic() < deadline:
        time.sleep(settle_s)
        now = _stamp(path)
        if now == last:
            return now
        last = now
    return last


class ConfigLoad:
    """A config file loaded in a thread of its own, beside the loop: parsing a config
    near :data:`~emlogd.config.MAX_CONFIG_BYTES` takes the pure-Python YAML parser
    seconds (6 s on a flow list of one-digit items), which in the loop's thread held
    every output. The thread first waits for the file to settle (:data:`SETTLE_S`), then
    parses it, and parses it again if it changed meanwhile; it takes the interpreter's
    lock in turns with the loop (every few milliseconds) and sets :attr:`done` when it has
    :attr:`result`; the loop, awake at least every
    :data:`~emlogd.daemon.loop.SELECT_TIMEOUT_S`, then applies it.

    Args:
        path: the config file.
        settle_s: how long the file must stay unchanged before it is parsed.
    """

    def __init__(self, path: Path, settle_s: float = SETTLE_S) -> None:
        self.path = path
        self.settle_s = settle_s
        self.result: Config | Exception = ConfigError(f"{path}: not loaded")
        self.done = threading.Event()
        threading.Thread(target=self._run, name="config-load", daemon=True).start()

    def _run(self) -> None:
        deadline = time.monotonic() + SETTLE_MAX_S
        while True:
            stamp = wait_settled(self.path, self.settle_s, max(deadline - time.monotonic(), 0))
            try:
                self.result = load_config(self.path)
            except Exception as exc:  # contained: handed to the loop as the reload's failure
                self.result = exc
            if _stamp(self.path) == stamp or time.monotonic() >= deadline:
                break  # else it changed while parsed: the newer file is the one meant
        self.done.set()


def why_not_loaded(exc: Exception) -> str:
    """A config error's message; any other failure with its type (no check foresaw it)."""
    return str(exc) if isinstance(exc, (ConfigError, OSError)) else f"{type(exc).__name__}: {exc}"
