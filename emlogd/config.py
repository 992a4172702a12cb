"""The daemon's YAML configuration, validated at load.

Every error names the file, the line and the key, e.g.
``emlogd.yaml:14: calibration[0].model: 'EM5' is not one of EM1, EM2, EM3, EM4``.
Unknown keys, duplicate keys, wrong types and bad values are all errors; relative
paths (serial devices given as files, the state file, the pty link) are resolved
against the config file's directory, so an example config works from anywhere.
The full schema with defaults is documented in ``examples/emlogd.yaml``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from calib.kalman import KfConfig
from drivers import protocol_names
from drivers.errors import ConfigError
from emlogd.pipeline.core import RefField, UutSettings
from emlogd.pipeline.integrity import Envelope

DEFAULT_PATH = "/etc/emlogd/emlogd.yaml"
DVL_PROTOCOLS = ("pd6", "pd13", "pd0", "pd4", "pd5", "nmea0183")
"""Protocols that can carry a DVL bottom track (nmea0183: Rowe $PRTI01)."""

Role = Literal["uut", "reference", "aux"]


@dataclass(frozen=True, slots=True)
class PortConfig:
    """One input port (``ports`` list)."""

    name: str
    url: str
    protocol: str
    role: Role
    baud: int = 9600
    checksum: Literal["required", "optional"] = "required"
    max_length: int = 82
    rate_hz: float | None = None
    stale_timeout_s: float = 5.0
    rest_s: float = 0.02
    """Reference and aux ports: once the port is readable, leave it alone this long,
    then read it (a burst is one read, not a wake-up per line; what arrived is stamped
    with that read, at most this late). Keep it well under the time the port takes to
    fill the 4 KiB tty buffer and under the gap between bursts; 0 disables (and suits
    devices replayed faster than real time). UUT ports never rest."""


_UUT = UutSettings(port="", reference_port="")
"""The pipeline's declared defaults: the config's defaults are read from here, never typed
again (``tests/emlogd/test_config.py`` checks every key against it)."""
_KF = KfConfig()
_ENVELOPE = Envelope()


@dataclass(frozen=True, slots=True)
class UutConfig:
    """Calibration of one EMlog (``calibration`` list).

    The fields with a :class:`~emlogd.pipeline.core.UutSettings` field of the same name
    pass to it as they are (:func:`emlogd.settings.pipeline_from_config`); the others
    are the filter's tuning and the envelope's speed range.
    """

    uut: str
    reference: str
    model: str = _UUT.model
    reference_field: RefField = _UUT.reference_field
    uut_source: str = _UUT.uut_source
    talker: str | None = None
    """The talker of this log's corrected sentences; None: ``outputs.talker`` (two logs
    with their own talkers are two sources to a chart plotter or Signal K)."""
    pty: str | None = None
    """This log's own output pty: its sentences go there instead of the shared outputs."""
    tcp: str | None = None
    """This log's own NMEA over TCP (``HOST:PORT``), instead of the shared outputs."""
    udp: str | None = None
    """This log's own UDP destination, instead of the shared outputs."""
    component: Literal["longitudinal", "magnitude"] = _UUT.component
    current: bool | Literal["auto"] = "auto"
    """auto: estimate the current wherever a heading is known to come (see
    :func:`emlogd.settings.heading_expected`)."""
    heading: str = _UUT.heading
    magnetic_variation_deg: float | None = _UUT.magnetic_variation_deg
    lag_s: float | None = _UUT.lag_s
    lag_window_s: float = _UUT.lag_window_s
    max_lag_s: float = _UUT.max_lag_s
    learn: bool = _UUT.learn
    apply: bool = _UUT.apply
    min_ref_speed_mps: float = _UUT.min_ref_speed_mps
    min_sog_mps: float = _UUT.min_sog_mps
    max_param_std: Mapping[str, float] = field(default_factory=lambda: dict(_UUT.max_param_std))
    excitation_half_life_samples: float = _UUT.excitation_half_life_samples
    r_raw_mps: float = math.sqrt(_KF.r_raw_mps2)
    r_ref_mps: float | None = None
    """None: the reference field's own noise (``REF_NOISE_MPS``)."""
    q_params: float = _KF.q_params
    p0: float = _KF.p0
    current_psd_m2ps3: float = _KF.current_psd_m2ps3
    persist_interval_s: float = _UUT.persist_interval_s
    persist_min_change_sigma: float = _UUT.persist_min_change_sigma
    persist_min_change_abs: float = _UUT.persist_min_change_abs
    validation_s: float = _UUT.validation_s
    average_s: float | None = _UUT.average_s
    recheck_s: float = _UUT.recheck_s
    gate_nis: float = _UUT.gate_nis
    relearn_gates: int = _UUT.relearn_gates
    low_speed_mps: float = _UUT.low_speed_mps
    max_speed_mps: float = _ENVELOPE.max_speed_mps
    stuck_s: float = _UUT.stuck_s
    zero_s: float = _UUT.zero_s
    max_accel_mps2: float = _UUT.max_accel_mps2
    max_turn_rate_dps: float = _UUT.max_turn_rate_dps


