"""What the offline commands read from captures: a UUT's inputs exactly as the daemon sees them.

Each capture is streamed through the daemon's own pipeline (:class:`~emlogd.pipeline.core.Pipeline`:
the same decoders, reference routing, glitch filters, heading selection, magnetic
variation and burst handling) with a :class:`~emlogd.pipeline.uut.Recorder` attached to
the UUT: the result is a :class:`Recording` — the UUT's readings, its reference along
the hull with validity, and the UUT's heading at each reference sample. Alignment at a
lag (:meth:`Recording.aligned`) applies the one alignment rule of
:mod:`emlogd.pipeline.align` to the whole recording at once.

:func:`record_captures` decodes several captures in parallel processes (the decoding
is the cost; the results are small arrays). :func:`concat_usable` and
:func:`block_means` join the usable aligned samples of several captures, each sample or
averaged over blocks, for the offline fits.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from calib.lsq import block_average
from calib.models import FloatArray
from drivers.io.capture import REORDER_WINDOW_S, CaptureReader, capture_name
from emlogd.contain import Containment
from emlogd.offline import ProgressFn
from emlogd.pipeline.align import DEFAULT_MAX_GAP_S, interpolate
from emlogd.pipeline.core import Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings

BoolArray = npt.NDArray[np.bool_]


class CaptureContentError(KeyError):
    """A capture lacks a port the job needs (the message lists what it has)."""


@dataclass(frozen=True, eq=False)
class Aligned:
    """A UUT's readings paired with the reference and heading at ``t − lag``.

    Attributes:
        t: reading receive times, s, shape (N,).
        raw: readings, m/s.
        ref: reference along the hull at ``t − lag``, m/s (nan: none by the rule).
        heading: the UUT's heading at ``t − lag``, degrees (nan: unknown).
        lag_s: the lag applied, s.
    """

    t: FloatArray
    raw: FloatArray
    ref: FloatArray
    heading: FloatArray
    lag_s: float

    def usable(self, *, heading: bool = False) -> BoolArray:
        """Samples with a reference (and a heading when ``heading``)."""
        ok = np.isfinite(self.ref) & np.isfinite(self.raw)
        return ok & np.isfinite(self.heading) if heading else ok

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True, eq=False)
class Recording:
    """One UUT's inputs from one capture.

    Attributes:
        path: the capture file.
        uut: the UUT port.
        ports: port name -> protocol (the capture's header).
        t_read: reading receive times, s.
        raw: readings of the learnt sentence, m/s (fresh and in range).
        t_ref: reference sample times, s.
        v_ref: reference along the hull, m/s (nan when invalid).
        ok_ref: reference validity (after the glitch filter).
        heading: the UUT's heading at each reference sample, degrees (nan: unknown).
        counters: port -> decoder counters (``records``, ``rejects`` by reason).
        uut_counters: the UUT's own counters (out of range, backlog...).
        t_start: first record time, s (nan for an empty capture).
        t_end: last record time, s.
        skips: the malformed records skipped (``CaptureReader.skip_report``).
        internal: the records whose handling failed and was contained
            (:meth:`~emlogd.contain.Containment.report`; also counted as ``internal``
            rejects in :attr:`counters`).
        heading_info: the pipeline's heading status at the end (``Pipeline.heading_status``:
            port, variation and its source, refused magnetic headings, the check).
    """

    path: str
    uut: str
    ports: dict[str, str]
    t_read: FloatArray
    raw: FloatArray
    t_ref: FloatArray
    v_ref: FloatArray
    ok_ref: BoolArray
    heading: FloatArray
    counters: dict[str, dict[str, object]]
    uut_counters: dict[str, int]
    t_start: float
    t_end: float
    skips: dict[str, object] = dataclasses.field(default_factory=dict)
    internal: dict[str, object] = dataclasses.field(default_factory=dict)
    heading_info: dict[str, object] = dataclasses.field(default_factory=dict)

    @property
    def name(self) -> str:
        """The capture's file name without ``.cap``/``.gz`` (:func:`capture_name`)."""
        return capture_name(self.path)

    def aligned(self, lag_s: float, max_gap_s: float = DEFAULT_MAX_GAP_S) -> Aligned:
        """Readings paired with the reference and heading at ``t − lag`` (the alignment
        rule, the gap from the reference's cadence as the daemon's)."""
        q = self.t_read - lag_s
        ref = interpolate(self.t_ref, self.v_ref, self.ok_ref, q, max_gap_s, cadence=True)
        hd_ok = np.isfinite(self.heading)
        heading = interpolate(
            self.t_ref, self.heading, hd_ok, q, max_gap_s, angular=True, cadence=True
        )
        return Aligned(self.t_read, self.raw, ref, heading, float(lag_s))


