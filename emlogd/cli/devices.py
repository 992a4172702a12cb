"""Device commands: ``dump`` (decode), ``record`` (capture live ports), ``fake`` (serve a capture)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import re
import signal
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from drivers import DecoderOptions, make_decoder, protocol_names
from drivers.base import NMEA_MAX_LENGTH, Decoder
from drivers.records import Rejected
from emlogd.cli.common import (
    Subparsers,
    UsageError,
    key_arg,
    positive_float,
    progress,
    progress_done,
)
from emlogd.jsonio import to_jsonable
from emlogd.pipeline.settings import PortSettings, UutSettings

_SNIFF_CHUNK = 4096


def _decoder_options(args: argparse.Namespace) -> DecoderOptions:
    return DecoderOptions(
        checksum="optional" if getattr(args, "checksum_optional", False) else "required",
        max_length=getattr(args, "max_length", None) or DecoderOptions().max_length,
    )


def _sniff_protocol(path: Path) -> str:
    """Guess the protocol of a raw (non-capture) file from its first bytes (the binary
    formats by their decoders' ``HEADER``)."""
    from drivers import rdi_pd0, rdi_pd45

    with open(path, "rb") as f:
        head = f.read(_SNIFF_CHUNK)
    if rdi_pd0.HEADER in head[:64]:
        return "pd0"
    if head.startswith(rdi_pd45.HEADER):
        return "pd4"
    text = head.lstrip()
    if text[:1] == b":":
        return "pd6"
    if b"$" in head or b"!" in head:
        return "nmea0183"
    raise UsageError(f"{path}: cannot tell the protocol from the content; pass --protocol")


def _is_capture(path: Path) -> bool:
    import gzip

    from drivers.io.capture import MAGIC

    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rb") as f:
            first = f.readline(256)
    except (gzip.BadGzipFile, EOFError):
        return False
    return bool(first.rstrip(b"\r\n") == MAGIC.encode("ascii"))


# ---------------------------------------------------------------------------- dump


def _dump_records(args: argparse.Namespace) -> Iterator[tuple[float | None, str, object]]:
    """Yield (receive time, port, record) for the dump command; fills ``args._decoders``."""
    path = Path(args.file)
    options = _decoder_options(args)
    decoders: dict[str, tuple[str, Decoder[Any]]] = {}
    args._decoders = decoders
    if _is_capture(path):
        from drivers.io.capture import CaptureReader

        reader = CaptureReader(path)
        for name, proto in reader.ports.items():
            proto = args.protocol or proto
            decoders[name] = (proto, make_decoder(proto, name, errors="yield", options=options))
        for rec in reader:
            _, dec = decoders[rec.port]
            for out in dec.feed(rec.data):
                yield rec.t, rec.port, out
    else:
        proto = args.protocol or _sniff_protocol(path)
        name = path.stem
        dec = make_decoder(proto, name, errors="yield", options=options)
        decoders[name] = (proto, dec)
        with open(path, "rb") as f:
            while chunk := f.read(65536):
                for out in dec.feed(chunk):
                    yield None, name, out
    for name, (_, dec) in decoders.items():
        for out in dec.flush():
            yield None, name, out


def _own_sentence(rec: object, kinds: dict[str, str]) -> str | None:
    """``PEMLS``/``PEMLF`` (with the maker given) when ``rec`` is one of emlogd's own
    proprietary sentences that the NMEA decoder left undecoded, else None."""
    if not isinstance(rec, Rejected) or rec.reason != "unknown_sentence" or rec.raw[:1] != b"$":
        return None
    address = rec.raw[1:].partition(b",")[0].decode("ascii", "replace")
    return address if address in kinds else None


def _format_record(rec: object) -> str:
    d = to_jsonable(rec)
    kind = d.pop("type", type(rec).__name__) if isinstance(d, dict) else type(rec).__name__
    if not isinstance(d, dict):
        return f"{kind} {d}"
    parts = [f"{k}={json.dumps(v, separators=(',', ':'))}" for k, v in d.items() if v is not None]
    return f"{kind} " + " ".join(parts)


def cmd_dump(args: argparse.Namespace) -> int:
    """Decode a capture or a raw log of one protocol; print records and counters."""
    out = sys.stdout
    own_kinds = {f"P{args.maker}S": "EmlogdStatus", f"P{args.maker}F": "EmlogdFused"}
    own: dict[str, dict[str, int]] = {}
    for t, port, rec in _dump_records(args):
        kind = _own_sentence(rec, own_kinds)
        if kind is not None:  # emlogd's own status or fused sentence: known, not a reject
            assert isinstance(rec, Rejected)
            counts = own.setdefault(port, {})
            counts[kind] = counts.get(kind, 0) + 1
            body = rec.raw.decode("ascii", "replace").partition("*")[0]
            rec = {"type": own_kinds[kind], "sentence": kind, "fields": body.split(",")[1:]}
        if args.json:
            line = {"t": t, "port": port, "record": to_jsonable(rec)}
            out.write(json.dumps(line, separators=(",", ":")) + "\n")
        else:
            ts = "-" if t is None else f"{t:.6f}"
            out.write(f"{ts} {port} {_format_record(rec)}\n")
    summary: dict[str, dict[str, Any]] = {}
    for name, (proto, dec) in args._decoders.items():
        counters = dec.counters.as_dict()
        mine = own.get(name, {})
        if mine:
            rejects = dict(counters["rejects"])
            rejects["unknown_sentence"] -= sum(mine.values())
            counters = {**counters, "rejects": rejects, "emlogd": mine}
        summary[name] = {"protocol": proto, **counters}
    if args.json:
        out.write(json.dumps({"summary": summary}, separators=(",", ":")) + "\n")
    else:
        out.write(_summary_table(summary))
    return 0


_DEFAULT_MAKER = next(f.default for f in dataclasses.fields(UutSettings) if f.name == "maker")


def _maker_arg(value: str) -> str:
    """dump --maker: three uppercase letters (like the outputs key maker)."""
    if not re.fullmatch(r"[A-Z]{3}", value):
        raise argparse.ArgumentTypeError(f"expected three uppercase letters, not {value!r}")
    return value


def _summary_table(summary: dict[str, dict[str, Any]]) -> str:
    lines = [f"{'port':<12} {'protocol':<9} {'records':>8} {'rejected':>8}  reasons"]
    for name, s in summary.items():
        rejects: dict[str, int] = s["rejects"]
        total = sum(rejects.values())
        reasons = ", ".join(f"{k}={v}" for k, v in rejects.items() if v) or "-"
        lines.append(f"{name:<12} {s['protocol']:<9} {s['records']:>8} {total:>8}  {reasons}")
        mine = s.get("emlogd")
        if mine:
            lines.append(
                f"{'':<12} emlogd's own: " + ", ".join(f"${k} {v}" for k, v in mine.items())
            )
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- record


def _parse_port_spec(spec: str) -> tuple[str, str, int, str]:
    """Parse ``NAME=URL[,baud=N][,protocol=P]``."""
    name, sep, rest = spec.partition("=")
    if not sep or not name or not rest:
        raise UsageError(f"--port {spec!r}: expected NAME=URL[,baud=N][,protocol=P]")
    url, *opts = rest.split(",")
    baud, proto = 9600, "nmea0183"
    for opt in opts:
        key, sep, value = opt.partition("=")
        if key == "baud" and sep and value.isdigit():
            baud = int(value)
        elif key == "protocol" and sep and value in protocol_names():
            proto = value
        else:
            raise UsageError(
                f"--port {spec!r}: bad option {opt!r} (baud=N, protocol={'|'.join(protocol_names())})"
            )
    return name, url, baud, proto


@contextlib.contextmanager
def _on_sigterm(action: Callable[[], object]) -> Iterator[None]:
    """Within the block, SIGTERM calls ``action`` (to end the work cleanly)."""

    def handler(signum: int, frame: FrameType | None) -> None:
        action()

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def cmd_record(args: argparse.Namespace) -> int:
    """Capture live ports into a capture v1 file until Ctrl-C, SIGTERM or --duration."""
    from drivers.io.record import PortSpec, record

    specs = [PortSpec(*_parse_port_spec(s)) for s in args.port]
    stopped: list[bool] = []
    try:
        with _on_sigterm(lambda: stopped.append(True)):
            counts = record(
                specs,
                args.out,
                duration_s=args.duration,
                stale_timeout_s=args.stale_timeout,
                should_stop=lambda: bool(stopped),
                on_event=lambda ev: sys.stderr.write(f"{ev.port}: {ev.kind} {ev.detail}\n"),
                on_progress=lambda c: progress(
                    "recording: " + ", ".join(f"{k}={v}" for k, v in c.items())
                ),
            )
    except ValueError as exc:
        raise UsageError(f"--port: {exc}") from None
    finally:
        progress_done()
    sys.stderr.write(
        f"wrote {args.out}: " + ", ".join(f"{k} {v} records" for k, v in counts.items()) + "\n"
    )
    return 0


# ---------------------------------------------------------------------------- fake


def _fake_links(args: argparse.Namespace, ports: dict[str, str]) -> dict[str, str]:
    """Port -> link from ``--link NAME=PATH`` (repeatable) or ``--link PATH [--port NAME]``."""
    links: dict[str, str] = {}
    plain: list[str] = []
    for spec in args.link:
        name, sep, path = spec.partition("=")
        if sep and name in ports and path:
            if name in links:
                raise UsageError(f"--link {name}=...: port {name} given twice")
            links[name] = path
        elif sep and path and "/" not in name:  # NAME=PATH naming a port the capture lacks
            raise UsageError(
                f"--link {spec}: {args.capture} has no port {name!r} (has {', '.join(ports)})"
            )
        else:
            plain.append(spec)
    if plain and (links or len(plain) > 1):
        raise UsageError("several ports: give each as --link NAME=PATH")
    if args.port is not None and not plain:
        raise UsageError("--port goes with one --link PATH")
    if plain:
        if args.port is None:
            if len(ports) != 1:
                raise UsageError(
                    f"{args.capture} has ports {', '.join(ports)}: choose one with --port "
                    "(or serve several with --link NAME=PATH each)"
                )
            port = next(iter(ports))
        elif args.port not in ports:
            raise UsageError(f"{args.capture} has no port {args.port!r} (has {', '.join(ports)})")
        else:
            port = args.port
        links[port] = plain[0]
    return links


def cmd_fake(args: argparse.Namespace) -> int:
    """Serve ports of a capture on pty symlinks, like the real devices would, on one clock."""
    from drivers.io.capture import read_ports
    from drivers.io.fake import FakeCapture

    ports = read_ports(args.capture)
    links = _fake_links(args, ports)
    speed = None if args.fast else args.speed

    def ended() -> None:
        sys.stderr.write(
            f"emlogd fake: {args.capture} has ended ({device.sent_records} records sent); "
            "the links stay open, silent, until Ctrl-C or SIGTERM\n"
        )
        sys.stderr.flush()

    device = FakeCapture(args.capture, links, speed=speed, loop=args.loop, on_end=ended)

    for port, link in links.items():
        sys.stderr.write(f"emlogd fake: serving {port} from {args.capture} on {link}\n")
    sys.stderr.flush()
    with _on_sigterm(device.stop):
        try:
            device.run()
        except KeyboardInterrupt:
            device.stop()
    return 0


def add_parsers(sub: Subparsers) -> None:
    """The ``dump``, ``record`` and ``fake`` sub-commands."""
    p = sub.add_parser(
        "dump",
        help="decode a capture or a raw log of one protocol",
        description="Decode a capture (port protocols from its header) or a raw log/binary "
        "file of one protocol. Prints one line per record (JSON lines with --json), "
        "then counters per port and reject reason.",
    )
    p.add_argument("file", help="capture v1 file, or a raw NMEA/PD6 log or PD0/PD4/PD5 binary")
    p.add_argument(
        "--protocol",
        choices=protocol_names(),
        help="protocol of a raw file (guessed from its content if omitted)",
    )
    p.add_argument("--json", action="store_true", help="JSON lines, then a summary object")
    p.add_argument(
        "--checksum-optional",
        action="store_true",
        help="accept NMEA sentences without *hh (a wrong checksum is still rejected)",
    )
    p.add_argument(
        "--maker",
        default=_DEFAULT_MAKER,
        type=_maker_arg,
        metavar="XXX",
        help=f"emlogd's proprietary maker code: $P+XXX+S (status) and $P+XXX+F (fused) "
        f"are shown as emlogd's own, not rejects (default {_DEFAULT_MAKER}, the outputs key maker)",
    )
    p.add_argument(
        "--max-length",
        type=key_arg(PortSettings, "max_length"),
        metavar="N",
        help=f"longest accepted text line incl. CR LF (default {NMEA_MAX_LENGTH}, the NMEA limit)",
    )
    p.set_defaults(handler=cmd_dump)

    p = sub.add_parser(
        "record",
        help="capture live serial ports into a capture file",
        description="Capture live ports (any pyserial URL: /dev/ttyUSB0, loop://, "
        "socket://host:port, spy://...) into a capture v1 file until Ctrl-C or SIGTERM.",
    )
    p.add_argument(
        "--port",
        action="append",
        required=True,
        metavar="NAME=URL[,baud=N][,protocol=P]",
        help="a port to record (repeat for several); protocol defaults to nmea0183",
    )
    p.add_argument("--out", required=True, metavar="FILE.cap", help="capture file to write")
    p.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--stale-timeout",
        type=positive_float,
        default=5.0,
        metavar="S",
        help="report a port silent for S seconds (default 5)",
    )
    p.set_defaults(handler=cmd_record)

    p = sub.add_parser(
        "fake",
        help="serve a capture's ports on pty symlinks (fake serial devices)",
        description="Replay ports of a capture into pseudo-terminals published at their "
        "--link, with the original timing (all ports on one clock, keeping their offsets), "
        "scaled (--speed X) or as fast as the readers take it (--fast). Serving starts when "
        "every link has a reader.",
    )
    p.add_argument("capture", help="capture v1 file")
    p.add_argument(
        "--link",
        required=True,
        action="append",
        metavar="PATH|NAME=PATH",
        help="symlink to the pty slave: PATH for one port (--port), NAME=PATH for port NAME "
        "(repeat to serve several ports)",
    )
    p.add_argument(
        "--port", help="with --link PATH: the port to serve (if the capture has several)"
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--speed", type=positive_float, default=1.0, metavar="X", help="X times real time"
    )
    g.add_argument("--fast", action="store_true", help="as fast as the reader takes it")
    p.add_argument("--loop", action="store_true", help="start the whole capture again at its end")
    p.set_defaults(handler=cmd_fake)