@dataclass(frozen=True, slots=True)
class OutputConfig:
    """Where the corrected NMEA goes (``outputs``)."""

    pty: str | None = "/run/emlogd/emlog0"
    pty_mode: int = 0o660
    pty_group: str | None = None
    """The group of the pty (its readers, e.g. the autopilot's user); None: unchanged."""
    tcp: str | None = None
    udp: str | None = None
    stdout: bool = False
    talker: str = "VW"
    maker: str = "EML"
    status_interval_s: float = 1.0
    speed: Literal["each", "fused", "both"] = "each"
    """each: every log's corrected sentences; fused: one speed for the autopilot, the
    inverse-variance weighted mean of every healthy log (``$PEMLF`` says which);
    both: the two."""
    fused_talker: str = "II"


@dataclass(frozen=True, slots=True)
class Config:
    """A validated configuration."""

    path: str
    ports: tuple[PortConfig, ...]
    calibration: tuple[UutConfig, ...]
    outputs: OutputConfig = field(default_factory=OutputConfig)
    state_path: str = "/var/lib/emlogd/state.yaml"
    control_socket: str = "/run/emlogd/control.sock"
    status_socket: str | None = None
    """A read-only socket (``status`` only, mode 0666), or None for none."""
    log_format: Literal["auto", "json", "console"] = "auto"
    log_level: Literal["debug", "info", "warning", "error"] = "info"
    status_interval_s: float = 10.0

    def port(self, name: str) -> PortConfig:
        """The port called ``name``."""
        for p in self.ports:
            if p.name == name:
                return p
        raise KeyError(name)


# ------------------------------------------------------------------ loading


class _Loader(yaml.SafeLoader):
    """SafeLoader that keeps nodes (for line numbers)."""


class _Ctx:
    def __init__(self, path: str, loader: _Loader) -> None:
        self.path = path
        self.loader = loader

    def fail(self, node: yaml.Node | None, where: str, msg: str) -> ConfigError:
        line = node.start_mark.line + 1 if node is not None else 1
        return ConfigError(
            f"{self.path}:{line}: {where}: {msg}" if where else f"{self.path}:{line}: {msg}"
        )

    def mapping(self, node: yaml.Node, where: str) -> dict[str, tuple[yaml.Node, yaml.Node]]:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, where, "expected a mapping (key: value)")
        out: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for k, v in node.value:
            if not isinstance(k, yaml.ScalarNode) or not isinstance(k.value, str):
                raise self.fail(k, where, "keys must be strings")
            if k.value in out:
                raise self.fail(k, f"{where}.{k.value}" if where else k.value, "duplicate key")
            out[k.value] = (k, v)
        return out

    def sequence(self, node: yaml.Node, where: str) -> list[yaml.Node]:
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(node, where, "expected a list")
        return list(node.value)

    def scalar(self, node: yaml.Node, where: str) -> Any:
        if not isinstance(node, yaml.ScalarNode):
            raise self.fail(node, where, "expected a single value")
        return self.loader.construct_object(node, deep=True)


Check = Callable[[_Ctx, yaml.Node, str], Any]


