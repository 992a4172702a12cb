"""What the offline commands share once the arguments are parsed: reading the captures,
the warnings about what was skipped, and scoring against a simulated trial's truth."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from calib.metrics import ImoVerdict
from drivers.io.capture import REORDER_WINDOW_S
from drivers.records import KNOT_MPS
from emlogd.cli.common import progress, progress_done
from emlogd.offline.dataset import Recording
from emlogd.offline.jobs import OfflineError, load_captures
from emlogd.offline.tables import fmt
from emlogd.pipeline.integrity import Envelope
from emlogd.pipeline.settings import UutSettings

if TYPE_CHECKING:
    from calib.models import Params
    from emlogd.offline.simulate import Truth, TruthScore


def truth_of(args: argparse.Namespace, uuts: Sequence[str]) -> Truth | None:
    """``--truth DIR``: the simulated trial's truth (checked to know ``uuts``), else None."""
    if not getattr(args, "truth", None):
        return None
    from emlogd.offline.simulate import read_truth

    truth = read_truth(args.truth)
    for port in uuts:
        truth.emlog(port)
    return truth


def score_rec(truth: Truth | None, port: str, rec: Recording, params: Params) -> TruthScore | None:
    """A capture's raw and calibrated readings scored against the truth (None without one)."""
    if truth is None:
        return None
    from calib.models import correct_array
    from emlogd.offline.simulate import score_truth

    return score_truth(truth, port, rec.t_read, rec.raw, correct_array(params, rec.raw))


def imo_cell(v: ImoVerdict | None) -> str:
    """An IMO A.824(19) verdict in a few characters: ``97.5 % meets``, ``61.0 % fails``."""
    if v is None or v.n == 0:
        return "-"
    return f"{100.0 * v.fraction:.1f} % {'meets' if v.meets else 'fails'}"


def truth_cells(score: TruthScore | None) -> list[str]:
    """Against the truth: RMSE raw, calibrated or corrected, the floor (m/s); IMO raw, cal."""
    if score is None:
        return []
    return [
        fmt(score.rmse_raw, ".4f"),
        fmt(score.rmse_corrected, ".4f"),
        fmt(score.rmse_floor, ".4f"),
        imo_cell(score.imo_raw),
        imo_cell(score.imo_corrected),
    ]


def warn_skips(command: str, skips: dict[str, dict[str, object]]) -> None:
    """One warning line on stderr per capture with malformed records skipped, and one per
    step back of the logger's clock (the records after it shifted)."""
    for path, rep in skips.items():
        steps = rep.get("steps")
        for step in steps if isinstance(steps, list) else []:
            sys.stderr.write(
                f"emlogd {command}: warning: {path}:{step['line']}: the time steps back "
                f"{step['step_s']:.3f} s (the logger's clock set back): the records from "
                "there on are shifted to follow the ones before\n"
            )
        n = rep.get("skipped", 0)
        if not isinstance(n, int) or n == 0:
            continue
        first = rep.get("first")
        where = ""
        if isinstance(first, list) and first:
            where = f" (first at line {first[0]['line']}: {first[0]['error']})"
        sys.stderr.write(
            f"emlogd {command}: warning: {path}: {n} malformed record"
            f"{'s' if n != 1 else ''} skipped{where}; --strict fails instead\n"
        )


def warn_internal(command: str, where: str, report: dict[str, object]) -> None:
    """One warning line when records failed unforeseen and were contained."""
    n = report.get("count", 0)
    first = report.get("first")
    if not isinstance(n, int) or n == 0 or not isinstance(first, list) or not first:
        return
    f = first[0]
    sys.stderr.write(
        f"emlogd {command}: warning: {where}: {n} record{'s' if n != 1 else ''} failed "
        f"and {'were' if n != 1 else 'was'} skipped (first on port {f['port']}: {f['error']}; "
        f"data {f['data']!r})\n"
    )


def warn_recs(command: str, recs: Sequence[Recording]) -> None:
    """The warnings of the captures read: malformed records skipped, records that failed."""
    warn_skips(command, capture_skips(recs))
    for r in recs:
        warn_internal(command, r.path, r.internal)


def capture_skips(recs: Sequence[Recording]) -> dict[str, dict[str, object]]:
    """Per capture, what its reading skipped (the JSON outputs' ``capture_skips``)."""
    return {r.path: r.skips for r in recs}


def load(paths: Sequence[str], settings: UutSettings, args: argparse.Namespace) -> list[Recording]:
    """Read the captures; without ``--uut-source`` a UUT that sends no VHW is read from VBW.

    Malformed records are skipped unless ``--strict`` (the command warns about them
    once it has succeeded: a failure stays one line).
    """
    strict = bool(getattr(args, "strict", False))
    window = float(getattr(args, "reorder_window", REORDER_WINDOW_S))
    recs = load_captures(paths, settings, progress=progress, strict=strict, reorder_window_s=window)
    if not getattr(args, "uut_source", None) and not any(r.raw.size for r in recs):
        recs = load_captures(
            paths,
            dataclasses.replace(settings, uut_source="VBW"),
            progress=progress,
            strict=strict,
            reorder_window_s=window,
        )
    progress_done()
    return recs


def warn_lag(command: str, note: str) -> None:
    """The lag fallback's note, once, on stderr (the lag line on stdout says ``fallback``)."""
    if note:
        sys.stderr.write(f"emlogd {command}: warning: {note}\n")


def check_writable(option: str, path: str) -> None:
    """Fail before the work when ``path``'s directory does not exist or is not writable
    (a runtime error naming the option and the path, exit 1)."""
    parent = Path(path).parent
    if not parent.is_dir():
        raise OfflineError(f"{option} {path}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise OfflineError(f"{option} {path}: the directory {parent} is not writable")


UNIT_GAIN_TOLERANCE = 0.15
"""A fitted gain ``1 + m`` within this fraction of the ratio of knots to m/s (1.944) or of
its inverse (0.514) is told as a unit mislabelled: the log's or the reference's speed in
knots taken for m/s, or the reverse."""


def warn_envelope(command: str, params: Params, envelope: Envelope) -> None:
    """On stderr: a calibration (fitted or loaded) outside the UUT's envelope (what the daemon would refuse), and a
    gain that tells a unit mislabelled: within :data:`UNIT_GAIN_TOLERANCE` of the ratio of
    knots to m/s (or its inverse), or outside the envelope and inside it once divided by
    that ratio."""
    why = envelope.check(params)
    gain = 1.0 + params.m
    if any(
        abs(gain / r - 1.0) <= UNIT_GAIN_TOLERANCE
        or (why and abs(gain / r - 1.0) <= envelope.max_abs_m)
        for r in (KNOT_MPS, 1.0 / KNOT_MPS)
    ):
        sys.stderr.write(
            f"emlogd {command}: warning: the log reads {gain:.2f}× the reference: the log's "
            "or the reference's speed in knots taken for m/s, or the reverse?\n"
        )
    if why:
        sys.stderr.write(
            f"emlogd {command}: warning: the calibration is outside the envelope ({why}): "
            "the daemon refuses such a calibration\n"
        )
