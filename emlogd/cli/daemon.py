"""Daemon commands: run, check-config, the control commands and demo."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from drivers import EmlogdError
from emlogd.cli.common import Subparsers, UsageError, config_path, positive_float, two_axis_line
from emlogd.offline.tables import fmt


def cmd_run(args: argparse.Namespace) -> int:
    """Run the daemon in the foreground (systemd runs it this way)."""
    import structlog

    from emlogd.config import load_config
    from emlogd.daemon.logsetup import configure_daemon_logging, flush_log
    from emlogd.daemon.loop import Daemon
    from emlogd.daemon.signals import hold_early, ignore_terminal_stops

    ignore_terminal_stops()  # before any line reaches a terminal it may not write to
    hold_early()  # a SIGHUP (or a stray SIGUSR1) while starting is not the end of it
    cfg = load_config(config_path(args))
    # the corrected NMEA on stdout never shares it with the log: the log goes to stderr
    configure_daemon_logging(cfg.log_format, cfg.log_level, cfg.outputs.stdout)
    log = structlog.get_logger("emlogd")
    try:
        return Daemon(cfg.path, log, state_path=args.state).run()
    finally:
        flush_log()  # the last lines a slow log reader has not taken yet


def cmd_check_config(args: argparse.Namespace) -> int:
    """Validate a config file without starting."""
    from emlogd.config import load_config

    cfg = load_config(args.file)
    ports = ", ".join(f"{p.name} ({p.protocol}, {p.role})" for p in cfg.ports)
    uuts = ", ".join(
        f"{u.port} {u.model} vs {u.reference_port} ({u.reference_field})"
        for u in (c.settings for c in cfg.calibration)
    )
    sys.stdout.write(f"{args.file}: ok\n  ports: {ports}\n  calibration: {uuts or 'none'}\n")
    return 0


def _socket_path(args: argparse.Namespace) -> str:
    if args.socket:
        return str(args.socket)
    from drivers.errors import ConfigError
    from emlogd.config import DEFAULT_PATH, load_config

    path = config_path(args)
    try:
        return load_config(path).control_socket
    except ConfigError as exc:
        if getattr(args, "config", None) or Path(path).exists():
            raise
        raise ConfigError(
            f"{exc}; name the daemon's config with --config FILE or its control socket "
            f"with --socket PATH (the default config is {DEFAULT_PATH})"
        ) from None


def _status_text(resp: dict[str, Any]) -> str:
    """The daemon's ``status`` answer as lines of text: per UUT its state and why, its
    calibration, what it holds and why, its inputs' freshness, its heading and its error
    against the reference; per port whether it is open, never heard, stale or not
    open (and why), with its counts."""
    status = resp.get("status") or {}
    lines = []
    for name, u in (status.get("uuts") or {}).items():
        params = ", ".join(f"{k}={v:+.4f}" for k, v in (u.get("params") or {}).items())
        std = u.get("param_std") or {}
        if params and std:
            params += " (σ " + ", ".join(f"{k} {v:.4f}" for k, v in std.items()) + ")"
        reason = u.get("reason")
        line = (
            f"{name}: {u.get('state')}{f' ({reason})' if reason else ''}, "
            f"reference {u.get('reference')}, {u.get('model')} "
            f"{params or '(no calibration)'}, lag {fmt(u.get('lag_s'), '.2f')} s, "
            f"learning {'on' if u.get('learning_enabled') else 'off'}"
        )
        raw, cor = u.get("rmse_raw"), u.get("rmse_corrected")
        if isinstance(raw, float) and isinstance(cor, float):
            gain = f", {100.0 * (1.0 - cor / raw):.0f} % better" if raw > 0 else ""
            line += (
                f"; RMSE raw {raw:.3f} -> corrected {cor:.3f} m/s over "
                f"{u.get('scored_samples', '?')} samples{gain}"
            )
        imo = u.get("imo")
        if isinstance(imo, dict) and isinstance(imo.get("raw"), dict) and imo["raw"].get("n"):
            cells = []
            for key in ("raw", "corrected"):
                v = imo[key]
                cells.append(
                    f"{key} {100.0 * float(v['fraction']):.1f} % {'meets' if v['meets'] else 'fails'}"
                )
            line += "; IMO A.824 (within 2 % or 0.2 kn) " + ", ".join(cells)
        lines.append(line)
        lines += _detail_lines(u)
    for name, p in (status.get("ports") or {}).items():
        rejects = p.get("rejects") or {}
        total = sum(rejects.values())
        reasons = ", ".join(f"{k} {v}" for k, v in rejects.items() if v)
        state = p.get("state") or ("stale" if p.get("stale") else "")
        if state == "not open":
            state += f" ({p.get('why_closed') or 'unknown reason'})"
        lines.append(
            f"port {name}: {f'{state}, ' if state else ''}{p.get('records')} records, "
            f"{total} rejects{f' ({reasons})' if reasons else ''}"
        )
    if resp.get("state_file"):
        errors = resp.get("state_errors")
        lines.append(
            f"state file {resp['state_file']}: {resp.get('persists', 0)} persists"
            + (f", {errors} errors" if errors else "")
        )
    return "".join(line + "\n" for line in lines)


def _detail_lines(u: dict[str, Any]) -> list[str]:
    """The indented lines under a UUT: what it holds and why, its inputs, its heading,
    its two-axis figures."""
    lines = []
    held = u.get("unidentifiable") or []
    if held:
        why = u.get("identifiability") or "not determinable from the data so far"
        lines.append(f"  holding {', '.join(str(h) for h in held)}: {why}")
    inputs = u.get("inputs")
    if isinstance(inputs, dict) and inputs:
        lines.append(f"  inputs: {_inputs_line(inputs)}")
    heading = u.get("heading")
    if isinstance(heading, dict):
        lines.append(f"  {_heading_line(heading)}")
    two = u.get("two_axis")
    if isinstance(two, dict):
        lines.append(f"  {two_axis_line(two)}")
    return lines


def _inputs_line(inputs: dict[str, Any]) -> str:
    """The freshness of a UUT's reading, reference and heading as the UUT sees them."""
    parts = []
    for role in ("reading", "reference", "heading"):
        i = inputs.get(role)
        if not isinstance(i, dict):
            continue
        if i.get("port") is None:
            parts.append(f"{role} no port yet")
            continue
        age = i.get("age_s")
        text = f"{role} {i['port']} " + ("never heard" if age is None else f"{age:.1f} s ago")
        if i.get("stale"):
            text += " STALE"
        used = i.get("used_age_s")
        if role == "reference" and isinstance(used, int | float):
            text += f" (last used {used:.1f} s ago)"
        parts.append(text)
    return ", ".join(parts)


