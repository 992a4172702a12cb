"""Synthetic serial streams for the pipeline tests: a DVL and a speed log in a current.

The streams are what the ports would receive: PD6 ensembles (with the heading in
``:SA`` and the ground speed along the hull in ``:BS``) at 10 Hz, and the speed log's
VHW sentences late by its latency. The truth (speed through the water) comes with
them, so a test scores what the pipeline emits against it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from types import SimpleNamespace

import numpy as np
import pytest

from calib.models import Params
from drivers.nmea0183 import encode_vhw
from drivers.rdi_ascii import encode_pd6
from emlogd.pipeline.core import Output, Pipeline
from emlogd.pipeline.settings import PortSettings, UutSettings
from tests.synth import WaterFrameSeries, water_frame_segment

T0 = 1_750_000_000.0
PORTS = [PortSettings("log", "nmea0183"), PortSettings("dvl", "pd6")]

Item = tuple[float, str, bytes]


@dataclass(frozen=True)
class Stream:
    """The received items and the truth behind them."""

    items: list[Item]
    series: WaterFrameSeries
    t0: float
    lag_s: float

    def true_stw(self, t_rx: float) -> float:
        """The true speed through the water the reading received at ``t_rx`` measured."""
        return float(
            np.interp(t_rx - self.lag_s - self.t0, self.series.t_s, self.series.u_water_mps)
        )


def make_stream(
    series: WaterFrameSeries,
    *,
    lag_s: float = 0.0,
    uut_period_s: float = 1.0,
    t0: float = T0,
    lock: Callable[[float], bool] | None = None,
    dvl_heading: bool = True,
    uut_raw: Callable[[float, float], float] | None = None,
) -> Stream:
    """PD6 at the series' rate and VHW every ``uut_period_s``, late by ``lag_s``.

    Args:
        series: the truth at 10 Hz (``tests.synth.water_frame_segment``).
        lag_s: the speed log's latency, s.
        uut_period_s: interval between VHW sentences, s.
        t0: epoch of the first sample.
        lock: bottom lock as a function of the series time (default: always).
        dvl_heading: send the heading in ``:SA`` (else 0 and no heading use is possible).
        uut_raw: replaces the log's reading: ``uut_raw(t, raw) -> reading``.
    """
    items: list[Item] = []
    step = max(1, round(uut_period_s / float(series.t_s[1] - series.t_s[0])))
    for k, t in enumerate(series.t_s.tolist()):
        ok = lock(t) if lock is not None else True
        lines = encode_pd6(
            timestamp=datetime.fromtimestamp(t0 + t, UTC),
            heading_deg=float(series.heading_deg[k]) if dvl_heading else 0.0,
            bottom_ship_mps=(0.0, float(series.ref_mps[k]), 0.0) if ok else None,
            range_m=20.0 if ok else None,
        )
        items.append((t0 + t, "dvl", "".join(x + "\r\n" for x in lines).encode()))
        if k % step == 0:
            raw = float(series.raw_mps[k])
            if uut_raw is not None:
                raw = uut_raw(t, raw)
            sentence = encode_vhw(raw, talker="VW") + "\r\n"
            items.append((t0 + t + lag_s, "log", sentence.encode()))
    items.sort(key=lambda it: it[0])
    return Stream(items, series, t0, lag_s)


def run(p: Pipeline, items: Iterable[Item], out: Output | None = None) -> Output:
    """Feed items in order, ticking after each (as replay does)."""
    out = out if out is not None else Output()
    for t, port, data in items:
        out.add(p.feed(t, port, data))
        out.add(p.tick(t))
    return out


def pipeline(**kw: object) -> Pipeline:
    """A pipeline with one UUT ``log`` calibrated against the DVL ``dvl``."""
    settings = UutSettings(port="log", reference_port="dvl", **kw)  # type: ignore[arg-type]
    return Pipeline(PORTS, [settings])


def emitted(out: Output, port: str = "log") -> list[tuple[float, float]]:
    """(receive time, speed m/s) of every corrected VHW the pipeline emitted."""
    res = []
    for e in out.emits:
        if e.port == port and e.sentence[3:6] == "VHW":
            kn = e.sentence.split(",")[5]
            res.append((e.t, float(kn) * 1852.0 / 3600.0))
    return res


def rmse_vs_truth(
    stream: Stream, pairs: Iterable[tuple[float, float]], *, after: float = -math.inf
) -> float:
    """RMSE of (t, speed) pairs against the true speed through the water."""
    d = [v - stream.true_stw(t) for t, v in pairs if t >= after]
    return math.sqrt(sum(x * x for x in d) / len(d)) if d else math.nan


def raw_rmse_vs_truth(stream: Stream, *, after: float = -math.inf) -> float:
    """RMSE of the raw readings the log sent against the truth."""
    pairs = []
    for t, port, data in stream.items:
        if port == "log" and t >= after:
            kn = data.decode().split(",")[5]
            pairs.append((t, float(kn) * 1852.0 / 3600.0))
    return rmse_vs_truth(stream, pairs)


@pytest.fixture
def segment() -> Callable[..., WaterFrameSeries]:
    """``segment(kind, seconds, params, current=(n, e), seed=1, constant=False)`` at 10 Hz."""

    def make(
        kind: str,
        seconds: float,
        params: Params,
        *,
        current: tuple[float, float] = (0.0, 0.0),
        seed: int = 1,
        constant: bool = False,
        sigma_raw: float = 0.03,
    ) -> WaterFrameSeries:
        return water_frame_segment(
            kind,  # type: ignore[arg-type]
            seconds,
            10.0,
            params,
            np.random.default_rng(seed),
            current_mps=current,
            constant_speed=constant,
            sigma_raw_mps=sigma_raw,
        )

    return make


@pytest.fixture
def kit() -> SimpleNamespace:
    """The stream helpers of this module, for the tests."""
    return SimpleNamespace(
        T0=T0,
        PORTS=PORTS,
        make_stream=make_stream,
        run=run,
        pipeline=pipeline,
        emitted=emitted,
        rmse=rmse_vs_truth,
        raw_rmse=raw_rmse_vs_truth,
    )
