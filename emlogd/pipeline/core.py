"""The calibration pipeline, one object used identically live and in replay.

``Pipeline.feed(t, port, data)`` takes received bytes with their receive time and
returns what the daemon should do: corrected sentences to emit, events to log, and
calibration states to persist. It never reads the wall clock and does no I/O, so a
replay is deterministic and a test can assert exact outputs (DESIGN.md, data flow).

Per unit under test (UUT):

- **Aligner** — the reference samples go into a fixed-size ring
  (:class:`RefBuffer`); a UUT reading at receive time t is paired with the
  reference interpolated at ``t − lag``. The lag is configured, or estimated once
  by cross-correlation over the first ``lag_window_s`` of data (bounded arrays),
  then fixed. Until it is known the filter does not learn.
- **Calibrator** — a :class:`calib.kalman.KfCalibrator` with the configured error
  model, started from the persisted state when there is one.
- **Supervisor** — learns only while the reference is valid (not lost, not stale,
  faster than ``min_ref_speed_mps``), learning is on, the lag is known and the
  recent reference speeds excite the model (:class:`calib.excitation.ExcitationWindow`).
  Otherwise the filter runs with frozen parameters. Parameters whose standard
  deviations are all under the thresholds while the window is identifiable become
  the *good* calibration; it is persisted with hysteresis (not for insignificant
  changes, not more often than ``persist_interval_s``).
- **Output** — each UUT sentence gives a corrected sentence at once (VHW → VHW with
  knots and km/h, heading passed through; VBW → VBW, longitudinal corrected,
  transverse passed through), always from the last good calibration, made before
  the filter learns from the same sample (and handed to :attr:`Output.deliver` at
  once when the caller set one); before a calibration exists no speed is emitted
  and the status sentence says ``U`` (uncalibrated).
  A proprietary status sentence (:func:`emlogd.pipeline.sentences.encode_status`) follows at
  most once per ``status_interval_s`` of record time.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from calib.errors import CalibrationError
from calib.excitation import ExcitationRule, ExcitationWindow
from calib.kalman import KfCalibrator, KfConfig
from calib.lag import estimate_lag
from calib.models import PARAM_NAMES, Layout, Params, check_model, invert
from drivers import DecoderOptions, make_decoder
from drivers.base import Decoder
from drivers.records import SpeedRecord
from emlogd.pipeline.sentences import StatusFields, encode_status, encode_vbw, encode_vhw

MIN_LAG_CORRELATION = 0.6
"""A lag estimate with a weaker correlation peak is not used (the window slides on)."""

RefField = Literal["bottom", "water", "speed"]
RefState = Literal["valid", "lost", "stale", "slow", "none"]
CalState = Literal["learning", "frozen", "uncalibrated"]

REF_SOURCES: dict[str, tuple[str, ...]] = {
    "bottom": ("PD6:BS", "PD0:BT", "PD4:BT", "PD5:BT", "PRTI01"),
    "water": ("PD6:WS",),
    "speed": ("VHW", "VBW"),
}
"""Speed-record sources that carry each reference field, by preference."""


@dataclass(frozen=True, slots=True)
class PortSettings:
    """What the pipeline needs to know about one input port."""

    name: str
    protocol: str
    checksum: Literal["required", "optional"] = "required"
    max_length: int = 82
    stale_timeout_s: float = 5.0


@dataclass(frozen=True, slots=True)
class UutSettings:
    """Calibration of one UUT (the ``calibration`` section of the config).

    Attributes:
        port: the EMlog port.
        model: ``EM1`` … ``EM4``.
        reference_port: the reference port.
        reference_field: ``bottom``/``water`` (DVL) or ``speed`` (another EMlog).
        lag_s: fixed latency in s, or None to estimate it.
        lag_window_s: data collected before estimating the lag, s.
        max_lag_s: lag search range ±s.
        learn: learning switch at start.
        apply: emit corrected sentences (False: status only).
        min_ref_speed_mps: no learning below this reference speed.
        max_param_std: parameter name -> largest σ for a calibration to count as good.
        excitation_half_life_samples: memory of the excitation window, in UUT samples.
        persist_interval_s: least record time between two persists of this UUT.
        persist_min_change_sigma: persist only if a parameter moved by this many σ…
        persist_min_change_abs: …or by this absolute amount.
        kf: filter tuning.
        rule: identifiability thresholds.
        uut_source: the UUT sentence the filter learns from (``VHW`` or ``VBW``).
        talker: talker ID of the corrected sentences.
        maker: three-letter maker code of the status sentence (``$P`` + maker + ``S``).
        status_interval_s: least record time between two status sentences.
    """

    port: str
    model: str = "EM3"
    reference_port: str = "dvl"
    reference_field: RefField = "bottom"
    lag_s: float | None = None
    lag_window_s: float = 300.0
    max_lag_s: float = 10.0
    learn: bool = True
    apply: bool = True
    min_ref_speed_mps: float = 0.3
    max_param_std: Mapping[str, float] = field(
        default_factory=lambda: {"a": 0.01, "m": 0.02, "b": 0.03}
    )
    excitation_half_life_samples: float = 600.0
    persist_interval_s: float = 60.0
    persist_min_change_sigma: float = 1.0
    persist_min_change_abs: float = 1e-3
    kf: KfConfig = field(default_factory=KfConfig)
    rule: ExcitationRule = field(default_factory=ExcitationRule)
    uut_source: str = "VHW"
    talker: str = "VW"
    maker: str = "EML"
    status_interval_s: float = 1.0

    def __post_init__(self) -> None:
        check_model(self.model)


@dataclass(frozen=True, slots=True)
class Emit:
    """A sentence to send to every output sink.

    Attributes:
        t: the receive time of the UUT sentence that caused it, s.
        port: the UUT port.
        sentence: the NMEA sentence without CR LF (checksummed, ≤ 82 characters).
    """

    t: float
    port: str
    sentence: str


@dataclass(frozen=True, slots=True)
class Event:
    """Something worth a log line (state changes, lag found, reference lost...)."""

    t: float
    port: str
    kind: str
    detail: Mapping[str, object]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """A calibration worth persisting (the good calibration of one UUT).

    Attributes:
        uut: UUT port name.
        model: error model.
        params: the parameters.
        param_std: their standard deviations by name.
        covariance: the filter's full covariance (state order), for a warm restart.
        t: record time of the calibration, s.
        n_samples: samples learnt from.
        lag_s: the latency used.
        excitation: figures of the excitation window.
        nis_mean: running NIS mean.
    """

    uut: str
    model: str
    params: Params
    param_std: Mapping[str, float]
    covariance: tuple[tuple[float, ...], ...]
    t: float
    n_samples: int
    lag_s: float | None
    excitation: Mapping[str, float]
    nis_mean: float | None


@dataclass(slots=True)
class Output:
    """What one :meth:`Pipeline.feed` or :meth:`Pipeline.tick` call produced."""

    emits: list[Emit] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    persist: list[Snapshot] = field(default_factory=list)
    deliver: Callable[[list[Emit]], None] | None = None
    """Live use: takes each corrected sentence as soon as it is ready, before the
    filter learns from the sample (the latency path); the emits are cleared after.
    None (replay, tests): the emits stay in :attr:`emits` for the caller."""

    def send(self, emit: Emit) -> None:
        """Add an emit, handing it to :attr:`deliver` at once when that is set."""
        self.emits.append(emit)
        if self.deliver is not None:
            self.deliver(self.emits)
            self.emits.clear()


@dataclass(slots=True)
class Score:
    """Running sums for the RMSE of raw and corrected speeds against the reference."""

    n: int = 0
    ss_raw: float = 0.0
    ss_cor: float = 0.0

    def add(self, err_raw: float, err_cor: float) -> None:
        """One sample's errors (reading − reference), m/s."""
        self.n += 1
        self.ss_raw += err_raw * err_raw
        self.ss_cor += err_cor * err_cor

    @property
    def rmse_raw(self) -> float | None:
        """RMSE of the raw readings, m/s (None before any sample)."""
        return math.sqrt(self.ss_raw / self.n) if self.n else None

    @property
    def rmse_corrected(self) -> float | None:
        """RMSE of the corrected output, m/s."""
        return math.sqrt(self.ss_cor / self.n) if self.n else None


