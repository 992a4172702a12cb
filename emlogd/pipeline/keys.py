"""Config keys declared once, on the dataclasses that use them.

A config key is a dataclass field made with :func:`key`: its default is the field's,
and its check, unit and doc travel in the field's metadata. A field made with
:func:`group` is a dataclass whose keys appear, flat, in the same config section (the
envelope's ``max_speed_mps`` is a ``calibration`` key). The YAML loader
(:mod:`emlogd.config`), its dump and the README's table (:mod:`emlogd.configdump`) and the pipeline
all read these declarations; this module is pure (no YAML, no I/O), so the pipeline's
own settings carry them.

A check takes the value as parsed and returns it (possibly converted) or raises
:class:`InvalidValueError` with the problem; the loader adds the file, the line and the key.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, get_args


class InvalidValueError(ValueError):
    """A value a check refuses.

    Attributes:
        sub: the key inside a mapping value at fault (``max_param_std.z``), or None.
    """

    def __init__(self, message: str, sub: str | None = None) -> None:
        super().__init__(message)
        self.sub = sub


@dataclass(frozen=True, slots=True)
class Check:
    """A value check and the words the README's table gives it."""

    fn: Callable[[Any], Any]
    text: str
    mapping: bool = False
    """The value is a mapping (not a single value)."""

    def __call__(self, value: Any) -> Any:
        return self.fn(value)


@dataclass(frozen=True, slots=True)
class Key:
    """What a config key carries besides its default.

    Attributes:
        check: validates (and converts) a value.
        doc: one or two sentences for the README's table.
        unit: the unit of a number (``s``, ``m/s``...), or "".
        name: the key's name in the config when it is not the field's.
        absent: ``(value,)``: the value the config assumes when the key is absent,
            when it is not the field's default (``current: auto`` is resolved at
            load); ``()``: the field's default.
        path: a relative path, resolved against the config file's directory.
        show: the value as written in a config (``lag``: None is ``auto``).
        text: the default as the README's table gives it, when not the value's text.
    """

    check: Check
    doc: str
    unit: str = ""
    name: str | None = None
    absent: tuple[Any, ...] = ()
    path: bool = False
    show: Callable[[Any], Any] | None = None
    text: str = ""


def key(
    default: Any = dataclasses.MISSING,
    *,
    check: Check,
    doc: str,
    unit: str = "",
    name: str | None = None,
    absent: Any = dataclasses.MISSING,
    path: bool = False,
    show: Callable[[Any], Any] | None = None,
    text: str = "",
    factory: Callable[[], Any] | None = None,
) -> Any:
    """A dataclass field that is a config key (see :class:`Key`); ``factory`` for a
    mutable default; no default and no factory: a required key."""
    given = () if absent is dataclasses.MISSING else (absent,)
    meta = {"key": Key(check, doc, unit, name, given, path, show, text)}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def group(cls: type, *, required: bool = False) -> Any:
    """A dataclass field holding ``cls``, whose keys sit flat in the parent's section;
    ``required``: no default (the group has required keys)."""
    meta = {"group": cls}
    if required:
        return dataclasses.field(metadata=meta)
    return dataclasses.field(default_factory=cls, metadata=meta)


@dataclass(frozen=True, slots=True)
class Entry:
    """One key of a section: its config name, the attribute path to its field, the
    declaration and the field's default (MISSING: required)."""

    name: str
    attrs: tuple[str, ...]
    key: Key
    default: Any

    @property
    def required(self) -> bool:
        """No default: the key must be given."""
        return self.default is dataclasses.MISSING and not self.key.absent

    @property
    def absent(self) -> Any:
        """The value the config assumes when the key is absent."""
        return self.key.absent[0] if self.key.absent else self.default


def entries(cls: type, prefix: tuple[str, ...] = ()) -> Iterator[Entry]:
    """Every key of the section ``cls`` declares, groups flattened, in field order."""
    for f in dataclasses.fields(cls):
        if "group" in f.metadata:
            yield from entries(f.metadata["group"], (*prefix, f.name))
        elif "key" in f.metadata:
            k: Key = f.metadata["key"]
            if f.default is not dataclasses.MISSING:
                default = f.default
            elif f.default_factory is not dataclasses.MISSING:
                default = f.default_factory()
            else:
                default = dataclasses.MISSING
            yield Entry(k.name or f.name, (*prefix, f.name), k, default)


def build(cls: type, values: dict[tuple[str, ...], Any]) -> Any:
    """An instance of ``cls`` from values by attribute path (groups built from theirs;
    a group with no value given takes its default)."""
    return _build(cls, values, ())


def _build(cls: type, values: dict[tuple[str, ...], Any], prefix: tuple[str, ...]) -> Any:
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        here = (*prefix, f.name)
        if "group" in f.metadata:
            required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            if required or any(p[: len(here)] == here for p in values):
                kw[f.name] = _build(f.metadata["group"], values, here)
        elif here in values:
            kw[f.name] = values[here]
    return cls(**kw)


def get(obj: Any, attrs: tuple[str, ...]) -> Any:
    """The value at an attribute path."""
    for a in attrs:
        obj = getattr(obj, a)
    return obj


# ------------------------------------------------------------------ checks