def _heading_line(h: dict[str, Any]) -> str:
    """A UUT's heading: its port, the variation and its source, refusals, the check."""
    text = f"heading from {h.get('port') or 'no port yet'}"
    var = h.get("variation_deg")
    if isinstance(var, float | int):
        text += f", variation {var:+.2f}° ({h.get('variation_source')})"
    if h.get("refused_magnetic"):
        text += f", {h['refused_magnetic']} magnetic headings refused (no variation)"
    check = h.get("check") or {}
    off = check.get("offset_deg")
    if isinstance(off, float | int):
        text += f", {off:+.1f}° from the course" + (
            " — FLAGGED, not used" if check.get("flagged") else ""
        )
    sources = h.get("sources") or {}
    for port, why in (sources.get("wrong") or {}).items():
        text += f"; {port} NOT USED ({why})"
    for pair in sources.get("unresolved") or []:
        text += f"; {pair} DISAGREE"
    return text


def _change_text(command: str, resp: dict[str, Any]) -> str:
    """The answer to ``freeze``, ``learn`` or ``reset`` as one line of text."""
    uuts = resp.get("uuts")
    names = ", ".join(str(u) for u in uuts) if isinstance(uuts, list) and uuts else ""
    if not names:
        return "no UUT changed\n"
    if command == "freeze":
        states = resp.get("states")
        if not isinstance(states, dict):
            return f"{names}: learning off\n"
        return "".join(f"{n}: {_freeze_text(states.get(n))}\n" for n in uuts or [])
    if command == "learn":
        return f"{names}: learning {'on' if resp.get('learning') else 'off'}\n"
    reset = resp.get("reset")
    if not isinstance(reset, dict):
        return f"{names}: calibration forgotten (uncalibrated until learnt again)\n"
    return "".join(f"{name}: {_reset_text(r)}\n" for name, r in reset.items())


def _freeze_text(state: object) -> str:
    """What a UUT is left doing by ``freeze``, from the state it is left in."""
    if state == "frozen":
        return "frozen (learning off, the calibration applied)"
    if state == "uncalibrated":
        return "learning off; no calibration to apply (raw readings pass through)"
    return f"learning off; {state}"