def _str(pattern: str | None = None, what: str = "") -> Check:
    def check(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
        v = ctx.scalar(node, where)
        if not isinstance(v, str) or not v:
            raise ctx.fail(node, where, f"expected a non-empty string, got {v!r}")
        if pattern is not None and not re.fullmatch(pattern, v):
            raise ctx.fail(node, where, f"{v!r} is not {what}")
        return v

    return check


def _opt_str() -> Check:
    def check(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
        v = ctx.scalar(node, where)
        if v is None:
            return None
        if not isinstance(v, str) or not v:
            raise ctx.fail(node, where, f"expected a string or null, got {v!r}")
        return v

    return check


def _enum(*choices: str) -> Check:
    def check(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
        v = ctx.scalar(node, where)
        if v not in choices:
            raise ctx.fail(node, where, f"{v!r} is not one of {', '.join(choices)}")
        return v

    return check


def _bool(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    v = ctx.scalar(node, where)
    if not isinstance(v, bool):
        raise ctx.fail(node, where, f"expected true or false, got {v!r}")
    return v


def _num(
    lo: float, hi: float, *, integer: bool = False, lo_open: bool = False, optional: bool = False
) -> Check:
    def check(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
        v = ctx.scalar(node, where)
        if v is None and optional:
            return None
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ctx.fail(node, where, f"expected a number, got {v!r}")
        if integer and not isinstance(v, int):
            raise ctx.fail(node, where, f"expected an integer, got {v!r}")
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            bound = f"({lo}, {hi}]" if lo_open else f"[{lo}, {hi}]"
            raise ctx.fail(node, where, f"{v!r} is out of range {bound}")
        return v

    return check


def _or_null(check: Check) -> Check:
    def inner(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
        return None if ctx.scalar(node, where) is None else check(ctx, node, where)

    return inner


def _bool_or_auto(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    v = ctx.scalar(node, where)
    if v == "auto" or isinstance(v, bool):
        return v
    raise ctx.fail(node, where, f"expected auto, true or false, got {v!r}")


def _lag(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    v = ctx.scalar(node, where)
    if v == "auto":
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= 30.0:
        raise ctx.fail(node, where, f"expected auto or seconds in [0, 30], got {v!r}")
    return float(v)


def _hostport(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    v = ctx.scalar(node, where)
    if v is None:
        return None
    text = str(v)
    host, sep, port = text.rpartition(":")
    if (
        not re.fullmatch(r"[0-9]{1,5}", port)
        or not 0 < int(port) < 65536
        or (sep and not re.fullmatch(r"[\w.\-\[\]:]*", host))
    ):
        raise ctx.fail(node, where, f"{text!r} is not HOST:PORT (port 1..65535)")
    return text


def _param_std(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    m = ctx.mapping(node, where)
    out = {}
    for key, (kn, vn) in m.items():
        if key not in ("a", "m", "b"):
            raise ctx.fail(kn, f"{where}.{key}", "unknown parameter (a, m or b)")
        out[key] = _num(0.0, 10.0, lo_open=True)(ctx, vn, f"{where}.{key}")
    return out


def _section(
    ctx: _Ctx,
    node: yaml.Node,
    where: str,
    spec: Mapping[str, tuple[str, Check]],
    required: tuple[str, ...] = (),
) -> dict[str, Any]:
    """Check a mapping against ``spec`` (yaml key -> (attribute, check))."""
    m = ctx.mapping(node, where)
    for key, (kn, _) in m.items():
        if key not in spec:
            raise ctx.fail(
                kn, f"{where}.{key}" if where else key, f"unknown key (valid: {', '.join(spec)})"
            )
    for key in required:
        if key not in m:
            raise ctx.fail(node, where, f"missing required key {key!r}")
    return {
        spec[k][0]: spec[k][1](ctx, vn, f"{where}.{k}" if where else k) for k, (_, vn) in m.items()
    }


_NAME = r"[A-Za-z0-9_.\-]{1,32}"

PORT_SPEC: dict[str, tuple[str, Check]] = {
    "name": ("name", _str(_NAME, "a port name (letters, digits, _ . -; at most 32)")),
    "url": ("url", _str()),
    "protocol": ("protocol", _str()),
    "role": ("role", _enum("uut", "reference", "aux")),
    "baud": ("baud", _num(50, 4_000_000, integer=True)),
    "checksum": ("checksum", _enum("required", "optional")),
    "max_length": ("max_length", _num(8, 1024, integer=True)),
    "rate_hz": ("rate_hz", _num(0.0, 1000.0, lo_open=True, optional=True)),
    "stale_timeout_s": ("stale_timeout_s", _num(0.0, 3600.0, lo_open=True)),
    "rest_s": ("rest_s", _num(0.0, 1.0)),
}


def _heading_source(ctx: _Ctx, node: yaml.Node, where: str) -> Any:
    v = ctx.scalar(node, where)
    if v == "auto" or (isinstance(v, str) and re.fullmatch(_NAME, v)):
        return v
    raise ctx.fail(node, where, f"expected auto or a port name, got {v!r}")


UUT_SPEC: dict[str, tuple[str, Check]] = {
    "uut": ("uut", _str(_NAME, "a port name")),
    "reference": ("reference", _str(_NAME, "a port name")),
    "model": ("model", _enum("EM1", "EM2", "EM3", "EM4")),
    "reference_field": ("reference_field", _enum("bottom", "water", "speed", "gnss")),
    "uut_source": ("uut_source", _enum("VHW", "VBW")),
    "talker": ("talker", _or_null(_str(r"[A-Z]{2}", "two uppercase letters"))),
    "pty": ("pty", _opt_str()),
    "tcp": ("tcp", _hostport),
    "udp": ("udp", _hostport),
    "component": ("component", _enum("longitudinal", "magnitude")),
    "current": ("current", _bool_or_auto),
    "heading": ("heading", _heading_source),
    "magnetic_variation_deg": (
        "magnetic_variation_deg",
        _num(-180.0, 180.0, optional=True),
    ),
    "lag": ("lag_s", _lag),
    "lag_window_s": ("lag_window_s", _num(10.0, 7200.0)),
    "max_lag_s": ("max_lag_s", _num(0.0, 30.0, lo_open=True)),
    "learn": ("learn", _bool),
    "apply": ("apply", _bool),
    "min_ref_speed_mps": ("min_ref_speed_mps", _num(0.0, 20.0)),
    "min_sog_mps": ("min_sog_mps", _num(0.0, 20.0)),
    "max_param_std": ("max_param_std", _param_std),
    "excitation_half_life_samples": ("excitation_half_life_samples", _num(1.0, 86400.0)),
    "r_raw_mps": ("r_raw_mps", _num(0.0, 10.0, lo_open=True)),
    "r_ref_mps": ("r_ref_mps", _num(0.0, 10.0, lo_open=True, optional=True)),
    "q_params": ("q_params", _num(0.0, 1.0)),
    "p0": ("p0", _num(0.0, 100.0, lo_open=True)),
    "current_psd_m2ps3": ("current_psd_m2ps3", _num(0.0, 1.0)),
    "persist_interval_s": ("persist_interval_s", _num(0.0, 86400.0)),
    "persist_min_change_sigma": ("persist_min_change_sigma", _num(0.0, 100.0)),
    "persist_min_change_abs": ("persist_min_change_abs", _num(0.0, 10.0)),
    "validation_s": ("validation_s", _num(0.1, 3600.0)),
    "average_s": ("average_s", _num(0.0, 600.0, optional=True)),
    "recheck_s": ("recheck_s", _num(1.0, 86400.0)),
    "gate_nis": ("gate_nis", _num(1.0, 1e6)),
    "relearn_gates": ("relearn_gates", _num(1, 100_000, integer=True)),
    "low_speed_mps": ("low_speed_mps", _num(0.0, 5.0)),
    "max_speed_mps": ("max_speed_mps", _num(0.0, 50.0, lo_open=True)),
    "stuck_s": ("stuck_s", _num(1.0, 86400.0)),
    "zero_s": ("zero_s", _num(1.0, 86400.0)),
    "max_accel_mps2": ("max_accel_mps2", _num(0.0, 100.0, lo_open=True)),
    "max_turn_rate_dps": ("max_turn_rate_dps", _num(0.0, 360.0, lo_open=True)),
}
"""The ``calibration`` keys (yaml key -> (attribute, check)); README's table lists them."""

OUTPUT_SPEC: dict[str, tuple[str, Check]] = {
    "pty": ("pty", _opt_str()),
    "pty_mode": ("pty_mode", _num(0, 0o777, integer=True)),
    "pty_group": ("pty_group", _opt_str()),
    "tcp": ("tcp", _hostport),
    "udp": ("udp", _hostport),
    "stdout": ("stdout", _bool),
    "talker": ("talker", _str(r"[A-Z]{2}", "two uppercase letters")),
    "maker": ("maker", _str(r"[A-Z]{3}", "three uppercase letters")),
    "status_interval_s": ("status_interval_s", _num(0.0, 3600.0)),
    "speed": ("speed", _enum("each", "fused", "both")),
    "fused_talker": ("fused_talker", _str(r"[A-Z]{2}", "two uppercase letters")),
}

TOP_SPEC: dict[str, tuple[str, Check]] = {
    "state_file": ("state_path", _str()),
    "control_socket": ("control_socket", _str()),
    "status_socket": ("status_socket", _opt_str()),
    "log_format": ("log_format", _enum("auto", "json", "console")),
    "log_level": ("log_level", _enum("debug", "info", "warning", "error")),
    "status_interval_s": ("status_interval_s", _num(0.5, 3600.0)),
}


def _values(ctx: _Ctx, node: yaml.Node, where: str) -> dict[str, yaml.Node]:
    """The value node of each key of a (checked) mapping, for precise line numbers."""
    return {k: vn for k, (_, vn) in ctx.mapping(node, where).items()}


def _check_uut(
    ctx: _Ctx,
    kw: dict[str, Any],
    at: Mapping[str, yaml.Node],
    where: str,
    by_name: Mapping[str, PortConfig],
) -> UutConfig:
    """Cross-check one ``calibration`` entry against the ports."""
    uut, ref = kw["uut"], kw["reference"]
    if uut not in by_name:
        raise ctx.fail(at["uut"], f"{where}.uut", f"no port named {uut!r}")
    if ref not in by_name:
        raise ctx.fail(at["reference"], f"{where}.reference", f"no port named {ref!r}")
    if by_name[uut].role != "uut":
        raise ctx.fail(
            at["uut"], f"{where}.uut", f"port {uut!r} has role {by_name[uut].role}, not uut"
        )
    if by_name[uut].protocol != "nmea0183":
        raise ctx.fail(at["uut"], f"{where}.uut", f"port {uut!r} must speak nmea0183 (VHW/VBW)")
    field_ = kw.get("reference_field", _UUT.reference_field)
    fat = at.get("reference_field", at["reference"])
    if uut == ref and field_ != "gnss":
        raise ctx.fail(
            at["reference"],
            f"{where}.reference",
            "the reference must be another port (one multiplexed port may be both only "
            "with reference_field: gnss)",
        )
    rport = by_name[ref]
    allowed_roles = ("reference", "uut") if field_ in ("speed", "gnss") else ("reference",)
    if rport.role not in allowed_roles:
        raise ctx.fail(
            at["reference"],
            f"{where}.reference",
            f"port {ref!r} has role {rport.role}, not {' or '.join(allowed_roles)}",
        )
    if field_ == "speed" and rport.protocol != "nmea0183":
        raise ctx.fail(
            fat,
            f"{where}.reference_field",
            f"speed needs an EMlog (nmea0183) reference, {ref!r} is {rport.protocol}",
        )
    if field_ == "water" and rport.protocol not in ("pd6", "pd13"):
        raise ctx.fail(
            fat,
            f"{where}.reference_field",
            f"water track (:WS) needs a pd6/pd13 reference, {ref!r} is {rport.protocol}",
        )
    if field_ == "gnss" and rport.protocol != "nmea0183":
        raise ctx.fail(
            fat,
            f"{where}.reference_field",
            f"gnss needs an NMEA 0183 (RMC/VTG) reference, {ref!r} is {rport.protocol}",
        )
    heading = kw.get("heading", _UUT.heading)
    if heading != "auto" and heading not in by_name:
        raise ctx.fail(at["heading"], f"{where}.heading", f"no port named {heading!r}")
    if field_ == "bottom" and rport.protocol not in DVL_PROTOCOLS:
        raise ctx.fail(
            fat,
            f"{where}.reference_field",
            f"bottom track needs a DVL reference, {ref!r} is {rport.protocol}",
        )
    max_lag = kw.get("max_lag_s", _UUT.max_lag_s)
    if kw.get("lag_s") is not None and kw["lag_s"] > max_lag:
        raise ctx.fail(
            at["lag"],
            f"{where}.lag",
            f"{kw['lag_s']!r} s is beyond max_lag_s ({max_lag!r} s): the reference is "
            "buffered only that far back",
        )
    return UutConfig(**kw)


def load_config(path: str | Path) -> Config:
    """Load and validate a config file.

    Raises:
        ConfigError: anything wrong, naming file, line and key.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the config: {exc}") from None
    return parse_config(text, str(p), base=p.resolve().parent)


def parse_config(text: str, path: str = "<config>", *, base: Path | None = None) -> Config:
    """Validate config text (see :func:`load_config`)."""
    loader = _Loader(text)
    try:
        root = loader.get_single_node()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else 1
        raise ConfigError(
            f"{path}:{line}: not valid YAML: {getattr(exc, 'problem', exc)}"
        ) from None
    finally:
        loader.dispose()
    ctx = _Ctx(path, loader)
    if root is None:
        raise ConfigError(f"{path}:1: the config is empty")
    top = ctx.mapping(root, "")
    known = {"ports", "calibration", "outputs", *TOP_SPEC}
    for key, (kn, _) in top.items():
        if key not in known:
            raise ctx.fail(kn, key, f"unknown key (valid: {', '.join(sorted(known))})")
    if "ports" not in top:
        raise ctx.fail(root, "", "missing required key 'ports'")
    protocols = set(protocol_names())
    ports: list[PortConfig] = []
    for i, node in enumerate(ctx.sequence(top["ports"][1], "ports")):
        where = f"ports[{i}]"
        kw = _section(ctx, node, where, PORT_SPEC, ("name", "url", "protocol", "role"))
        at = _values(ctx, node, where)
        if kw["protocol"] not in protocols:
            raise ctx.fail(
                at["protocol"],
                f"{where}.protocol",
                f"{kw['protocol']!r} is not one of {', '.join(sorted(protocols))}",
            )
        if any(p.name == kw["name"] for p in ports):
            raise ctx.fail(at["name"], f"{where}.name", f"duplicate port name {kw['name']!r}")
        if base is not None and "://" not in kw["url"] and not kw["url"].startswith("/"):
            kw["url"] = str(base / kw["url"])
        ports.append(PortConfig(**kw))
    if not ports:
        raise ctx.fail(top["ports"][1], "ports", "at least one port is needed")
    by_name = {p.name: p for p in ports}
    uuts: list[UutConfig] = []
    cal_nodes = ctx.sequence(top["calibration"][1], "calibration") if "calibration" in top else []
    for i, node in enumerate(cal_nodes):
        where = f"calibration[{i}]"
        kw = _section(ctx, node, where, UUT_SPEC, ("uut", "reference"))
        if base is not None and kw.get("pty") and not kw["pty"].startswith("/"):
            kw["pty"] = str(base / kw["pty"])
        uut = _check_uut(ctx, kw, _values(ctx, node, where), where, by_name)
        if any(u.uut == uut.uut for u in uuts):
            raise ctx.fail(
                _values(ctx, node, where)["uut"], f"{where}.uut", f"{uut.uut!r} is calibrated twice"
            )
        uuts.append(uut)
    outputs = OutputConfig()
    if "outputs" in top:
        kw = _section(ctx, top["outputs"][1], "outputs", OUTPUT_SPEC)
        if base is not None and kw.get("pty") and not kw["pty"].startswith("/"):
            kw["pty"] = str(base / kw["pty"])
        outputs = OutputConfig(**kw)
        ptys = [u.pty for u in uuts if u.pty]
        if outputs.pty in ptys or len(set(ptys)) != len(ptys):
            raise ctx.fail(
                top["outputs"][1],
                "outputs.pty",
                "each output pty must be its own (a log's pty repeats another)",
            )
        if outputs.speed != "each" and "fused" in by_name:
            raise ctx.fail(
                top["outputs"][1],
                "outputs.speed",
                "a port called 'fused' clashes with the fused output: rename the port",
            )
    rest = {
        TOP_SPEC[k][0]: TOP_SPEC[k][1](ctx, vn, k) for k, (_, vn) in top.items() if k in TOP_SPEC
    }
    for key in ("state_path", "control_socket", "status_socket"):
        if base is not None and rest.get(key) and not rest[key].startswith("/"):
            rest[key] = str(base / rest[key])
    return Config(path=path, ports=tuple(ports), calibration=tuple(uuts), outputs=outputs, **rest)


def _dump_section(obj: Any, spec: Mapping[str, tuple[str, Check]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, (attr, _) in spec.items():
        value = getattr(obj, attr)
        if attr == "lag_s" and value is None:
            value = "auto"
        elif isinstance(value, Mapping):
            value = dict(value)
        out[key] = value
    return out


def dump_config(config: Config) -> str:
    """The effective configuration (every key, defaults filled in) as YAML.

    Paths are written as loaded (already resolved), so
    ``parse_config(dump_config(c), c.path) == c``.
    """
    doc: dict[str, Any] = {
        "ports": [_dump_section(p, PORT_SPEC) for p in config.ports],
        "calibration": [_dump_section(u, UUT_SPEC) for u in config.calibration],
        "outputs": _dump_section(config.outputs, OUTPUT_SPEC),
        **_dump_section(config, TOP_SPEC),
    }
    name = " ".join(config.path.splitlines())
    return f"# emlogd effective configuration of {name}\n" + yaml.safe_dump(doc, sort_keys=False)
