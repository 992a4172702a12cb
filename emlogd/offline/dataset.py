"""Speed time series from capture files, for the offline commands.

One pass over a capture decodes the ports asked for and collects every
:class:`~drivers.records.SpeedRecord` into numpy arrays, one
:class:`SpeedSeries` per (port, source sentence). :func:`align` then pairs a
unit under test (UUT) with a reference: the reference is interpolated at the
UUT's receive times minus the UUT's latency, only where valid reference samples
lie close on both sides (a reference outage is never bridged).

The daemon does not use this module: it runs the streaming pipeline. Both share
the decoders and the speed mapping, so they agree on what a speed is.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.records import SpeedRecord

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

Component = Literal["magnitude", "longitudinal"]
ReferenceField = Literal["bottom", "water", "speed"]

ProgressFn = Callable[[str, float], None]

# Sources that carry each reference field, in order of preference.
_FIELD_SOURCES: dict[str, tuple[str, ...]] = {
    "bottom": ("PD6:BS", "PD0:BT", "PD4:BT", "PD5:BT", "PRTI01"),
    "water": ("PD6:WS",),
    "speed": ("VHW", "VBW"),
}
_UUT_SOURCES: tuple[str, ...] = ("VHW", "VBW")


@dataclass(frozen=True)
class SpeedSeries:
    """The speed records of one port and source sentence, as arrays of shape (n,).

    Attributes:
        port: port name.
        source: sentence or block, e.g. ``"VHW"``, ``"VBW"``, ``"PD6:BS"``.
        kind: ``"stw"`` or ``"sog"``.
        t: receive times, s since the epoch, non-decreasing.
        longitudinal: m/s, NaN where absent.
        transverse: m/s, NaN where absent.
        valid: the sensor's own validity flag.
        heading: degrees, NaN where the record carried none.
    """

    port: str
    source: str
    kind: str
    t: FloatArray
    longitudinal: FloatArray
    transverse: FloatArray
    valid: BoolArray
    heading: FloatArray

    def __len__(self) -> int:
        return int(self.t.size)

    def values(self, component: Component = "magnitude") -> FloatArray:
        """Speed in m/s: the horizontal magnitude, or the longitudinal axis alone.

        For a sentence without a transverse axis (VHW) both are the reported speed.
        """
        if component == "longitudinal":
            return self.longitudinal
        if component != "magnitude":
            raise ValueError(f"component must be magnitude or longitudinal, not {component!r}")
        tr = np.where(np.isnan(self.transverse), 0.0, self.transverse)
        mag = np.hypot(self.longitudinal, tr)
        return np.where(np.isnan(self.longitudinal), np.nan, mag)

    def usable(self, component: Component = "magnitude") -> BoolArray:
        """Samples flagged valid whose value is finite."""
        return self.valid & np.isfinite(self.values(component))


@dataclass
class _Builder:
    kind: str
    t: list[float] = field(default_factory=list)
    lon: list[float] = field(default_factory=list)
    tr: list[float] = field(default_factory=list)
    valid: list[bool] = field(default_factory=list)
    heading: list[float] = field(default_factory=list)

    def add(self, t: float, rec: SpeedRecord) -> None:
        self.t.append(t)
        self.lon.append(np.nan if rec.longitudinal_mps is None else rec.longitudinal_mps)
        self.tr.append(np.nan if rec.transverse_mps is None else rec.transverse_mps)
        self.valid.append(rec.valid)
        self.heading.append(np.nan if rec.heading_deg is None else rec.heading_deg)

    def build(self, port: str, source: str) -> SpeedSeries:
        return SpeedSeries(
            port,
            source,
            self.kind,
            np.asarray(self.t, dtype=np.float64),
            np.asarray(self.lon, dtype=np.float64),
            np.asarray(self.tr, dtype=np.float64),
            np.asarray(self.valid, dtype=np.bool_),
            np.asarray(self.heading, dtype=np.float64),
        )


@dataclass(frozen=True)
class CaptureData:
    """What one pass over a capture produced.

    Attributes:
        path: the capture file.
        ports: port name -> protocol, from the header.
        series: (port, source) -> speed series, for the ports decoded.
        counters: port -> ``{"records": n, "rejects": {reason: n}}``.
        t_start: first record time, s (NaN for an empty capture).
        t_end: last record time, s.
    """

    path: str
    ports: dict[str, str]
    series: dict[tuple[str, str], SpeedSeries]
    counters: dict[str, dict[str, object]]
    t_start: float
    t_end: float

    @property
    def name(self) -> str:
        """The capture's file name without ``.cap``/``.gz`` (e.g. ``2-figure8``)."""
        name = Path(self.path).name
        for suffix in (".gz", ".cap"):
            name = name.removesuffix(suffix)
        return name

    def sources(self, port: str) -> list[str]:
        """Sources seen on ``port``."""
        return [s for (p, s) in self.series if p == port]

    def uut_series(self, port: str, source: str | None = None) -> SpeedSeries:
        """The UUT series of ``port``: ``source`` if given, else VHW, else VBW.

        Raises:
            KeyError: the port has no such series (the message lists what it has).
        """
        return self._pick(port, (source,) if source else _UUT_SOURCES)

    def reference_series(self, port: str, field_: ReferenceField = "bottom") -> SpeedSeries:
        """The reference series of ``port`` for ``field_`` (bottom / water track, or EMlog speed).

        Raises:
            KeyError: the port carries no series for that field.
        """
        if field_ not in _FIELD_SOURCES:
            raise ValueError(f"reference field must be bottom, water or speed, not {field_!r}")
        return self._pick(port, _FIELD_SOURCES[field_])

    def _pick(self, port: str, sources: Sequence[str]) -> SpeedSeries:
        for src in sources:
            s = self.series.get((port, src))
            if s is not None and len(s):
                return s
        if port not in self.ports:
            raise KeyError(f"{self.path}: no port {port!r} (has {', '.join(self.ports)})")
        have = ", ".join(self.sources(port)) or "none"
        raise KeyError(
            f"{self.path}: port {port!r} has no {' or '.join(sources)} speeds (has {have})"
        )