class RefBuffer:
    """Fixed-size ring of reference samples, queried at a past time.

    Args:
        capacity: samples kept (memory bound).
        max_gap_s: a query is answered only if valid samples lie within this
            distance on both sides (an outage is never bridged).
    """

    __slots__ = ("_buf", "max_gap_s")

    def __init__(self, capacity: int, max_gap_s: float = 1.0) -> None:
        self._buf: deque[tuple[float, float, bool]] = deque(maxlen=capacity)
        self.max_gap_s = max_gap_s

    def add(self, t: float, v: float | None, valid: bool) -> None:
        """Append one sample (times must not decrease; an earlier one is ignored)."""
        if self._buf and t < self._buf[-1][0]:
            return
        self._buf.append((t, math.nan if v is None else v, valid and v is not None))

    def last(self) -> tuple[float, float, bool] | None:
        """The newest sample (t, v, valid), if any."""
        return self._buf[-1] if self._buf else None

    def at(self, t: float) -> float | None:
        """The reference at time ``t`` by linear interpolation, or None.

        Between two valid samples at most ``max_gap_s`` away: interpolated. After
        the newest sample: that sample, for up to ``max_gap_s / 2``. Otherwise None.
        """
        buf = self._buf
        after: tuple[float, float, bool] | None = None
        for i in range(len(buf) - 1, -1, -1):
            s = buf[i]
            if s[0] > t:
                after = s
                continue
            if not s[2]:
                return None
            if s[0] == t:
                return s[1]
            if after is None:
                # the newest sample is before t (a lag shorter than the reference
                # interval): hold it briefly rather than wait for the next one
                return s[1] if t - s[0] <= self.max_gap_s / 2 else None
            if not after[2]:
                return None
            if t - s[0] > self.max_gap_s or after[0] - t > self.max_gap_s:
                return None
            w = (t - s[0]) / (after[0] - s[0])
            return s[1] + w * (after[1] - s[1])
        return None


