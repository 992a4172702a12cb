"""What the command groups share: usage errors, progress on stderr, argument types."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NoReturn, TypeAlias

from drivers import EmlogdError

Handler = Callable[[argparse.Namespace], int]


class UsageError(EmlogdError):
    """A command line that parses but makes no sense (exit code 2)."""


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on stderr (exit code 2).

    Sub-command parsers are of the same class (``add_subparsers`` uses the parent's).
    """

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE (PROG --help)`` and exit 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


Subparsers: TypeAlias = "argparse._SubParsersAction[Parser]"
"""What ``add_subparsers`` returns; each command group adds its commands to it."""


STD_STREAMS = (
    ("stdin", os.O_RDONLY, "r"),
    ("stdout", os.O_WRONLY, "w"),
    ("stderr", os.O_WRONLY, "w"),
)
"""The standard streams by descriptor (0, 1, 2): name, how ``/dev/null`` is opened for
it and the mode of its stream."""


def open_std_streams() -> list[str]:
    """Give each standard descriptor (0, 1, 2) that is closed ``/dev/null``, and the
    interpreter a stream on it; the names of those given, in order.

    A process started with them closed (``emlogd run >&- 2>&-``, a script or a service
    manager that closes them) has ``sys.stdout`` None, and the first descriptors it opens
    take their numbers: a port, the state file or a client's socket written to as the
    standard output.
    """
    given = []
    for fd, (name, flags, mode) in enumerate(STD_STREAMS):
        try:
            os.fstat(fd)
        except OSError:
            null = os.open(os.devnull, flags)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            given.append(name)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, mode, encoding="utf-8", closefd=False))  # noqa: SIM115
    return given


def is_tty(stream: Any) -> bool:
    """Whether ``stream`` is a terminal (False for anything without a working isatty)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


PROGRESS_QUIET_S = 2.0
"""Piped progress starts only once a command has run this long (a quick command stays
silent on stderr)."""

PROGRESS_EVERY_S = 1.0
"""Piped progress: at most one line per this many seconds for the same message (a new
message, or the end of one, is always written)."""


@dataclass(slots=True)
class _Progress:
    """Where the progress of the running command stands (one command per process)."""

    command: str = "emlogd"
    started: float = field(default_factory=time.monotonic)
    last_msg: str = ""
    last_t: float = -math.inf


_state = _Progress()


def progress_start(command: str) -> None:
    """A command starts: piped progress lines are prefixed with it and timed from now."""
    global _state
    _state = _Progress(command=f"emlogd {command}")


def progress(msg: str, fraction: float | None = None) -> None:
    """Progress on stderr as the work happens.

    On a terminal: one line rewritten in place. Piped: once the command has run
    :data:`PROGRESS_QUIET_S`, a line per new message and at most one per
    :data:`PROGRESS_EVERY_S` otherwise (and at 100 %), ``emlogd CMD: [ELAPSED s] MSG PCT``,
    flushed as written.
    """
    pct = "" if fraction is None else f" {100.0 * fraction:5.1f} %"
    if is_tty(sys.stderr):
        sys.stderr.write(f"\r{msg}{pct}\x1b[K")
        sys.stderr.flush()
        return
    now = time.monotonic()
    elapsed = now - _state.started
    if elapsed < PROGRESS_QUIET_S:
        return
    done = fraction is not None and fraction >= 1.0
    if msg == _state.last_msg and not done and now - _state.last_t < PROGRESS_EVERY_S:
        return
    _state.last_msg, _state.last_t = msg, now
    sys.stderr.write(f"{_state.command}: [{elapsed:6.1f} s] {msg}{pct}\n")
    sys.stderr.flush()


def progress_done() -> None:
    """Clear the progress line (on a terminal; piped lines stay)."""
    if is_tty(sys.stderr):
        sys.stderr.write("\r\x1b[K")
        sys.stderr.flush()


def config_path(args: argparse.Namespace) -> str:
    """``--config``, else the default config path."""
    from emlogd.config import DEFAULT_PATH

    return str(getattr(args, "config", None) or DEFAULT_PATH)


def positive_float(value: str) -> float:
    """argparse type: a finite number greater than zero (a speed, a duration)."""
    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, not {value!r}") from None
    if not (x > 0.0 and math.isfinite(x)):
        raise argparse.ArgumentTypeError(f"must be a positive number, not {value!r}")
    return x


def key_arg(cls: type, field: str, *, allow_auto: bool = True) -> Callable[[str], Any]:
    """argparse type: a value checked like the config key ``field`` of the settings
    dataclass ``cls`` (the key's own declared check and bounds, so an option and its
    key accept the same values); ``allow_auto`` false refuses ``auto`` where a key takes it.

    The text is read as an integer, else a number, else kept (``auto``); a value the
    key's check refuses is an argparse error (exit 2) naming the key's range.
    """
    import dataclasses

    from emlogd.pipeline.keys import InvalidValueError, Key

    f = next((f for f in dataclasses.fields(cls) if f.name == field), None)
    if f is None or "key" not in f.metadata:
        raise ValueError(f"{cls.__name__}.{field} is not a config key")
    k: Key = f.metadata["key"]
    name = k.name or field

    def convert(text: str) -> Any:
        value: Any = text
        for conv in (int, float):
            try:
                value = conv(text)
                break
            except ValueError:
                continue
        if value == "auto" and not allow_auto:
            raise argparse.ArgumentTypeError(f"expected a number, not {text!r}")
        try:
            return k.check(value)
        except InvalidValueError as exc:
            raise argparse.ArgumentTypeError(
                f"{exc} (the config key {name}: {k.check.text}"
                + (f" {k.unit}" if k.unit else "")
                + ")"
            ) from None

    convert.__name__ = name  # argparse names the type in its messages
    return convert


def two_axis_line(two: dict[str, Any]) -> str:
    """A two-axis log's learnt figures (``axes: 2``): applied, validating or learning, α
    ± σ with m_t and b_t, whose forward speed goes out and why (``forward_reason``), the
    leeway angle, and why the latest window refused α (said once: the forward speed's
    reason may be that refusal)."""
    fig = two.get("applied") or two.get("estimate")
    text = f"two axes: {two.get('state')}"
    if isinstance(fig, dict):
        text += (
            f", misalignment {fig['misalign_deg']:+.2f} ± {fig['misalign_std_deg']:.2f}°, "
            f"m_t {fig['m_t']:+.4f} ± {fig['m_t_std']:.4f}, "
            f"b_t {fig['b_t_mps']:+.3f} ± {fig['b_t_std_mps']:.3f} m/s"
        )
    if two.get("state") == "applied" and two.get("forward") == "two_axis":
        text += ", forward speed by the two-axis fit"
    lee = two.get("leeway_deg")
    if isinstance(lee, float):
        text += f", leeway {lee:+.1f}°"
    why = two.get("forward_reason")
    if why:
        text += f"; forward speed: {why}"
    refused = two.get("refused")
    if refused and not (why and str(refused) in str(why)):
        text += f"; latest window: misalignment refused: {refused}"
    if two.get("note"):
        text += f"; {two['note']}"
    return text
