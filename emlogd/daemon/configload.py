"""A reloaded config, loaded in a thread beside the daemon's loop."""

from __future__ import annotations

import threading
from pathlib import Path

from drivers.errors import ConfigError
from emlogd.config import Config, load_config


class ConfigLoad:
    """A config file loaded in a thread of its own, beside the loop: parsing a config
    near :data:`~emlogd.config.MAX_CONFIG_BYTES` takes the pure-Python YAML parser
    seconds (6 s on a flow list of one-digit items), which in the loop's thread held
    every output. The thread
    takes the interpreter's lock in turns with the loop (every few milliseconds) and
    sets :attr:`done` when it has :attr:`result`; the loop, awake at least every
    :data:`~emlogd.daemon.loop.SELECT_TIMEOUT_S`, then applies it.

    Args:
        path: the config file.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.result: Config | Exception = ConfigError(f"{path}: not loaded")
        self.done = threading.Event()
        threading.Thread(target=self._run, name="config-load", daemon=True).start()

    def _run(self) -> None:
        try:
            self.result = load_config(self.path)
        except Exception as exc:  # contained: handed to the loop as the reload's failure
            self.result = exc
        self.done.set()


def why_not_loaded(exc: Exception) -> str:
    """A config error's message; any other failure with its type (no check foresaw it)."""
    return str(exc) if isinstance(exc, (ConfigError, OSError)) else f"{type(exc).__name__}: {exc}"