class _LagCollector:
    """Bounded arrays of UUT and reference speeds for the one-off lag estimate."""

    __slots__ = ("max_lag_s", "ref", "uut", "window_s")

    def __init__(self, window_s: float, max_lag_s: float, ref_rate_cap: int) -> None:
        self.window_s = window_s
        self.max_lag_s = max_lag_s
        cap = int((window_s + 2 * max_lag_s) * ref_rate_cap) + 16
        self.uut: deque[tuple[float, float]] = deque(maxlen=cap)
        self.ref: deque[tuple[float, float]] = deque(maxlen=cap)

    def ready(self) -> bool:
        return bool(self.uut) and self.uut[-1][0] - self.uut[0][0] >= self.window_s

    def estimate(self) -> tuple[float | None, str]:
        """(lag, "") on success; (None, reason) otherwise — and drop the older half."""
        tu = np.array([s[0] for s in self.uut])
        vu = np.array([s[1] for s in self.uut])
        tr = np.array([s[0] for s in self.ref])
        vr = np.array([s[1] for s in self.ref])
        try:
            est = estimate_lag(tu, vu, tr, vr, self.max_lag_s, step_s=0.1)
        except CalibrationError as exc:
            reason = str(exc)
        else:
            if est.peak_corr >= MIN_LAG_CORRELATION and not est.at_bound and est.lag_s >= 0.0:
                return est.lag_s, f"peak correlation {est.peak_corr:.2f}"
            if est.lag_s < 0.0 and est.peak_corr >= MIN_LAG_CORRELATION:
                reason = (
                    f"negative lag {est.lag_s:.2f} s (the EMlog would lead its reference): not used"
                )
            else:
                reason = (
                    f"no clear correlation peak (r={est.peak_corr:.2f}"
                    f"{', at the search bound' if est.at_bound else ''})"
                )
        for q in (self.uut, self.ref):
            for _ in range(len(q) // 2):
                q.popleft()
        return None, reason


class _Uut:
    """The per-UUT state of the pipeline."""

    def __init__(self, s: UutSettings, snapshot: Snapshot | None) -> None:
        self.s = s
        self.model = check_model(s.model)
        self.names = PARAM_NAMES[self.model]
        params0 = snapshot.params if snapshot is not None and snapshot.model == self.model else None
        p0: np.ndarray | None = None
        if params0 is not None and snapshot is not None and snapshot.covariance:
            p0 = np.array(snapshot.covariance, dtype=np.float64)
            if p0.shape != (len(self.names) + 1,) * 2:
                p0 = None
        self.kf = KfCalibrator(self.model, s.kf, params0=params0, P0=p0)
        self.good: Params | None = params0
        self.good_std: dict[str, float] = dict(snapshot.param_std) if params0 and snapshot else {}
        self.persisted: Params | None = params0
        self.t_persist = -math.inf
        self.lag_s = s.lag_s
        self.lag_collector = (
            _LagCollector(s.lag_window_s, s.max_lag_s, 20) if s.lag_s is None else None
        )
        self.ref = RefBuffer(int((s.max_lag_s + 5.0) * 50) + 64)  # up to 50 Hz references
        self.window = ExcitationWindow(
            Layout(self.model), max(s.excitation_half_life_samples, 1.0), s.rule
        )
        self.t_prev: float | None = None
        self.t_status = -math.inf
        self.learn_on = s.learn
        self.state: CalState = "frozen" if params0 is not None else "uncalibrated"
        self.ref_state: RefState = "none"
        self.n_learnt = snapshot.n_samples if snapshot is not None else 0
        self.nis: deque[float] = deque(maxlen=300)
        self.nis_sum = 0.0
        self.identifiable = False
        self.excitation: dict[str, float] = {}
        self.n_since_eval = 0
        self.score = Score()
        self.freezes = 0
        self.state_prev_learning = False
        self.t_ref_last = -math.inf


class Pipeline:
    """Decoders, aligners, calibrators, supervisors and encoders for every UUT.

    Args:
        ports: the input ports.
        uuts: one entry per calibrated EMlog.
        snapshots: persisted calibrations by UUT port (warm start).
    """

    def __init__(
        self,
        ports: Sequence[PortSettings],
        uuts: Sequence[UutSettings],
        snapshots: Mapping[str, Snapshot] | None = None,
    ) -> None:
        self.ports = {p.name: p for p in ports}
        self.decoders: dict[str, Decoder] = {
            p.name: make_decoder(
                p.protocol,
                p.name,
                errors="skip",
                options=DecoderOptions(checksum=p.checksum, max_length=p.max_length),
            )
            for p in ports
        }
        snaps = snapshots or {}
        self.uuts: dict[str, _Uut] = {}
        self._by_ref: dict[str, list[_Uut]] = {}
        for s in uuts:
            if s.port not in self.ports or s.reference_port not in self.ports:
                raise ValueError(f"UUT {s.port}: unknown port {s.port!r} or {s.reference_port!r}")
            u = _Uut(s, snaps.get(s.port))
            self.uuts[s.port] = u
            self._by_ref.setdefault(s.reference_port, []).append(u)
        self.last_rx: dict[str, float] = {}
        self.stale: dict[str, bool] = dict.fromkeys(self.ports, False)

    # -- input ----------------------------------------------------------------

    def feed(self, t: float, port: str, data: bytes, out: Output | None = None) -> Output:
        """Decode received bytes of ``port`` stamped ``t`` and run the pipeline on them."""
        out = out if out is not None else Output()
        dec = self.decoders.get(port)
        if dec is None:
            return out
        self.last_rx[port] = t
        if self.stale[port]:
            self.stale[port] = False
            out.events.append(Event(t, port, "alive", {}))
        for rec in dec.feed(data):
            for sp in dec.speed_records(rec):
                self._speed(t, sp, out, rec)
        return out

    def _speed(self, t: float, sp: SpeedRecord, out: Output, rec: object = None) -> None:
        port = sp.port
        for r in self._by_ref.get(port, ()):
            if sp.source in REF_SOURCES[r.s.reference_field]:
                self._reference(r, t, sp)
        u = self.uuts.get(port)
        if u is not None and sp.source in ("VHW", "VBW"):
            self._uut(u, t, sp, out, rec)

    def _reference(self, u: _Uut, t: float, sp: SpeedRecord) -> None:
        v = sp.longitudinal_mps
        ok = sp.valid and v is not None and math.isfinite(v)
        u.ref.add(t, v, ok)
        u.t_ref_last = t
        if ok and u.lag_collector is not None and v is not None:
            u.lag_collector.ref.append((t, v))

    def _uut(self, u: _Uut, t: float, sp: SpeedRecord, out: Output, rec: object) -> None:
        """Correct and emit with the calibration so far, then learn from the sample.

        Emitting first keeps the filter update off the output's latency path, and
        makes the corrected error scored here a one-step-ahead one: the parameters
        that corrected the sample have not seen its reference.
        """
        raw = sp.longitudinal_mps
        if not sp.valid or raw is None or not math.isfinite(raw):
            return
        corrected = math.nan
        if u.s.apply and u.good is not None:
            p = u.good
            corrected = invert(p.a_spm, p.m, p.b_mps, raw)
            if math.isfinite(corrected):
                if sp.source == "VHW":
                    sentence = encode_vhw(
                        corrected,
                        getattr(rec, "heading_true_deg", None),
                        getattr(rec, "heading_mag_deg", None),
                        u.s.talker,
                    )
                else:
                    sentence = encode_vbw(corrected, sp.transverse_mps, u.s.talker)
                out.send(Emit(t, u.s.port, sentence))
        if sp.source == u.s.uut_source:
            ref = self._learn(u, t, raw, out)
            if ref is not None and math.isfinite(corrected):
                u.score.add(raw - ref, corrected - ref)
        if t - u.t_status >= u.s.status_interval_s:
            u.t_status = t
            out.emits.append(Emit(t, u.s.port, encode_status(self._status_fields(u))))

    def _learn(self, u: _Uut, t: float, raw: float, out: Output) -> float | None:
        """Align, supervise and update the filter; return the valid reference used, if any."""
        dt = 0.0 if u.t_prev is None else max(t - u.t_prev, 0.0)
        u.t_prev = t
        lc = u.lag_collector
        if lc is not None:
            lc.uut.append((t, raw))
            if lc.ready():
                lag, why = lc.estimate()
                if lag is not None:
                    u.lag_s = lag
                    u.lag_collector = None
                    out.events.append(
                        Event(t, u.s.port, "lag_estimated", {"lag_s": lag, "why": why})
                    )
                else:
                    out.events.append(Event(t, u.s.port, "lag_retry", {"why": why}))
        ref = u.ref.at(t - u.lag_s) if u.lag_s is not None else None
        ref_state = self._ref_state(u, t, ref)
        if ref_state != u.ref_state:
            out.events.append(
                Event(t, u.s.port, "reference", {"from": u.ref_state, "to": ref_state})
            )
            u.ref_state = ref_state
        if ref_state == "valid" and ref is not None:
            u.window.add(ref, raw)
            u.n_since_eval += 1
            if u.n_since_eval >= 10 or not u.excitation:
                self._evaluate_window(u)
        learn = u.learn_on and ref_state == "valid" and u.identifiable
        inn = u.kf.update(raw, ref if ref_state == "valid" else None, dt, learn=learn).raw
        if learn and inn is not None:
            u.n_learnt += 1
            if len(u.nis) == u.nis.maxlen:
                u.nis_sum -= u.nis[0]
            u.nis.append(inn.nis)
            u.nis_sum += inn.nis
        new_state: CalState = (
            "learning" if learn else ("frozen" if u.good is not None else "uncalibrated")
        )
        if new_state != u.state:
            out.events.append(Event(t, u.s.port, "state", {"from": u.state, "to": new_state}))
            u.state = new_state
        if learn:
            self._supervise(u, t, out)
        if new_state == "frozen" and u.state_prev_learning:
            u.freezes += 1
        u.state_prev_learning = learn
        return ref if ref_state == "valid" else None

    def _evaluate_window(self, u: _Uut) -> None:
        u.n_since_eval = 0
        ex = u.window.evaluate(u.s.kf.r_raw_mps2 + u.s.kf.r_ref_mps2)
        u.identifiable = ex.identifiable
        u.excitation = {
            "n_effective": ex.stats.n_samples,
            "condition_number": ex.cond_info,
            "speed_std_mps": ex.stats.speed_std_mps,
            "speed_mean_mps": ex.stats.speed_mean_mps,
        }

    def _ref_state(self, u: _Uut, t: float, ref: float | None) -> RefState:
        if u.lag_s is None and u.t_ref_last == -math.inf:
            return "none"
        if t - u.t_ref_last > self.ports[u.s.reference_port].stale_timeout_s:
            return "stale"
        if ref is None:
            return "lost" if u.lag_s is not None else "none"
        if abs(ref) < u.s.min_ref_speed_mps:
            return "slow"
        return "valid"

    def _supervise(self, u: _Uut, t: float, out: Output) -> None:
        std: dict[str, float] = dict(u.kf.param_std)
        if any(std[k] > u.s.max_param_std.get(k, math.inf) for k in u.names):
            return
        params = u.kf.params
        if u.good is None:
            out.events.append(Event(t, u.s.port, "calibrated", {"params": params.as_dict()}))
        u.good = params
        u.good_std = std
        if t - u.t_persist < u.s.persist_interval_s:
            return
        if u.persisted is not None and not self._significant(u, params, std):
            return
        u.t_persist = t
        u.persisted = params
        out.persist.append(self.snapshot(u.s.port, t))

    @staticmethod
    def _significant(u: _Uut, params: Params, std: Mapping[str, float]) -> bool:
        old = u.persisted
        if old is None:
            return True
        a, b = old.as_dict(), params.as_dict()
        return any(
            abs(b[k] - a[k])
            > max(u.s.persist_min_change_sigma * std[k], u.s.persist_min_change_abs)
            for k in u.names
        )

    # -- time -----------------------------------------------------------------

    def tick(self, t: float, out: Output | None = None) -> Output:
        """Advance to time ``t`` without data: stale detection."""
        out = out if out is not None else Output()
        for name, p in self.ports.items():
            last = self.last_rx.get(name)
            if last is not None and not self.stale[name] and t - last > p.stale_timeout_s:
                self.stale[name] = True
                out.events.append(Event(t, name, "stale", {"silent_s": round(t - last, 3)}))
        return out

    # -- control --------------------------------------------------------------

    def set_learning(self, on: bool, port: str | None = None) -> list[str]:
        """Switch learning on or off (one UUT or all); returns the UUTs affected."""
        ports = [port] if port is not None else list(self.uuts)
        for p in ports:
            self.uuts[p].learn_on = on
        return ports

    def reset(self, port: str | None = None) -> list[str]:
        """Forget the calibration of one UUT or all (filter restarted, uncalibrated)."""
        ports = [port] if port is not None else list(self.uuts)
        for p in ports:
            u = self.uuts[p]
            fresh = _Uut(u.s, None)
            fresh.lag_s = u.lag_s
            fresh.lag_collector = u.lag_collector
            fresh.ref = u.ref
            fresh.learn_on = u.learn_on
            self.uuts[p] = fresh
            refs = self._by_ref[u.s.reference_port]
            refs[refs.index(u)] = fresh
        return ports

    def snapshot(self, port: str, t: float | None = None) -> Snapshot:
        """The good calibration of ``port`` (falls back to the live estimate)."""
        u = self.uuts[port]
        params = u.good if u.good is not None else u.kf.params
        std = u.good_std or dict(u.kf.param_std)
        cov = u.kf.covariance()
        return Snapshot(
            uut=port,
            model=u.model,
            params=params,
            param_std=std,
            covariance=tuple(tuple(float(x) for x in row) for row in cov),
            t=u.t_prev if t is None and u.t_prev is not None else (t or 0.0),
            n_samples=u.n_learnt,
            lag_s=u.lag_s,
            excitation=dict(u.excitation),
            nis_mean=self._nis_mean(u),
        )

    def good_snapshots(self) -> list[Snapshot]:
        """Snapshots of every UUT that has a good calibration (what shutdown persists)."""
        return [self.snapshot(p) for p, u in self.uuts.items() if u.good is not None]

    @staticmethod
    def _nis_mean(u: _Uut) -> float | None:
        return u.nis_sum / len(u.nis) if u.nis else None

    def _status_fields(self, u: _Uut) -> StatusFields:
        p = u.good
        return StatusFields(
            port=u.s.port,
            maker=u.s.maker,
            state=u.state,
            model=u.model,
            params=p.as_dict() if p is not None else {},
            std=u.good_std if p is not None else {},
            nis_mean=self._nis_mean(u),
            ref_state=u.ref_state,
        )

    def status(self) -> dict[str, object]:
        """A JSON-ready status: per-port counters and per-UUT calibration state."""
        return {
            "ports": {
                name: {
                    **dec.counters.as_dict(),
                    "stale": self.stale[name],
                    "last_rx": self.last_rx.get(name),
                }
                for name, dec in self.decoders.items()
            },
            "uuts": {
                name: {
                    "state": u.state,
                    "reference": u.ref_state,
                    "learning_enabled": u.learn_on,
                    "model": u.model,
                    "params": u.good.as_dict() if u.good is not None else None,
                    "param_std": u.good_std or None,
                    "estimate": u.kf.params.as_dict(),
                    "estimate_std": dict(u.kf.param_std),
                    "lag_s": u.lag_s,
                    "identifiable": u.identifiable,
                    "excitation": dict(u.excitation),
                    "nis_mean": self._nis_mean(u),
                    "samples_learnt": u.n_learnt,
                    "freezes": u.freezes,
                    "scored_samples": u.score.n,
                    "rmse_raw": u.score.rmse_raw,
                    "rmse_corrected": u.score.rmse_corrected,
                }
                for name, u in self.uuts.items()
            },
        }

    def summary(self) -> str:
        """One line for sd_notify STATUS=."""
        parts = []
        for name, u in self.uuts.items():
            if u.good is not None:
                pv = " ".join(f"{k}={v:+.3f}" for k, v in u.good.as_dict().items())
                parts.append(f"{name} {u.state} {u.model} {pv} ref {u.ref_state}")
            else:
                parts.append(f"{name} {u.state} ref {u.ref_state}")
        return "; ".join(parts)

    def flush(self) -> Output:
        """End of input (replay): flush every decoder."""
        out = Output()
        for port, dec in self.decoders.items():
            t = self.last_rx.get(port, 0.0)
            for rec in dec.flush():
                for sp in dec.speed_records(rec):
                    self._speed(t, sp, out)
        return out


def feed_all(pipeline: Pipeline, items: Iterable[tuple[float, str, bytes]]) -> Output:
    """Run a whole record stream through ``pipeline`` (tests and replay helpers)."""
    out = Output()
    for t, port, data in items:
        pipeline.feed(t, port, data, out)
        pipeline.tick(t, out)
    flushed = pipeline.flush()
    out.emits.extend(flushed.emits)
    out.events.extend(flushed.events)
    out.persist.extend(flushed.persist)
    return out
