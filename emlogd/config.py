"""The daemon's YAML configuration, validated at load.

Every key is declared once, as a dataclass field made with
:func:`emlogd.pipeline.keys.key` (its default, check, unit and doc): the pipeline's
keys on the pipeline's own settings (:class:`~emlogd.pipeline.settings.PortSettings`,
:class:`~emlogd.pipeline.settings.UutSettings`,
:class:`~emlogd.pipeline.integrity.Envelope`), the daemon's on the dataclasses here.
Validation, :func:`emlogd.configdump.dump_config` and
:func:`emlogd.configdump.key_table` (README's "Configuration reference") read those
declarations, and the loaded config holds the pipeline's settings themselves, complete.

Every error names the file, the line and the key, e.g.
``emlogd.yaml:14: calibration[0].model: 'EM5' is not one of EM1, EM2, EM3, EM4``.
Unknown keys, duplicate keys, wrong types and bad values are all errors; relative
paths (serial devices given as files, the state file, the pty link) are resolved
against the config file's directory, so an example config works from anywhere.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

from drivers import Use, get_decoder, protocols_for
from drivers.errors import ConfigError
from drivers.io.port import url_problem
from emlogd.configclash import path_clash, tcp_clash
from emlogd.confignodes import Ctx, Loader, build_section, refuse_unknown, section
from emlogd.configyaml import YAML_FAILURES, yaml_depth_error, yaml_why
from emlogd.fileio import read_text_bounded
from emlogd.pipeline.fusion import FusionSettings
from emlogd.pipeline.keys import (
    Check,
    InvalidValueError,
    boolean,
    entries,
    group,
    ipv4_port,
    key,
    literal,
    number,
    opt_string,
    string,
)
from emlogd.pipeline.settings import PortSettings, RefField, UutSettings

DEFAULT_PATH = "/etc/emlogd/emlogd.yaml"

MAX_CONFIG_BYTES = 256 * 1024
"""Longest config file read, bytes (the example vehicle's is under 5 KiB). A longer
one, or anything not a regular file (a FIFO would block the read), is refused
unparsed: the pure-Python YAML parser takes seconds per 100 KiB of a hostile file."""

Role = Literal["uut", "reference", "aux"]
Speed = Literal["each", "fused", "both"]
LogFormat = Literal["auto", "json", "console"]
LogLevel = Literal["debug", "info", "warning", "error"]

_UUT = UutSettings(port="", reference_port="")
"""The pipeline's defaults, for the ``outputs`` keys that reach every UUT."""
_TALKER = r"[A-Z]{2}"
_FILE_PATH = r"(?s)(?!(?:.*/)?\.{0,2}$).+"
"""A path that names a file by its form: not ending in ``/``, ``.`` or ``..``, which name
a directory (the state file's would be moved aside by the first save, with its files)."""


_ANY_URL = string(what="pyserial URL")


def _url(v: object) -> str:
    url: str = _ANY_URL(v)
    problem = url_problem(url)
    if problem is not None:
        raise InvalidValueError(problem)
    return url


@dataclass(frozen=True, slots=True)
class PortConfig:
    """One input port (``ports`` list): the pipeline's settings and the device's."""

    settings: PortSettings = group(PortSettings, required=True)
    url: str = key(
        check=Check(_url, "pyserial URL"),
        path=True,
        doc="Any pyserial URL: `/dev/ttyUSB0`, `socket://address:port` (an IP address: a "
        "host name is refused), ... but `rfc2217://` (its open waits in the daemon's one "
        "thread); a relative path is the config file's directory's.",
    )
    role: Role = key(
        check=literal(Role),
        doc="uut: an EMlog to calibrate; reference: a DVL, GNSS or EMlog reference; aux: "
        "headings only.",
    )
    baud: int = key(9600, check=number(50, 4_000_000, integer=True), unit="bit/s", doc="Baud rate.")
    rate_hz: float | None = key(
        None,
        check=number(0.0, 1000.0, lo_open=True, optional=True),
        unit="Hz",
        doc="The device's sentence rate, as documentation; null: unknown.",
    )
    rest_s: float = key(
        0.02,
        check=number(0.0, 1.0),
        unit="s",
        doc="Reference and aux ports: once readable, the port is left this long, then read "
        "at the daemon's next wake-up, at the latest 0.02 s later (an ensemble's lines in one "
        "read, stamped at the end of the rest). Keep it well under the time the port takes "
        "to fill the 4 KiB tty buffer, and it plus 0.02 s under the gap between bursts; "
        "0 disables. UUT ports never rest.",
    )

    @property
    def name(self) -> str:
        """The port's name."""
        return self.settings.name

    @property
    def protocol(self) -> str:
        """What the device speaks."""
        return self.settings.protocol


@dataclass(frozen=True, slots=True)
class UutOutputs:
    """One log's own outputs (``calibration`` keys the daemon alone reads)."""

    pty: str | None = key(
        None,
        check=opt_string("path"),
        path=True,
        doc="This log's own output pty: its sentences go there instead of the shared outputs.",
    )
    tcp: str | None = key(
        None, check=ipv4_port, doc="This log's own NMEA over TCP, instead of the shared outputs."
    )
    udp: str | None = key(
        None, check=ipv4_port, doc="This log's own UDP destination, instead of the shared outputs."
    )


@dataclass(frozen=True, slots=True)
class UutConfig:
    """Calibration of one EMlog (``calibration`` list): the pipeline's settings, complete
    (:func:`emlogd.settings.pipeline_from_config` passes them as they are), and the
    log's own outputs."""

    settings: UutSettings = group(UutSettings, required=True)
    outputs: UutOutputs = group(UutOutputs)

    @property
    def uut(self) -> str:
        """The EMlog's port."""
        return self.settings.port

    @property
    def reference(self) -> str:
        """The reference's port."""
        return self.settings.reference_port


@dataclass(frozen=True, slots=True)
class OutputConfig:
    """Where the corrected NMEA goes (``outputs``)."""

    pty: str | None = key(
        "/run/emlogd/emlog0",
        check=opt_string("path"),
        path=True,
        doc="The pty the autopilot opens, published at this symlink; null: none.",
    )
    pty_mode: int = key(
        0o660, check=number(0, 0o777, integer=True), text="0660", doc="The pty's file mode."
    )
    pty_group: str | None = key(
        None,
        check=opt_string("group"),
        doc="The pty's group (its readers, e.g. the autopilot's user); null: unchanged.",
    )
    tcp: str | None = key(
        None,
        check=ipv4_port,
        doc="NMEA over TCP, e.g. `127.0.0.1:10110` (several clients); `0.0.0.0:10110` or "
        "`:10110` listens on every interface.",
    )
    tcp_max_clients: int = key(
        32,
        check=number(1, 1024, integer=True),
        doc="Most clients of a TCP output; a newcomer beyond it evicts the client stalled "
        "longest, else the most recently connected.",
    )
    tcp_max_pending_bytes: int = key(
        64 * 1024,
        check=number(1024, 64 * 1024 * 1024, integer=True),
        unit="bytes",
        doc="A TCP client with more output pending (unsent or unacknowledged) is closed.",
    )
    tcp_stall_s: float = key(
        10.0,
        check=number(0.0, 3600.0, lo_open=True),
        unit="s",
        doc="A TCP client that takes nothing this long while output is pending is closed.",
    )
    udp: str | None = key(None, check=ipv4_port, doc="NMEA over UDP, e.g. `192.168.1.255:10110`.")
    stdout: bool = key(
        False, check=boolean, doc="NMEA on stdout too (the log then goes to stderr)."
    )
    talker: str = key(
        _UUT.talker,
        check=string(_TALKER, "two uppercase letters"),
        doc="The talker of the corrected sentences (a log's own `talker` overrides it).",
    )
    maker: str = key(
        _UUT.maker,
        check=string(r"[A-Z]{3}", "three uppercase letters"),
        doc="The maker of the proprietary sentences (`$PEMLS` status, `$PEMLF` fused).",
    )
    status_sentence_interval_s: float = key(
        _UUT.status_sentence_interval_s,
        check=number(0.0, 3600.0),
        unit="s",
        doc="Each log's status sentence at most this often.",
    )
    speed: Speed = key(
        "each",
        check=literal(Speed),
        doc="each: every log's corrected sentences (two logs under one talker on one output "
        "are refused: give each its own `talker` or output); fused: one speed for the autopilot, the "
        "inverse-variance weighted mean of the healthy logs that agree, else invalid "
        "(`$PEMLF` says which are used and why the others are not); both: the two.",
    )
    fused_talker: str = key(
        FusionSettings().talker,
        check=string(_TALKER, "two uppercase letters"),
        doc="The talker of the fused speed's sentences.",
    )
    fused_gate_chi2: float = key(
        FusionSettings().gate_chi2,
        check=number(1.0, 1000.0),
        doc="Two logs whose smoothed difference, squared over their consistency variances, "
        "exceeds this disagree and are never averaged (6.63: 1 % for one degree of freedom).",
    )
    fused_hold_s: float = key(
        FusionSettings().hold_s,
        check=number(0.0, 3600.0),
        unit="s",
        doc="A log with an implausible reading (spike, dropout, babble) stays out of the fused "
        "speed this long.",
    )
    fused_rejoin_s: float = key(
        FusionSettings().rejoin_s,
        check=number(0.0, 3600.0),
        unit="s",
        doc="Two disagreeing logs are fused again after agreeing this long.",
    )
    fused_max_current_mps: float = key(
        FusionSettings().max_current_mps,
        check=number(0.0, 10.0),
        unit="m/s",
        doc="The largest current: between two disagreeing logs, one further than this (+0.9 "
        "m/s of GNSS noise) from the speed over ground is left out.",
    )


@dataclass(frozen=True, slots=True)
class Config:
    """A validated configuration."""

    path: str
    ports: tuple[PortConfig, ...]
    calibration: tuple[UutConfig, ...]
    outputs: OutputConfig = field(default_factory=OutputConfig)
    state_path: str = key(
        "/var/lib/emlogd/state.yaml",
        name="state_file",
        check=string(_FILE_PATH, "a file's path (not ending in /, . or ..)"),
        path=True,
        doc="The persisted calibrations (written atomically, with a `.bak`).",
    )
    control_socket: str = key(
        "/run/emlogd/control.sock",
        check=string(what="path"),
        path=True,
        doc="The control socket (`emlogd status`, `freeze`, `reset`, `learn`).",
    )
    status_socket: str | None = key(
        None,
        check=opt_string("path"),
        path=True,
        doc="A read-only socket (`status` only, mode 0666) for any local user; null: none.",
    )
    log_format: LogFormat = key(
        "auto",
        check=literal(LogFormat),
        doc="auto: json when the log does not go to a terminal.",
    )
    log_level: LogLevel = key("info", check=literal(LogLevel), doc="The least level logged.")
    status_log_interval_s: float = key(
        10.0,
        check=number(0.5, 3600.0),
        unit="s",
        doc="The periodic `status` log event (per-port records, rejects by reason) this often.",
    )

    def port(self, name: str) -> PortConfig:
        """The port called ``name``."""
        for p in self.ports:
            if p.name == name:
                return p
        raise KeyError(name)


SECTIONS: tuple[tuple[str, type], ...] = (
    ("ports[].", PortConfig),
    ("calibration[].", UutConfig),
    ("outputs.", OutputConfig),
    ("", Config),
)
"""Each section's prefix in a key's full name, and its dataclass."""


def heading_expected(heading: str, reference_field: str, reference_protocol: str) -> bool:
    """A heading is known to come for a UUT: a heading port is named, the reference is a
    DVL output that carries one, or the reference is GNSS (which needs one anyway).

    ``current: auto`` estimates the current exactly then: in the water frame the
    calibration is the sensor's (without it a current ends up in the scale and bias);
    without a heading the current cannot be observed at all.
    """
    if heading != "auto" or reference_field == "gnss":
        return True
    return reference_field in ("bottom", "water") and get_decoder(reference_protocol).heading


def _either(use: Use) -> str:
    """The protocols that can serve ``use``, for a message: ``pd6/pd13``."""
    return "/".join(protocols_for(use))


def _needs(field_: RefField) -> str:
    """What a reference field needs, for the message refusing a reference port."""
    return {
        "bottom": "bottom track needs a DVL",
        "water": f"water track (:WS) needs a {_either('water')}",
        "speed": f"speed needs an EMlog ({_either('speed')})",
        "gnss": "gnss needs an NMEA 0183 (RMC/VTG)",
    }[field_]


def _check_uut(
    ctx: Ctx,
    kw: dict[str, Any],
    at: Mapping[str, yaml.Node],
    where: str,
    by_name: Mapping[str, PortConfig],
) -> None:
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
    if by_name[uut].protocol not in protocols_for("uut"):
        raise ctx.fail(
            at["uut"], f"{where}.uut", f"port {uut!r} must speak {_either('uut')} (VHW/VBW)"
        )
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
    if rport.protocol not in protocols_for(field_):
        raise ctx.fail(
            fat,
            f"{where}.reference_field",
            f"{_needs(field_)} reference, {ref!r} is {rport.protocol}",
        )
    heading = kw.get("heading", _UUT.heading)
    if heading != "auto" and heading not in by_name:
        raise ctx.fail(at["heading"], f"{where}.heading", f"no port named {heading!r}")
    max_lag = kw.get("max_lag_s", _UUT.max_lag_s)
    if kw.get("lag") is not None and kw["lag"] > max_lag:
        raise ctx.fail(
            at["lag"],
            f"{where}.lag",
            f"{kw['lag']!r} s is beyond max_lag_s ({max_lag!r} s): the reference is "
            "buffered only that far back",
        )


def load_config(path: str | Path) -> Config:
    """Load and validate a config file.

    Raises:
        ConfigError: anything wrong, naming file, line and key.
    """
    p = Path(path)
    try:
        text = read_text_bounded(p, MAX_CONFIG_BYTES)
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the config: {exc}") from None
    return parse_config(text, str(p), base=p.resolve().parent)


def parse_config(text: str, path: str = "<config>", *, base: Path | None = None) -> Config:
    """Validate config text (see :func:`load_config`)."""
    deep = yaml_depth_error(text)
    if deep:
        raise ConfigError(f"{path}:1: not valid YAML: {deep}")
    loader = Loader(text)
    try:
        root = loader.get_single_node()
    except YAML_FAILURES as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else 1
        raise ConfigError(
            f"{path}:{line}: not valid YAML: {getattr(exc, 'problem', None) or yaml_why(exc)}"
        ) from None
    finally:
        loader.dispose()
    ctx = Ctx(path, loader, base)
    if root is None:
        raise ConfigError(f"{path}:1: the config is empty")
    top = ctx.mapping(root, "")
    top_keys = {e.name: e for e in entries(Config)}
    known = {"ports", "calibration", "outputs", *top_keys}
    for k, (kn, _) in top.items():
        if k not in known:
            refuse_unknown(ctx, kn, k, k, sorted(known))
    if "ports" not in top:
        raise ctx.fail(root, "", "missing required key 'ports'")
    ports = _parse_ports(ctx, top["ports"][1])
    by_name = {p.name: p for p in ports}
    cals: list[dict[str, Any]] = []
    cal_nodes = ctx.sequence(top["calibration"][1], "calibration") if "calibration" in top else []
    for i, node in enumerate(cal_nodes):
        where = f"calibration[{i}]"
        kw, at = section(ctx, node, where, UutConfig, "calibration[].")
        _check_uut(ctx, kw, at, where, by_name)
        if any(c["uut"] == kw["uut"] for c in cals):
            raise ctx.fail(at["uut"], f"{where}.uut", f"{kw['uut']!r} is calibrated twice")
        cals.append(kw)
    outputs = (
        _parse_outputs(ctx, top["outputs"][1], cals, by_name)
        if "outputs" in top
        else OutputConfig()
    )
    uuts: list[UutConfig] = []
    for kw in cals:  # what a log takes from the rest of the config
        reference = by_name[kw["reference"]]
        if kw["current"] == "auto":
            kw["current"] = heading_expected(
                kw.get("heading", _UUT.heading),
                kw.get("reference_field", _UUT.reference_field),
                reference.protocol,
            )
        if kw["talker"] is None:
            kw["talker"] = outputs.talker
        extra: dict[tuple[str, ...], Any] = {
            ("settings", "ref_stale_s"): reference.settings.stale_timeout_s,
            ("settings", "maker"): outputs.maker,
            ("settings", "status_sentence_interval_s"): outputs.status_sentence_interval_s,
        }
        uuts.append(build_section(UutConfig, kw, extra))
    _check_one_speed_per_talker(ctx, top["outputs"][1] if "outputs" in top else None, uuts, outputs)
    rest = {
        top_keys[k].attrs[0]: ctx.value(vn, k, top_keys[k])
        for k, (_, vn) in top.items()
        if k in top_keys
    }
    cfg = Config(path=path, ports=tuple(ports), calibration=tuple(uuts), outputs=outputs, **rest)
    _refuse_path_clash(ctx, top, cfg)
    return cfg


def _refuse_path_clash(ctx: Ctx, top: dict[str, tuple[yaml.Node, yaml.Node]], cfg: Config) -> None:
    """Refuse two sockets, the state file or two ptys at one path (:func:`path_clash`)."""
    clash, name, section = path_clash(cfg)
    if clash:
        raise ctx.fail(top.get(section, (None, None))[1], name, clash)


def _parse_ports(ctx: Ctx, node: yaml.Node) -> list[PortConfig]:
    """The ``ports`` section: at least one, each name once."""
    ports: list[PortConfig] = []
    for i, item in enumerate(ctx.sequence(node, "ports")):
        where = f"ports[{i}]"
        kw, at = section(ctx, item, where, PortConfig, "ports[].")
        if any(p.name == kw["name"] for p in ports):
            raise ctx.fail(at["name"], f"{where}.name", f"duplicate port name {kw['name']!r}")
        ports.append(build_section(PortConfig, kw))
    if not ports:
        raise ctx.fail(node, "ports", "at least one port is needed")
    return ports


def _parse_outputs(
    ctx: Ctx, node: yaml.Node, cals: Sequence[Mapping[str, Any]], by_name: Mapping[str, Any]
) -> OutputConfig:
    """The ``outputs`` section: no two TCP outputs on one port (:func:`tcp_clash`), no
    port named ``fused`` beside a fused output."""
    kw, _ = section(ctx, node, "outputs", OutputConfig, "outputs.")
    outputs: OutputConfig = build_section(OutputConfig, kw)
    clash = tcp_clash([t for t in (outputs.tcp, *(c.get("tcp") for c in cals)) if t])
    if clash:
        raise ctx.fail(node, "outputs.tcp", clash)
    if outputs.speed != "each" and "fused" in by_name:
        raise ctx.fail(
            node,
            "outputs.speed",
            "a port called 'fused' clashes with the fused output: rename the port",
        )
    return outputs


def _check_one_speed_per_talker(
    ctx: Ctx, node: yaml.Node | None, uuts: Sequence[UutConfig], outputs: OutputConfig
) -> None:
    """Refuse two logs' speeds under one talker on one declared output: an autopilot
    reading `$VWVHW` from two logs cannot tell them apart (a config without an
    ``outputs`` section, written for replay, is not checked).

    A log with outputs of its own writes only there; every other log's corrected
    sentences (``speed`` each or both) go to the shared outputs; with ``speed: fused``
    only the fused speed is emitted.
    """
    if node is None:
        # no outputs declared (a config for replay and the offline commands): nothing
        # reaches an autopilot through the default output unless it is run as a daemon,
        # and configs written for replay keep working
        return
    seen: dict[tuple[str, str], str] = {}
    for dest, talker, who in _speed_routes(uuts, outputs):
        other = seen.setdefault((dest, talker), who)
        if other != who:
            raise ctx.fail(
                node,
                "outputs.speed",
                f"{other} and {who} both send talker {talker!r} to {dest}: an autopilot "
                "cannot tell the two speeds apart; give each log its own talker and output "
                "(calibration[].talker and .pty/.tcp/.udp) or set outputs.speed: fused",
            )


def _speed_routes(uuts: Sequence[UutConfig], outputs: OutputConfig) -> list[tuple[str, str, str]]:
    """(output, talker, which log) for every log's corrected speed the config emits."""
    routes = []
    shared = [
        f"{kind} {dest}"
        for kind, dest in (("pty", outputs.pty), ("tcp", outputs.tcp), ("udp", outputs.udp))
        if dest
    ] + (["stdout"] if outputs.stdout else [])
    if outputs.speed != "fused":
        for c in uuts:
            own = [
                f"{kind} {dest}"
                for kind, dest in (
                    ("pty", c.outputs.pty),
                    ("tcp", c.outputs.tcp),
                    ("udp", c.outputs.udp),
                )
                if dest
            ]
            for dest in own or shared or ["the shared outputs (replay --out)"]:
                routes.append((dest, c.settings.talker, f"log {c.uut!r}"))
    return routes
