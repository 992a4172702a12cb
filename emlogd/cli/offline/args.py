"""The offline commands' shared arguments: each option declared once, and the UUT's
settings they give."""

from __future__ import annotations

import argparse
import dataclasses
import math
from typing import Any, get_args

from calib.models import MODEL_NAMES
from drivers.io.capture import REORDER_WINDOW_S
from emlogd.cli.common import UsageError, key_arg
from emlogd.pipeline.settings import RefField, UutSentence, UutSettings

STRICT_HELP = "fail at the first malformed capture record instead of counting and skipping it"

REORDER_HELP = (
    "capture records up to S seconds out of time order are put back in order "
    f"(default {REORDER_WINDOW_S:g}; 0: each must follow the last)"
)

JSON_HELP = "one JSON document (README keys)"
"""``--json``'s help where the command has no output of its own to name."""


def uut_settings(args: argparse.Namespace, **over: Any) -> UutSettings:
    """The UUT of an offline job, as the daemon's settings (defaults from the declarations)."""
    kw: dict[str, Any] = {
        "port": args.uut,
        "reference_port": args.ref,
        "current": bool(getattr(args, "current", False)),
    }
    given = {
        "reference_field": args.ref_field,
        "uut_source": getattr(args, "uut_source", None),
        "component": "magnitude" if getattr(args, "magnitude", False) else None,
        "heading": getattr(args, "heading", None),
        "magnetic_variation_deg": getattr(args, "variation", None),
        "model": getattr(args, "model", None),
        "r_raw_mps": getattr(args, "r_raw", None),
    }
    kw.update({k: v for k, v in given.items() if v is not None})
    kw.update(over)
    try:
        return UutSettings(**kw)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def window_arg(value: str) -> float:
    """A duration in seconds, at least 0 (``--reorder-window``, calibrate ``--average``)."""
    try:
        x = float(value)
    except ValueError:
        x = math.nan
    if not (math.isfinite(x) and x >= 0.0):
        raise argparse.ArgumentTypeError(f"expected seconds ≥ 0, not {value!r}")
    return x


def captures_arg(p: argparse.ArgumentParser, help: str = "capture v1 files") -> None:
    """The positional ``CAPTURE ...``: the capture files a command reads."""
    p.add_argument("captures", nargs="+", metavar="CAPTURE", help=help)


def json_arg(p: argparse.ArgumentParser, help: str = JSON_HELP) -> None:
    """``--json``: the command's output as one JSON document."""
    p.add_argument("--json", action="store_true", help=help)


def capture_args(p: argparse.ArgumentParser) -> None:
    """``--strict`` and ``--reorder-window``: how a command reads captures."""
    p.add_argument("--strict", action="store_true", help=STRICT_HELP)
    p.add_argument(
        "--reorder-window",
        type=window_arg,
        default=REORDER_WINDOW_S,
        metavar="S",
        help=REORDER_HELP,
    )


def uut_source_arg(p: argparse.ArgumentParser) -> None:
    """``--uut-source``: the sentence the UUT's speed is read from."""
    p.add_argument("--uut-source", choices=get_args(UutSentence), help="UUT sentence (default VHW)")


def lag_arg(p: argparse.ArgumentParser, *, auto: bool = True) -> None:
    """``--lag``: the UUT's latency; with ``auto`` measured unless given, else the value
    that overrides a saved calibration's."""
    if auto:
        p.add_argument(
            "--lag",
            type=key_arg(UutSettings, "lag_s"),
            default=None,
            metavar="auto|SECONDS",
            help="UUT latency (default auto: cross-correlation)",
        )
    else:
        p.add_argument(
            "--lag",
            type=key_arg(UutSettings, "lag_s", allow_auto=False),
            default=None,
            metavar="SECONDS",
            help="override the saved lag (default: the file's; [0, 30] like the config key lag)",
        )


def truth_arg(p: argparse.ArgumentParser, scored: str) -> None:
    """``--truth DIR``: a simulated trial's directory to score ``scored`` against."""
    p.add_argument(
        "--truth",
        metavar="DIR",
        help=f"a simulated trial's directory: score {scored} against its true speed through water",
    )


def pairing_args(p: argparse.ArgumentParser, required: bool = True) -> None:
    """``--uut``, ``--ref`` and ``--ref-field``: the EMlog and the reference it is paired
    with (not ``required`` where a calibration file names them)."""
    p.add_argument(
        "--uut",
        required=required,
        metavar="PORT",
        help="the EMlog's port" + ("" if required else " (default: the parameters file's)"),
    )
    p.add_argument(
        "--ref",
        required=required,
        metavar="PORT",
        help="the reference's port" + ("" if required else " (default: the parameters file's)"),
    )
    p.add_argument(
        "--ref-field",
        choices=get_args(RefField),
        default="bottom" if required else None,
        help="reference: DVL bottom track (default), DVL water track, an EMlog's speed, "
        "or GNSS speed and course (RMC/VTG) projected on the hull with the heading",
    )


def model_arg(p: argparse.ArgumentParser) -> None:
    """``--model``: the error model (default: the calibration's declared one)."""
    default = next(f.default for f in dataclasses.fields(UutSettings) if f.name == "model")
    p.add_argument("--model", choices=MODEL_NAMES, help=f"error model (default {default})")


def water_frame(p: argparse.ArgumentParser) -> None:
    """``--current``, ``--heading`` and ``--variation``: the water frame."""
    p.add_argument(
        "--current",
        action="store_true",
        help="estimate the sea current too (the water frame; needs a heading)",
    )
    p.add_argument(
        "--heading",
        metavar="auto|PORT",
        help="heading source (default auto: the reference's, else the UUT's VHW, else any)",
    )
    p.add_argument(
        "--variation",
        type=key_arg(UutSettings, "magnetic_variation_deg"),
        metavar="DEG",
        help="magnetic variation, + east, for magnetic headings without one",
    )


def common_offline(p: argparse.ArgumentParser, json_doc: bool = True) -> None:
    """What calibrate, crossval and report share: the water frame, the UUT's sentence and
    component, the lag, how captures are read, and (with ``json_doc``) ``--json``."""
    water_frame(p)
    uut_source_arg(p)
    p.add_argument(
        "--magnitude",
        action="store_true",
        help="compare horizontal speed magnitudes instead of longitudinal speeds",
    )
    lag_arg(p)
    capture_args(p)
    if json_doc:
        json_arg(p)