def string(pattern: str | None = None, what: str = "") -> Check:
    """A non-empty string, matching ``pattern`` (described as ``what``) when given."""

    def fn(v: Any) -> Any:
        if not isinstance(v, str) or not v:
            raise InvalidValueError(f"expected a non-empty string, got {v!r}")
        if pattern is not None and not re.fullmatch(pattern, v):
            raise InvalidValueError(f"{v!r} is not {what}")
        return v

    return Check(fn, what or "string")


def opt_string(what: str = "string") -> Check:
    """A non-empty string or null."""

    def fn(v: Any) -> Any:
        if v is None:
            return None
        if not isinstance(v, str) or not v:
            raise InvalidValueError(f"expected a string or null, got {v!r}")
        return v

    return Check(fn, f"{what} or null")


def enum(*choices: str) -> Check:
    """One of ``choices``."""

    def fn(v: Any) -> Any:
        if v not in choices:
            raise InvalidValueError(f"{v!r} is not one of {', '.join(choices)}")
        return v

    return Check(fn, ", ".join(choices))


def literal(tp: Any) -> Check:
    """One of the values of the ``Literal`` type ``tp`` (the field's own type)."""
    return enum(*get_args(tp))


def _boolean(v: Any) -> Any:
    if not isinstance(v, bool):
        raise InvalidValueError(f"expected true or false, got {v!r}")
    return v


boolean = Check(_boolean, "true, false")
"""true or false."""


def _g(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def number(
    lo: float, hi: float, *, integer: bool = False, lo_open: bool = False, optional: bool = False
) -> Check:
    """A finite number in [lo, hi] (``lo_open``: (lo, hi]); ``integer``: an integer;
    ``optional``: or null."""
    bound = f"({_g(lo)}, {_g(hi)}]" if lo_open else f"[{_g(lo)}, {_g(hi)}]"

    def fn(v: Any) -> Any:
        if v is None and optional:
            return None
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise InvalidValueError(f"expected a number, got {v!r}")
        if integer and not isinstance(v, int):
            raise InvalidValueError(f"expected an integer, got {v!r}")
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            b = f"({lo}, {hi}]" if lo_open else f"[{lo}, {hi}]"
            raise InvalidValueError(f"{v!r} is out of range {b}")
        return v

    return Check(
        fn, ("integer" if integer else "number") + f" in {bound}" + (" or null" if optional else "")
    )


def or_null(check: Check) -> Check:
    """``check``, or null."""

    def fn(v: Any) -> Any:
        return None if v is None else check(v)

    return Check(fn, f"{check.text} or null")


def _bool_or_auto(v: Any) -> Any:
    if v == "auto" or isinstance(v, bool):
        return v
    raise InvalidValueError(f"expected auto, true or false, got {v!r}")


bool_or_auto = Check(_bool_or_auto, "auto, true, false")
"""auto, true or false."""


def _lag(v: Any) -> Any:
    if v == "auto":
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= 30.0:
        raise InvalidValueError(f"expected auto or seconds in [0, 30], got {v!r}")
    return float(v)


lag = Check(_lag, "auto or number in [0, 30]")
"""auto (None) or seconds in [0, 30]."""


def _hostport(v: Any) -> Any:
    if v is None:
        return None
    text = str(v)
    host, sep, port = text.rpartition(":")
    if (
        not re.fullmatch(r"[0-9]{1,5}", port)
        or not 0 < int(port) < 65536
        or (sep and not re.fullmatch(r"[\w.\-\[\]:]*", host))
    ):
        raise InvalidValueError(f"{text!r} is not HOST:PORT (port 1..65535)")
    return text


hostport = Check(_hostport, "HOST:PORT or null")
"""``HOST:PORT`` (host optional) or null."""


def _ipv4_port(v: Any) -> Any:
    text = _hostport(v)
    host = "" if text is None else text.rpartition(":")[0]
    if host:
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise InvalidValueError(
                f"{text!r}: needs an IPv4 address, not a host name (resolving it would hold "
                "the daemon's one thread, every output with it, at every retry)"
            ) from None
    return text


ipv4_port = Check(_ipv4_port, "IPv4:PORT or null")
"""``IPV4:PORT`` (the address optional) or null: a TCP output's or a UDP destination's."""


def param_std(names: tuple[str, ...], lo: float, hi: float) -> Check:
    """A mapping of some of ``names`` to numbers in (lo, hi]."""
    each = number(lo, hi, lo_open=True)

    def fn(v: Any) -> Any:
        out = {}
        for k, x in v.items():
            if k not in names:
                raise InvalidValueError(
                    f"unknown parameter ({', '.join(names[:-1])} or {names[-1]})", k
                )
            try:
                out[k] = each(x)
            except InvalidValueError as exc:
                raise InvalidValueError(str(exc), k) from None
        return out

    return Check(fn, f"map of {', '.join(names)} to {each.text}", mapping=True)


NAME = r"[A-Za-z0-9_.\-]{1,32}"
"""A port name."""


def port_or_auto() -> Check:
    """auto or a port name."""

    def fn(v: Any) -> Any:
        if v == "auto" or (isinstance(v, str) and re.fullmatch(NAME, v)):
            return v
        raise InvalidValueError(f"expected auto or a port name, got {v!r}")

    return Check(fn, "auto or a port name")
