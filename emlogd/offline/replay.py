"""``emlogd replay``: the daemon's pipeline run over captures.

The captures are read in the order given (each is sorted by time; the pipeline's
state carries across files), every record goes through the same
:class:`~emlogd.pipeline.core.Pipeline` as live data, the corrected sentences go to a
sink, and the calibration can be loaded from and persisted to a state file. With
``speed`` the replay is paced at that multiple of real time, otherwise it runs as
fast as it can.

With the truth of a simulated trial (:func:`~emlogd.offline.simulate.read_truth`),
every UUT reading that was emitted corrected is scored against the true speed
through the water: the emitted sentence is decoded as a receiver would read it and
paired with the raw reading it corrects (same receive time, the UUT's learnt
sentence).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np

from calib.models import FloatArray
from drivers import EmlogdError, make_decoder
from drivers.io.capture import REORDER_WINDOW_S, CaptureReader, read_ports
from drivers.nmea0183 import NmeaDecoder
from drivers.records import Rejected
from emlogd.contain import Containment
from emlogd.offline import ProgressFn
from emlogd.offline.replay_twoaxis import AthwartScorer
from emlogd.offline.simfaults import WindowScore, score_windows
from emlogd.offline.simulate import Truth, TruthScore, score_truth
from emlogd.pipeline.core import Emit, Event, Output, Pipeline

TICK_S = 0.5
"""Record time between two stale checks (the daemon's loop ticks at a similar rate)."""


class NoMatchingPortError(EmlogdError):
    """A capture none of whose ports the config declares: replaying it would do nothing."""


def unmatched_ports(pipeline: Pipeline, paths: Sequence[str | Path]) -> dict[str, list[str]]:
    """Per capture, the ports its header declares that the pipeline has no decoder for
    (captures whose ports all match are left out).

    Raises:
        NoMatchingPortError: a capture none of whose ports is configured (names the
            capture's ports and the configured ones).
        CaptureFormatError: a malformed capture header.
    """
    out: dict[str, list[str]] = {}
    for path in paths:
        ports = list(read_ports(path))
        missing = [p for p in ports if p not in pipeline.decoders]
        if ports and len(missing) == len(ports):
            raise NoMatchingPortError(
                f"{path}: none of its ports ({', '.join(ports)}) is in the config "
                f"(configured: {', '.join(pipeline.decoders) or 'none'}); replaying it "
                "would do nothing: declare them under ports"
            )
        if missing:
            out[str(path)] = missing
    return out


@dataclass(slots=True)
class ReplayResult:
    """What a replay did (JSON: :meth:`to_dict`, keys documented in the README)."""

    status: dict[str, object]
    records: int = 0
    emitted: int = 0
    persisted: int = 0
    events: deque[Event] = field(default_factory=lambda: deque(maxlen=1000))
    event_counts: dict[str, int] = field(default_factory=dict)
    unknown_ports: dict[str, int] = field(default_factory=dict)
    elapsed_s: float = 0.0
    span_s: float = 0.0
    capture_skips: dict[str, dict[str, object]] = field(default_factory=dict)
    truth: dict[str, TruthScore] = field(default_factory=dict)
    """Per UUT, its emitted speeds scored against the truth (replay with ``truth``)."""
    truth_windows: dict[str, list[WindowScore]] = field(default_factory=dict)
    """Per UUT, the same per window of :data:`~emlogd.offline.simfaults.WINDOW_S`."""
    two_axis_truth: dict[str, dict[str, object]] = field(default_factory=dict)
    """Per UUT that learns two axes, its VBW scored on both axes against the truth
    (:class:`~emlogd.offline.replay_twoaxis.AthwartScorer`)."""
    internal: dict[str, object] = field(default_factory=dict)
    """The records whose handling failed and was contained (:meth:`Containment.report`)."""

    def to_dict(self) -> dict[str, object]:
        """``{"uuts": {...}, "ports": {...}, ...}`` (README: ``replay --json``)."""
        uuts = self.status.get("uuts", {})
        ports = self.status.get("ports", {})
        assert isinstance(uuts, dict) and isinstance(ports, dict)
        return {
            "uuts": {
                name: {
                    "rmse_raw": u["rmse_raw"],
                    "rmse_corrected": u["rmse_corrected"],
                    "scored_samples": u["scored_samples"],
                    "params": u["params"],
                    "param_std": u["param_std"],
                    "state": u["state"],
                    "freezes": u["freezes"],
                    "lag_s": u["lag_s"],
                    "nis_mean": u["nis_mean"],
                    "samples_learnt": u["samples_learnt"],
                    "truth": self.truth[name].to_dict() if name in self.truth else None,
                    "truth_worst_window": _worst_window(self.truth_windows.get(name)),
                    **({"two_axis": u["two_axis"]} if "two_axis" in u else {}),
                    **(
                        {"two_axis_truth": self.two_axis_truth[name]}
                        if name in self.two_axis_truth
                        else {}
                    ),
                }
                for name, u in uuts.items()
            },
            "ports": {
                name: {"records": p["records"], "rejects": p["rejects"]}
                for name, p in ports.items()
            },
            "records": self.records,
            "emitted": self.emitted,
            "persisted": self.persisted,
            "unknown_ports": dict(self.unknown_ports),
            "events": dict(self.event_counts),
            "elapsed_s": round(self.elapsed_s, 3),
            "span_s": round(self.span_s, 3),
            "capture_skips": dict(self.capture_skips),
            "internal": dict(self.internal),
        }


def _worst_window(windows: Sequence[WindowScore] | None) -> dict[str, object] | None:
    """The window whose emitted speeds are furthest above raw's against the truth
    (``replay --json``'s ``truth_worst_window``), or None without one."""
    if not windows:
        return None
    w = max(windows, key=lambda x: x.ratio)
    return {
        "t0": round(w.t0, 3),
        "n_samples": w.n,
        "rmse_raw": round(w.rmse_raw, 5),
        "rmse_corrected": round(w.rmse_corrected, 5),
        "ratio": round(w.ratio, 4) if math.isfinite(w.ratio) else None,
        "windows": len(windows),
    }


def replay(
    pipeline: Pipeline,
    paths: Sequence[str | Path],
    *,
    sink: BinaryIO | None = None,
    on_emit: Callable[[list[Emit]], None] | None = None,
    speed: float | None = None,
    on_persist: Callable[[Output], None] | None = None,
    on_event: Callable[[Event], None] | None = None,
    progress: ProgressFn | None = None,
    truth: Truth | None = None,
    sleep: Callable[[float], None] = time.sleep,
    monotonic: Callable[[], float] = time.monotonic,
    strict: bool = False,
    reorder_window_s: float = REORDER_WINDOW_S,
) -> ReplayResult:
    """Feed every record of ``paths`` to ``pipeline``.

    Args:
        pipeline: the pipeline (built from the config, warm-started from a state).
        paths: capture v1 files, replayed in this order.
        sink: where the corrected sentences go (CR LF appended); None drops them.
        on_emit: also called with every batch of emitted sentences (``--out FILE.cap``).
        speed: pace at this multiple of real time; None: as fast as possible.
        on_persist: called with each output that asks for a persist.
        on_event: called for each pipeline event.
        progress: called as (message, fraction of the current file).
        truth: a simulated trial's truth: score each UUT's emitted speeds against it
            (:attr:`ReplayResult.truth`).
        sleep: the sleep function (tests).
        monotonic: the clock used for pacing (tests).
        strict: a malformed record raises; otherwise it is counted and skipped
            (``capture_skips``: per capture, the count by reason and the first lines).
            A record whose handling fails unforeseen is counted as an ``internal`` reject
            of its port and kept in :attr:`ReplayResult.internal`; the replay goes on.
        reorder_window_s: records this far (s) out of time order are put back in order
            (``capture_skips``' ``reordered``; :class:`~drivers.io.capture.CaptureReader`).

    Returns:
        Counters and the pipeline's final status.

    Raises:
        CaptureFormatError: a malformed capture header, or with ``strict`` any malformed
            record (names the file and line).
        TruthError: with ``truth``, a UUT that is not one of the simulated EMlogs.
        NoMatchingPortError: a capture none of whose ports is configured (checked
            before anything is fed; :func:`unmatched_ports`).
    """
    unmatched_ports(pipeline, paths)
    started = time.perf_counter()
    result = ReplayResult(status={})
    scorer: _TruthScorer | None = None
    if truth is not None:
        for name in pipeline.uuts:
            truth.emlog(name)  # a UUT the truth does not know fails now, not after the replay
        scorer = _TruthScorer(pipeline)
    run = _Run(
        pipeline, result, sink, on_persist, on_event, on_emit, scorer, speed, sleep, monotonic
    )
    for path in paths:
        reader = CaptureReader(
            path, errors="raise" if strict else "skip", reorder_window_s=reorder_window_s
        )
        run.file(Path(path), reader, progress)
    run.finish()
    if scorer is not None and truth is not None:
        result.truth = scorer.scores(truth)
        result.truth_windows = scorer.windows(truth)
        if scorer.athwart is not None:
            result.two_axis_truth = scorer.athwart.scores(truth)
    result.elapsed_s = time.perf_counter() - started
    result.span_s = run.span()
    return result


@dataclass(slots=True)
class _Run:
    """One replay under way: the records of each file in turn through the pipeline (paced
    with ``speed``), what they make delivered, a record's failure contained."""

    pipeline: Pipeline
    result: ReplayResult
    sink: BinaryIO | None
    on_persist: Callable[[Output], None] | None
    on_event: Callable[[Event], None] | None
    on_emit: Callable[[list[Emit]], None] | None
    scorer: _TruthScorer | None
    speed: float | None
    sleep: Callable[[float], None]
    monotonic: Callable[[], float]
    t_first: float | None = None
    """The first record's time of the current run of captures in time order."""
    t_last: float = 0.0
    pace0: tuple[float, float] | None = None
    """The first record's time and the clock's then (pacing)."""
    t_tick: float = -float("inf")
    spanned: float = 0.0
    """The time spanned before the current run of records in time order (a capture
    earlier than the one before it starts a new one)."""
    contain: Containment = field(default_factory=Containment)

    def file(self, path: Path, reader: CaptureReader, progress: ProgressFn | None) -> None:
        """Every record of one capture, in time order."""
        result, decoders = self.result, self.pipeline.decoders
        size = max(path.stat().st_size, 1)
        first: float | None = None  # this capture's first record's time
        for t, port, data, line in reader.received():
            if port not in decoders:
                result.unknown_ports[port] = result.unknown_ports.get(port, 0) + 1
                continue
            if first is None:
                first = t
                if self.t_first is None:
                    self.t_first = t
                elif t < self.t_last:  # a capture earlier than the one before it:
                    self.spanned += self.t_last - self.t_first  # its time spanned too,
                    self.t_first, self.t_tick, self.pace0 = t, -float("inf"), None
                    # ticked and paced from its own first record on
            if self.speed is not None:
                self._pace(t, self.speed)
            self._feed(t, port, data)
            if t - self.t_tick >= TICK_S:
                self.t_tick = t
                self._tick(t)
            result.records += 1
            self.t_last = t
            if progress is not None and result.records % 20_000 == 0:
                progress(f"replay {path.name}", min(line * 60.0 / size, 1.0))
        result.capture_skips[str(path)] = reader.skip_report()

    def span(self) -> float:
        """The time the records spanned, s: from the first to the last, each run of
        captures in time order added up (never negative)."""
        return self.spanned + (self.t_last - self.t_first if self.t_first is not None else 0.0)

    def _pace(self, t: float, speed: float) -> None:
        """Wait until record time ``t`` is due at ``speed`` times real time."""
        if self.pace0 is None:
            self.pace0 = (t, self.monotonic())
        wait = self.pace0[1] + (t - self.pace0[0]) / speed - self.monotonic()
        if wait > 0.0:
            self.sleep(wait)

    def _feed(self, t: float, port: str, data: bytes) -> None:
        try:
            out = self.pipeline.feed(t, port, data)
        except Exception as exc:  # contained: one record is lost, not the replay
            self.contain.failed(self.pipeline, port, data, exc, t)
            return
        if out.emits or out.events or out.persist:
            if self.scorer is not None:
                self.scorer.emitted(out.emits)
            self._deliver(out)

    def _tick(self, t: float) -> None:
        try:
            out = self.pipeline.tick(t)
        except Exception as exc:  # contained like a record's
            self.contain.failed(self.pipeline, "", b"", exc, t)
            return
        if out.events or out.persist:
            self._deliver(out)

    def finish(self) -> None:
        """The pipeline flushed (a failure contained), the result's status and failures."""
        try:
            last = self.pipeline.flush()
        except Exception as exc:  # contained: the end of the input, not the replay
            self.contain.failed(self.pipeline, "", b"", exc, self.t_last)
            last = Output()
        self.result.internal = self.contain.report()
        if self.scorer is not None:
            self.scorer.emitted(last.emits)
        self._deliver(last)
        self.result.status = self.pipeline.status()

    def _deliver(self, out: Output) -> None:
        _deliver(out, self.result, self.sink, self.on_persist, self.on_event, self.on_emit)


def _deliver(
    out: Output,
    result: ReplayResult,
    sink: BinaryIO | None,
    on_persist: Callable[[Output], None] | None,
    on_event: Callable[[Event], None] | None,
    on_emit: Callable[[list[Emit]], None] | None = None,
) -> None:
    if out.emits:
        result.emitted += len(out.emits)
        if sink is not None:
            sink.write(b"".join(e.sentence.encode("ascii") + b"\r\n" for e in out.emits))
        if on_emit is not None:
            on_emit(out.emits)
    if out.events:
        result.events.extend(out.events)
        for ev in out.events:
            result.event_counts[ev.kind] = result.event_counts.get(ev.kind, 0) + 1
        if on_event is not None:
            for ev in out.events:
                on_event(ev)
    if out.persist:
        result.persisted += len(out.persist)
        if on_persist is not None:
            on_persist(out)


class _Readings:
    """A UUT's learnt readings as the pipeline takes them (a :class:`Recorder`)."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.raw: list[float] = []

    def reference(
        self, t: float, v_mps: float | None, valid: bool, heading_deg: float | None
    ) -> None:
        """References are not scored."""

    def reading(self, t: float, raw_mps: float) -> None:
        self.t.append(t)
        self.raw.append(raw_mps)


class _TruthScorer:
    """Pairs each UUT's emitted corrected speed with the raw reading it corrects."""

    def __init__(self, pipeline: Pipeline) -> None:
        self.readings: dict[str, _Readings] = {}
        self.source: dict[str, str] = {}
        self.decoders: dict[str, NmeaDecoder] = {}
        self.corrected: dict[str, dict[float, float]] = {}
        for name, u in pipeline.uuts.items():
            rec = _Readings()
            u.cal.recorder = rec
            u.passed = rec.reading  # scored as sent: raw above the range
            self.readings[name] = rec
            self.source[name] = u.s.uut_source
            self.decoders[name] = make_decoder("nmea0183", name, errors="skip")
            self.corrected[name] = {}
        self.athwart = AthwartScorer(pipeline) if pipeline.two_axis else None

    def emitted(self, emits: Sequence[Emit]) -> None:
        """Decode the UUTs' corrected speed sentences as a receiver would."""
        if self.athwart is not None:
            self.athwart.emitted(emits)
        for e in emits:
            dec = self.decoders.get(e.port)
            if dec is None or e.sentence[3:6] != self.source[e.port]:
                continue
            for rec in dec.feed(e.sentence.encode("ascii") + b"\r\n"):
                if isinstance(rec, Rejected):
                    continue
                for sp in dec.speed_records(rec):
                    if sp.source == self.source[e.port] and sp.longitudinal_mps is not None:
                        self.corrected[e.port][e.t] = sp.longitudinal_mps

    def _corrected(self, name: str) -> FloatArray:
        got = self.corrected[name]
        return np.array([got.get(t, np.nan) for t in self.readings[name].t], dtype=np.float64)

    def windows(self, truth: Truth) -> dict[str, list[WindowScore]]:
        """Each UUT's emitted speeds scored against the truth per window."""
        return {
            name: score_windows(truth, name, rec.t, rec.raw, self._corrected(name))
            for name, rec in self.readings.items()
        }

    def scores(self, truth: Truth) -> dict[str, TruthScore]:
        """Each UUT's readings that were emitted corrected, scored against the truth."""
        out = {}
        for name, rec in self.readings.items():
            got = self.corrected[name]
            cor = np.array([got.get(t, np.nan) for t in rec.t], dtype=np.float64)
            out[name] = score_truth(truth, name, rec.t, rec.raw, cor)
        return out