def _reset_text(r: Any) -> str:
    """What a reset of one UUT cleared and kept, in a few words."""
    cleared = r.get("cleared") if isinstance(r, dict) else None
    kept = r.get("kept") if isinstance(r, dict) else None
    parts = []
    if isinstance(cleared, list) and cleared:
        parts.append("cleared " + ", ".join(str(c) for c in cleared))
    if isinstance(kept, dict):
        lag = kept.get("lag_s")
        lag_text = f"lag {lag:.3f} s" if isinstance(lag, int | float) else "lag not known yet"
        on = "on" if kept.get("learning_enabled") else "off"
        parts.append(f"kept {lag_text}, learning {on}")
    return "; ".join(parts) or "calibration forgotten"


def cmd_control(args: argparse.Namespace) -> int:
    """status / freeze / learn / reset through the daemon's control socket."""
    from emlogd.client import request

    req: dict[str, object] = {"cmd": args.command}
    if getattr(args, "uut", None):
        req["port"] = args.uut
    if args.command == "learn":
        req["on"] = args.state == "on"
    resp = request(_socket_path(args), req)
    if not resp.get("ok"):
        raise EmlogdError(f"the daemon refused: {resp.get('error')}")
    if args.json:
        sys.stdout.write(json.dumps(resp, indent=2, default=str) + "\n")
    elif args.command == "status":
        sys.stdout.write(_status_text(resp))
    else:
        sys.stdout.write(_change_text(args.command, resp))
    return 0


# ---------------------------------------------------------------------------- demo


def cmd_demo(args: argparse.Namespace) -> int:
    """The real daemon calibrating the bundled example live (fake devices on ptys)."""
    from emlogd.offline.demo import run_demo

    if not 1.0 <= args.speed <= 50.0:
        raise UsageError("--speed must be within 1..50")
    run_demo(speed=args.speed, workdir=args.workdir, out=sys.stdout)
    return 0


def add_demo_parser(sub: Subparsers) -> None:
    """The ``demo`` sub-command."""
    p = sub.add_parser(
        "demo",
        help="the daemon calibrating the bundled example, live (about 40 s)",
        description="Serve the bundled example (a simulated figure-8) from three fake serial "
        "devices on ptys, run the real daemon against them, read its corrected NMEA, show the "
        "calibration converging and the error before and after.",
    )
    p.add_argument("--speed", type=positive_float, default=10.0, help="replay speed (default 10x)")
    p.add_argument("--workdir", metavar="DIR", help="keep config, ptys, log and state here")
    p.set_defaults(handler=cmd_demo)


def add_parsers(sub: Subparsers) -> None:
    """The ``run`` and ``check-config`` sub-commands."""
    p = sub.add_parser(
        "run",
        help="run the daemon (foreground; systemd Type=notify)",
        description="Read the sensors, learn the calibration, emit corrected NMEA.",
    )
    p.add_argument("--config", metavar="FILE", help="config file (default /etc/emlogd/emlogd.yaml)")
    p.add_argument("--state", metavar="FILE", help="override the config's state file")
    p.set_defaults(handler=cmd_run)

    p = sub.add_parser(
        "check-config",
        help="validate a config file without starting",
        description="Load and check a config file as `emlogd run` would (every key, its "
        "range and the ports each calibration names) without opening a device; print the "
        "config with every default filled in, or each problem with its file, line and key.",
    )
    p.add_argument("file", help="config file")
    p.set_defaults(handler=cmd_check_config)


def add_control_parsers(sub: Subparsers) -> None:
    """The ``status``, ``freeze``, ``reset`` and ``learn`` sub-commands."""
    for name, text in (
        ("status", "show the running daemon's calibration and ports"),
        ("freeze", "stop learning (all UUTs or --uut) and persist"),
        ("reset", "forget the calibration (all UUTs or --uut)"),
        ("learn", "switch learning on or off"),
    ):
        p = sub.add_parser(name, help=text, description=text + " (through the control socket).")
        if name == "learn":
            p.add_argument(
                "state",
                choices=["on", "off"],
                help="on: learn from the incoming data; off: keep the current parameters",
            )
        p.add_argument("--uut", metavar="PORT", help="one UUT only")
        p.add_argument("--config", metavar="FILE", help="config file naming the control socket")
        p.add_argument("--socket", metavar="PATH", help="control socket path")
        p.add_argument("--json", action="store_true", help="raw JSON answer")
        p.set_defaults(handler=cmd_control)