class _Collector:
    """The :class:`~emlogd.pipeline.uut.Recorder` that fills a :class:`Recording`."""

    def __init__(self) -> None:
        self.t_read: list[float] = []
        self.raw: list[float] = []
        self.t_ref: list[float] = []
        self.v_ref: list[float] = []
        self.ok_ref: list[bool] = []
        self.heading: list[float] = []

    def reference(
        self, t: float, v_mps: float | None, valid: bool, heading_deg: float | None
    ) -> None:
        self.t_ref.append(t)
        self.v_ref.append(math.nan if v_mps is None else v_mps)
        self.ok_ref.append(valid and v_mps is not None)
        self.heading.append(math.nan if heading_deg is None else heading_deg)

    def reading(self, t: float, raw_mps: float) -> None:
        self.t_read.append(t)
        self.raw.append(raw_mps)


def record_capture(
    path: str | Path,
    settings: UutSettings,
    *,
    progress: ProgressFn | None = None,
    strict: bool = False,
    reorder_window_s: float = REORDER_WINDOW_S,
) -> Recording:
    """Stream one capture through the daemon's pipeline and record the UUT's inputs.

    Args:
        path: capture v1 file (``.cap`` or ``.cap.gz``).
        settings: the UUT (port, reference port and field, heading source...).
        progress: called now and then with the fraction of the file read.
        strict: a malformed record raises instead of being counted and skipped.
        reorder_window_s: records this far (s) out of time order are put back in order
            (:class:`~drivers.io.capture.CaptureReader`).

    Raises:
        CaptureContentError: the capture lacks the UUT, reference or heading port.
        CaptureFormatError: a malformed header, or with ``strict`` a malformed record
            (names the line).
    """
    reader = CaptureReader(
        path, errors="raise" if strict else "skip", reorder_window_s=reorder_window_s
    )
    needed = [settings.port, settings.reference_port]
    if settings.heading != "auto":
        needed.append(settings.heading)
    missing = [p for p in needed if p not in reader.ports]
    if missing:
        raise CaptureContentError(
            f"{path}: no port {', '.join(missing)} (has {', '.join(reader.ports) or 'none'})"
        )
    ports = [PortSettings(name, proto) for name, proto in reader.ports.items()]
    quiet = dataclasses.replace(settings, learn=False, lag_s=0.0)
    pipeline = Pipeline(ports, [quiet])
    cal = pipeline.uuts[settings.port].cal
    col = _Collector()
    cal.recorder = col
    cal.record_only = True
    size = max(Path(path).stat().st_size, 1)
    t_first = t_last = math.nan
    contain = Containment()
    for n, (t, port, data, line) in enumerate(reader.received()):
        if n == 0:
            t_first = t
        t_last = t
        try:
            pipeline.feed(t, port, data)
        except Exception as exc:  # contained: one record is lost, not the capture
            contain.failed(pipeline, port, data, exc, t)
        if progress is not None and n % 50_000 == 0:
            progress(f"reading {Path(path).name}", min(line * 60 / size, 1.0))
    try:
        pipeline.flush()
    except Exception as exc:  # contained: the end of the capture, not the capture
        contain.failed(pipeline, "", b"", exc, t_last)
    ports_status = pipeline.port_status()
    return Recording(
        path=str(path),
        uut=settings.port,
        ports=dict(reader.ports),
        t_read=np.asarray(col.t_read, dtype=np.float64),
        raw=np.asarray(col.raw, dtype=np.float64),
        t_ref=np.asarray(col.t_ref, dtype=np.float64),
        v_ref=np.asarray(col.v_ref, dtype=np.float64),
        ok_ref=np.asarray(col.ok_ref, dtype=np.bool_),
        heading=np.asarray(col.heading, dtype=np.float64),
        counters={
            name: {"records": v["records"], "rejects": v["rejects"]}
            for name, v in ports_status.items()
        },
        uut_counters=cal.counters.as_dict(),
        t_start=t_first,
        t_end=t_last,
        skips=reader.skip_report(),
        internal=contain.report(),
        heading_info=pipeline.heading_status(settings.port),
    )