def load_capture(
    path: str | Path,
    ports: Collection[str] | None = None,
    *,
    progress: ProgressFn | None = None,
) -> CaptureData:
    """Decode ``ports`` (default: all) of a capture into speed series.

    Bad frames are skipped and counted (``counters``), never fatal; a malformed
    capture file raises :class:`~drivers.errors.CaptureFormatError` naming the line.

    Args:
        path: capture v1 file.
        ports: names of the ports to decode; other ports are skipped unparsed.
        progress: called as ``progress(message, fraction)`` now and then.
    """
    reader = CaptureReader(path)
    wanted = set(reader.ports) if ports is None else set(ports)
    missing = wanted - set(reader.ports)
    if missing:
        raise KeyError(
            f"{path}: no port {', '.join(sorted(missing))} (has {', '.join(reader.ports)})"
        )
    decoders = {
        name: make_decoder(proto, name, errors="skip")
        for name, proto in reader.ports.items()
        if name in wanted
    }
    builders: dict[tuple[str, str], _Builder] = {}
    size = max(Path(path).stat().st_size, 1)
    t_first = t_last = float("nan")
    n = 0
    for rec in reader:
        if n == 0:
            t_first = rec.t
        t_last = rec.t
        n += 1
        dec = decoders.get(rec.port)
        if dec is None:
            continue
        for out in dec.feed(rec.data):
            for sp in dec.speed_records(out):
                key = (rec.port, sp.source)
                b = builders.get(key)
                if b is None:
                    b = builders[key] = _Builder(sp.kind)
                b.add(rec.t, sp)
        if progress is not None and n % 50_000 == 0:
            progress(f"reading {Path(path).name}", min(rec.line * 60 / size, 1.0))
    for dec in decoders.values():
        for _ in dec.flush():
            pass
    return CaptureData(
        str(path),
        dict(reader.ports),
        {key: b.build(*key) for key, b in builders.items()},
        {name: dec.counters.as_dict() for name, dec in decoders.items()},
        t_first,
        t_last,
    )


@dataclass(frozen=True)
class AlignedPair:
    """UUT samples paired with the reference at the same physical instant.

    Attributes:
        t: UUT receive times, s (only samples where both are usable).
        raw: UUT speed, m/s.
        ref: reference speed at ``t - lag_s``, m/s.
        lag_s: the UUT latency applied, s.
    """

    t: FloatArray
    raw: FloatArray
    ref: FloatArray
    lag_s: float

    def __len__(self) -> int:
        return int(self.t.size)


def interpolate_valid(
    t_ref: FloatArray, v_ref: FloatArray, t_query: FloatArray, max_gap_s: float
) -> FloatArray:
    """Linear interpolation of a reference at ``t_query``; NaN where it cannot be trusted.

    A query gets a value only if valid reference samples exist within ``max_gap_s``
    on both sides (so an outage is never bridged) or a sample coincides with it.

    Args:
        t_ref: reference times of the valid samples, s, non-decreasing, shape (n,).
        v_ref: reference values, m/s, shape (n,).
        t_query: times to interpolate at, s, shape (k,).
        max_gap_s: the largest distance to a neighbouring sample, s.

    Returns:
        Values at ``t_query``, m/s, NaN where not trusted, shape (k,).
    """
    out = np.full(t_query.shape, np.nan)
    if t_ref.size == 0:
        return out
    idx = np.searchsorted(t_ref, t_query)
    inside = (idx > 0) & (idx < t_ref.size)
    i = np.clip(idx, 1, max(t_ref.size - 1, 1))
    left = t_ref[i - 1]
    right = t_ref[np.minimum(i, t_ref.size - 1)]
    ok = inside & (t_query - left <= max_gap_s) & (right - t_query <= max_gap_s)
    out[ok] = np.interp(t_query[ok], t_ref, v_ref)
    # exact hits on the first or last sample
    exact = ~ok & np.isin(t_query, t_ref)
    if exact.any():
        out[exact] = np.interp(t_query[exact], t_ref, v_ref)
    return out


def align(
    uut: SpeedSeries,
    ref: SpeedSeries,
    lag_s: float,
    *,
    component: Component = "magnitude",
    max_gap_s: float = 1.0,
) -> AlignedPair:
    """Pair UUT samples with the reference at ``t - lag_s`` (see :func:`interpolate_valid`).

    Args:
        uut: the unit under test.
        ref: the reference.
        lag_s: UUT latency relative to the reference, s (positive: the UUT reports late).
        component: compare horizontal magnitudes or longitudinal speeds.
        max_gap_s: largest reference gap bridged by interpolation, s.
    """
    ru = ref.usable(component)
    vals = ref.values(component)
    ref_at = interpolate_valid(ref.t[ru], vals[ru], uut.t - lag_s, max_gap_s)
    raw = uut.values(component)
    keep = uut.usable(component) & np.isfinite(ref_at)
    return AlignedPair(uut.t[keep], raw[keep], ref_at[keep], float(lag_s))