def _record_job(args: tuple[str, UutSettings, bool, float]) -> Recording:
    return record_capture(args[0], args[1], strict=args[2], reorder_window_s=args[3])


def record_captures(
    paths: Sequence[str | Path],
    settings: UutSettings,
    *,
    workers: int | None = None,
    progress: ProgressFn | None = None,
    strict: bool = False,
    reorder_window_s: float = REORDER_WINDOW_S,
) -> list[Recording]:
    """:func:`record_capture` for each capture, in parallel processes when there are several.

    Args:
        paths: capture files, in the order the result keeps.
        settings: the UUT.
        workers: processes (default: one per core, at most one per capture).
        progress: called after each capture with the fraction done.
        strict: a malformed record raises instead of being counted and skipped.
        reorder_window_s: as :func:`record_capture`'s.
    """
    n = len(paths)
    if workers is None:
        workers = min(os.cpu_count() or 1, n)
    if workers <= 1 or n <= 1:
        out = []
        for i, p in enumerate(paths):
            out.append(
                record_capture(p, settings, strict=strict, reorder_window_s=reorder_window_s)
            )
            if progress is not None:
                progress(f"read {Path(p).name}", (i + 1) / max(n, 1))
        return out
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {
            pool.submit(_record_job, (str(p), settings, strict, reorder_window_s)): i
            for i, p in enumerate(paths)
        }
        done: dict[int, Recording] = {}
        # said as each capture is read (not in the order given: the first may be the longest)
        for fut in as_completed(futures):
            i = futures[fut]
            done[i] = fut.result()
            if progress is not None:
                progress(f"read {Path(paths[i]).name}", len(done) / n)
        return [done[i] for i in range(n)]


def block_means(pairs: Sequence[Aligned], current: bool, window_s: float) -> tuple[FloatArray, ...]:
    """Each capture's usable samples averaged over ``window_s`` blocks, then joined."""
    parts = []
    for p in pairs:
        m = p.usable(heading=current)
        parts.append(
            block_average(p.t[m], p.raw[m], p.ref[m], p.heading[m] if current else None, window_s)
        )
    return tuple(
        np.concatenate([getattr(a, k) for a in parts]) if parts else np.empty(0)
        for k in ("t", "raw", "ref", "heading_deg")
    )


def concat_usable(pairs: Sequence[Aligned], current: bool) -> tuple[FloatArray, ...]:
    """``(t, raw, ref, heading)`` of every usable aligned sample of ``pairs``, in order.

    Usable: a reading with a reference, and a heading too when ``current``.
    """
    masks = [p.usable(heading=current) for p in pairs]
    cat = [
        np.concatenate([getattr(p, k)[m] for p, m in zip(pairs, masks, strict=True)])
        if pairs
        else np.empty(0)
        for k in ("t", "raw", "ref", "heading")
    ]
    return tuple(np.asarray(c, dtype=np.float64) for c in cat)
