"""The calibration pipeline, one object used identically live, in replay and offline.

``Pipeline.feed(t, port, data)`` takes received bytes with their receive time and
returns what the caller should do: corrected sentences to emit, events to log, and
calibrations to persist. It never reads the wall clock and does no I/O, so a replay
is deterministic and a test can assert exact outputs.

Routing (per port, the decoders' common navigation records):

- a **reference** speed (DVL bottom or water track, another log's speed, or GNSS
  speed and course projected on the hull with the heading) goes, through a glitch
  filter (:class:`~emlogd.pipeline.integrity.JumpFilter`), to every UUT that
  calibrates against that port and field;
- a **heading** (true, or magnetic with a variation: the log's, the configured one,
  else the IGRF model's at the last GNSS position, :mod:`emlogd.pipeline.variation`)
  goes to its port's ring; a GNSS reference is projected only with a heading the
  course check has not flagged;
  each UUT reads its heading from the port it is configured for, or (``auto``) from
  its reference's port, else its own VHW heading, else any port with a heading;
- a UUT's **reading** is corrected with the calibration in use and its sentence made
  (the per-UUT :class:`~emlogd.pipeline.uut.UutCalibration` decides how), then queued
  for learning against the reference at ``t − lag``.

``feed``, ``tick`` and ``flush`` return everything they made as an :class:`Output`
(sentences in order, events, calibrations to persist); the caller delivers it. The
pipeline calls nothing of the caller's.

A read that brings several readings of one sentence (a USB-serial stall released
as a burst) carries one receive time for all: only the newest is fresh; the older
ones are backlog — neither learnt from nor emitted as new.

Outputs per UUT: VHW → corrected VHW (heading passed through); VBW → corrected VBW;
a status sentence at most once per ``status_sentence_interval_s``, and with current states
a ``VDR`` (set and drift) whenever the heading determines the current.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from drivers import DecoderOptions, make_decoder
from drivers.base import Decoder, R
from drivers.nmea0183 import Gga, Rmc, Vtg
from drivers.nmea0183 import Heading as NmeaHeading
from drivers.records import KNOT_MPS, Rejected, SpeedRecord
from emlogd.pipeline.align import SampleRing, wrap_deg
from emlogd.pipeline.calibration import Calibration, check
from emlogd.pipeline.fusion import Fusion, FusionSettings, consistency_std
from emlogd.pipeline.headingcheck import HeadingCheck
from emlogd.pipeline.integrity import JumpFilter, ReadingCheck
from emlogd.pipeline.sentences import (
    StatusFields,
    encode_fused_status,
    encode_status,
    encode_vbw,
    encode_vdr,
    encode_vhw,
    encode_vhw_void,
)
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.uut import UutCalibration
from emlogd.pipeline.variation import CourseOffsetCheck, model_variation

FUSED_PORT = "fused"
"""The port name of the fused speed's emits (a UUT may not be called this)."""

HEADING_CHECK_TOL_S = 1.5
"""A GNSS fix is judged with the heading nearest its time within this, s (a heading
sentence often follows the fix; a wrong heading is tens of degrees off, not a turn's
1.5 s)."""


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


@dataclass(slots=True)
class Output:
    """What one :meth:`Pipeline.feed`, :meth:`Pipeline.tick` or :meth:`Pipeline.flush`
    call produced, returned to the caller, which delivers it: the sentences in the order
    they were made (corrected speeds, status, VDR, fused speed), the events, and the
    calibrations to persist. Each call returns a new one; the pipeline keeps no
    reference to it and calls nothing of the caller's."""

    emits: list[Emit] = field(default_factory=list)
    events: list[Event] = field(default_factory=list)
    persist: list[Calibration] = field(default_factory=list)

    def add(self, other: Output) -> None:
        """Append another call's output after this one's (a caller collecting several)."""
        self.emits.extend(other.emits)
        self.events.extend(other.events)
        self.persist.extend(other.persist)


class _Heading(NamedTuple):
    true_deg: float | None
    magnetic_deg: float | None
    variation_deg: float | None


class _Gnss(NamedTuple):
    sog_mps: float | None
    cog_true_deg: float | None
    valid: bool
    variation_deg: float | None
    lat_deg: float | None = None
    lon_deg: float | None = None
    fix_t: float | None = None


class _Fix(NamedTuple):
    quality: int
    lat_deg: float | None = None
    lon_deg: float | None = None


_Nav = SpeedRecord | _Heading | _Gnss | _Fix


def _nav_items(dec: Decoder[R], rec: R | Rejected) -> Iterable[_Nav]:
    """The navigation content of one decoded record of ``dec``.

    GNSS and heading sentences are told apart by type; every speed by its record's
    typed role, and a heading sent with a speed (VHW, a DVL's) comes before it.
    """
    if isinstance(rec, Rejected):
        return
    if isinstance(rec, Rmc):
        fix_t = None if rec.time_utc is None else rec.time_utc.timestamp()
        yield _Gnss(
            rec.sog_mps,
            rec.cog_true_deg,
            rec.valid,
            rec.variation_deg,
            rec.lat_deg,
            rec.lon_deg,
            fix_t,
        )
        return
    if isinstance(rec, Vtg):
        yield _Gnss(rec.sog_mps, rec.cog_true_deg, rec.valid, None)
        return
    if isinstance(rec, Gga):
        yield _Fix(rec.quality, rec.lat_deg, rec.lon_deg)
        return
    if isinstance(rec, NmeaHeading):
        if rec.heading_deg is None:
            return
        if rec.true:
            yield _Heading(rec.heading_deg, None, None)
            return
        mag = rec.heading_deg + (rec.deviation_deg or 0.0)
        var = rec.variation_deg
        yield _Heading(None if var is None else wrap_deg(mag + var), wrap_deg(mag), var)
        return
    for sp in dec.speed_records(rec):
        if sp.role == "ground":
            continue  # a log's ground pair (VBW) is no reference
        ht, hm = sp.heading_true_deg, sp.heading_mag_deg
        if ht is not None or hm is not None:
            yield _Heading(ht, hm, None)
        yield sp


def _keep_lag(cal: UutCalibration, lag_s: float) -> None:
    """Give a new UUT calibration a lag known before (it estimates none)."""
    cal.lag_s = lag_s
    cal.lag_finder = None


def _value(sp: SpeedRecord, component: str) -> float | None:
    """The speed a UUT compares: along the hull, or the horizontal magnitude."""
    v = sp.longitudinal_mps
    if component == "magnitude" and v is not None:
        return math.hypot(v, sp.transverse_mps or 0.0)
    return v


class _PortHeading:
    """The true-heading ring of one port, with its glitch filter and variation."""

    def __init__(self, max_turn_rate_dps: float) -> None:
        self.ring = SampleRing(1024, 2.0, angular=True)
        self.jumps = JumpFilter(max_turn_rate_dps, 5.0, angular=True)
        self.refused_magnetic = 0
        self.magnetic = 0


class _Uut:
    """One UUT's calibration plus its routing state."""

    def __init__(self, s: UutSettings, cal: UutCalibration) -> None:
        self.s = s
        self.cal = cal
        self.ref_jumps = JumpFilter(s.max_accel_mps2, 0.3)
        self.t_status = -math.inf
        self.t_vdr = -math.inf
        self.heading_port: str | None = None
        self.gnss: deque[tuple[float, float | None, float | None, bool]] = deque(maxlen=256)
        self.course_check = CourseOffsetCheck()
        """The heading's offset from the course through the water (variation module)."""
        self.course_refused = 0
        """GNSS fixes not projected because the course check flagged the heading."""
        self.checks: dict[str, ReadingCheck] = {}
        """The plausibility of the readings, per sentence (VHW, VBW)."""
        self.heading_check = HeadingCheck(s.envelope.max_current_mps)
        self.stw: tuple[float, float] | None = None
        """The latest corrected speed through the water (time, m/s)."""
        self.implausible = {"implausible_accel": 0, "implausible_rate": 0}
        """Readings neither emitted nor learnt, by reason (shown with the counters)."""

    def plausible(self, t: float, source: str, raw: float) -> str:
        """``""`` when the reading is plausible, else why not (counted)."""
        chk = self.checks.get(source)
        if chk is None:
            chk = self.checks[source] = ReadingCheck(self.s.limits)
        why = chk.check(t, raw)
        if why:
            self.implausible[f"implausible_{why}"] += 1
        elif chk.reacquired:
            return "reacquired"
        return why


class Pipeline:
    """Decoders, aligners, calibrators, supervisors and encoders for every UUT.

    Args:
        ports: the input ports.
        uuts: one entry per calibrated EMlog.
        calibrations: persisted calibrations by UUT port (warm start); each is checked
            first (:func:`emlogd.pipeline.calibration.check`) and ignored with an event
            when it fails. One of another error model than the UUT's is kept aside
            (:attr:`kept`) and the UUT starts from its own model's record in ``others``,
            else uncalibrated; the lag is taken from either when the config fixes none.
        fusion: the fused output's settings, or None.
        others: the UUTs' calibrations of other error models (the state file's).
    """

    def __init__(
        self,
        ports: Sequence[PortSettings],
        uuts: Sequence[UutSettings],
        calibrations: Mapping[str, Calibration] | None = None,
        *,
        fusion: FusionSettings | None = None,
        others: Iterable[Calibration] = (),
    ) -> None:
        self.ports = {p.name: p for p in ports}
        self.decoders: dict[str, Decoder[Any]] = {
            p.name: make_decoder(
                p.protocol,
                p.name,
                errors="skip",
                options=DecoderOptions(checksum=p.checksum, max_length=p.max_length),
            )
            for p in ports
        }
        self.startup_events: list[Event] = []
        self.fusion = Fusion(fusion) if fusion is not None else None
        self.t_fused_status = -math.inf
        self.headings: dict[str, _PortHeading] = {}
        self.variation: dict[str, float] = {}
        self.model_var: float | None = None
        self.fix_quality: dict[str, int] = {}
        self.uuts: dict[str, _Uut] = {}
        self._by_ref: dict[str, list[_Uut]] = {}
        cals = calibrations or {}
        self.kept: dict[str, dict[str, Calibration]] = {}
        """Per UUT, by model: its calibrations of the error models it is not using now
        (restored when its config switches back to that model)."""
        for c in others:
            self.kept.setdefault(c.uut, {})[c.params.model] = c
        for s in uuts:
            if fusion is not None and s.port == FUSED_PORT:
                raise ValueError(f"a UUT port may not be called {FUSED_PORT!r} with a fused output")
            if s.port not in self.ports or s.reference_port not in self.ports:
                raise ValueError(f"UUT {s.port}: unknown port {s.port!r} or {s.reference_port!r}")
            if s.heading != "auto" and s.heading not in self.ports:
                raise ValueError(f"UUT {s.port}: unknown heading port {s.heading!r}")
            latest = cals.get(s.port)
            kept = self.kept.setdefault(s.port, {})
            if latest is not None and latest.params.model == s.model:
                prior: Calibration | None = latest
                kept.pop(s.model, None)
            else:
                if latest is not None:  # another model's: kept for a switch back
                    kept[latest.params.model] = latest
                prior = kept.pop(s.model, None)  # this model's own, from before
            if prior is not None:
                why = check(prior, s.envelope, s.max_lag_s)
                if why:
                    self.startup_events.append(
                        Event(prior.t, s.port, "calibration_refused", {"why": why})
                    )
                    prior = None
            u = _Uut(s, self._new_cal(s, prior))
            if u.cal.lag_s is None:  # the lag is the sensor's, whatever the model or a reset
                for rec in (prior, latest):
                    if (
                        rec is not None
                        and rec.lag_s is not None
                        and not check(rec, s.envelope, s.max_lag_s)
                    ):
                        _keep_lag(u.cal, rec.lag_s)
                        break
            self.uuts[s.port] = u
            self._by_ref.setdefault(s.reference_port, []).append(u)
        self.last_rx: dict[str, float] = {}
        self.stale: dict[str, bool] = dict.fromkeys(self.ports, False)
        self.now = -math.inf
        self._pending_events: list[Event] = []

    def _new_cal(self, s: UutSettings, prior: Calibration | None) -> UutCalibration:
        return UutCalibration(s, prior, *self._hooks(s.port))

    def _hooks(
        self, port: str
    ) -> tuple[Callable[[float], float | None], Callable[[float, str, Mapping[str, object]], None]]:
        """A UUT calibration's heading look-up and event sink, on this pipeline."""

        def event(t: float, kind: str, detail: Mapping[str, object]) -> None:
            self._pending_events.append(Event(t, port, kind, detail))

        return (lambda t: self._heading_at(port, t)), event

    def adopt(self, old: Pipeline) -> list[str]:
        """Take over from ``old`` (a reload) whatever did not change; return the UUTs kept.

        A port with equal settings keeps its decoder (counters, a partial line), its
        heading ring and its staleness. A UUT with equal settings keeps its whole
        calibration object: learning state, lag estimate, the operator's learning
        switch, scores. A UUT whose settings changed starts from the calibration this
        pipeline was built with, and keeps the operator's learning switch unless its
        ``learn`` setting changed.
        """
        for name, p in self.ports.items():
            if old.ports.get(name) != p:
                continue
            self.decoders[name] = old.decoders[name]
            self.stale[name] = old.stale[name]
            if name in old.headings:
                self.headings[name] = old.headings[name]
            if name in old.variation:
                self.variation[name] = old.variation[name]
            if name in old.fix_quality:
                self.fix_quality[name] = old.fix_quality[name]
            if name in old.last_rx:
                self.last_rx[name] = old.last_rx[name]
        self.model_var = old.model_var
        kept: list[str] = []
        for name, u in self.uuts.items():
            o = old.uuts.get(name)
            if o is None:
                continue
            if o.s == u.s:
                o.cal.heading_at, o.cal._event = self._hooks(name)
                self.uuts[name] = o
                kept.append(name)
            elif o.s.learn == u.s.learn:
                u.cal.learn_on = o.cal.learn_on
        self._by_ref = {}
        for u in self.uuts.values():
            self._by_ref.setdefault(u.s.reference_port, []).append(u)
        if self.fusion is not None and old.fusion is not None:
            self.fusion.adopt(old.fusion)
        self.now = max(self.now, old.now)
        return kept

    # -- headings --------------------------------------------------------------

    def _heading_ports(self, s: UutSettings) -> list[str]:
        if s.heading != "auto":
            return [s.heading]
        order = [s.reference_port, s.port]
        order += [p for p in self.ports if p not in order]
        return order

    def _heading_at(self, uut: str, t: float) -> float | None:
        """The UUT's heading at ``t``, unless the course over ground says it is wrong."""
        u = self.uuts.get(uut)
        if u is None or u.heading_check.suspect:
            return None
        return self._raw_heading_at(u, t)

    def _raw_heading_at(self, u: _Uut, t: float, tol_s: float = 0.6) -> float | None:
        for port in self._heading_ports(u.s):
            ph = self.headings.get(port)
            if ph is None:
                continue
            h = ph.ring.at(t)
            if h is None:
                h = ph.ring.nearest(t, tol_s)
            if h is not None:
                if u.heading_port != port:
                    u.heading_port = port
                return h
        return None

    def _heading(self, t: float, port: str, h: _Heading) -> None:
        ph = self.headings.get(port)
        if ph is None:
            ph = self.headings[port] = _PortHeading(self._turn_rate(port))
        if h.variation_deg is not None:
            self.variation[port] = h.variation_deg
        true = h.true_deg
        if true is None and h.magnetic_deg is not None:
            var = self._variation(port)
            if var is None:
                ph.refused_magnetic += 1
                return
            true = wrap_deg(h.magnetic_deg + var)
            ph.magnetic += 1
        if true is None or not math.isfinite(true):
            return
        if ph.jumps.accept(t, true):
            ph.ring.add(t, wrap_deg(true))

    def _turn_rate(self, port: str) -> float:
        rates = [u.s.max_turn_rate_dps for u in self.uuts.values()]
        return max(rates) if rates else 45.0

    def _variation(self, port: str) -> float | None:
        return self.variation_source(port)[0]

    def variation_source(self, port: str) -> tuple[float | None, str | None]:
        """The variation for magnetic headings of ``port`` and where it comes from: the
        log (HDG/RMC of that port, else of any port), the configuration
        (``magnetic_variation_deg``), the model (IGRF at the last GNSS position and
        date, :mod:`emlogd.pipeline.variation`); (None, None) without any."""
        if port in self.variation:
            return self.variation[port], "log"
        for v in self.variation.values():
            return v, "log"
        for u in self.uuts.values():
            if u.s.magnetic_variation_deg is not None:
                return u.s.magnetic_variation_deg, "config"
        if self.model_var is not None:
            return self.model_var, "model"
        return None, None

    # -- input ----------------------------------------------------------------

    def feed(self, t: float, port: str, data: bytes) -> Output:
        """Decode received bytes of ``port`` stamped ``t`` and run the pipeline on them;
        return what that emitted."""
        out = Output()
        dec = self.decoders.get(port)
        if dec is None:
            return out
        self.last_rx[port] = t
        if t > self.now:
            self.now = t
        if self.stale[port]:
            self.stale[port] = False
            out.events.append(Event(t, port, "alive", {}))
        items = [item for rec in dec.feed(data) for item in _nav_items(dec, rec)]
        if items:
            self._route(t, port, items, out)
        self._after(t, out)
        return out

    def _route(self, t: float, port: str, items: list[_Nav], out: Output) -> None:
        u = self.uuts.get(port)
        # a UUT reading is fresh when it is the chunk's last of its sentence
        last: dict[str, int] = {}
        if u is not None:
            for i, it in enumerate(items):
                if isinstance(it, SpeedRecord) and it.role == "speed":
                    last[it.source] = i
        for i, item in enumerate(items):
            if isinstance(item, _Heading):
                self._heading(t, port, item)
            elif isinstance(item, _Gnss):
                self._gnss(t, port, item)
            elif isinstance(item, _Fix):
                self.fix_quality[port] = item.quality
                if item.quality > 0:
                    self._position(t, item.lat_deg, item.lon_deg)
            else:
                self._reference(t, port, item)
                if u is not None and item.role == "speed":
                    self._reading(u, t, item, fresh=last[item.source] == i, out=out)

    def _reference(self, t: float, port: str, sp: SpeedRecord) -> None:
        for u in self._by_ref.get(port, ()):
            if u.s.reference_field != sp.role:
                continue
            v = _value(sp, u.s.component)
            ok = sp.valid and v is not None and math.isfinite(v)
            if ok and v is not None and not u.ref_jumps.accept(t, v):
                ok = False
            u.cal.add_reference(t, v if ok else None, ok)

    def _position(self, t: float, lat: float | None, lon: float | None) -> None:
        """A GNSS position (RMC, GGA) at ``t``: the model's variation there and then."""
        if lat is not None and lon is not None:
            mv = model_variation(lat, lon, t)
            if mv is not None:
                self.model_var = mv

    def _gnss(self, t: float, port: str, g: _Gnss) -> None:
        """A GNSS speed and course: queued until the heading at its time is known."""
        if g.variation_deg is not None:
            self.variation[port] = g.variation_deg
        if g.valid:
            self._position(t if g.fix_t is None else g.fix_t, g.lat_deg, g.lon_deg)
        valid = g.valid and self.fix_quality.get(port, 1) > 0
        if valid and g.sog_mps is not None and self.fusion is not None:
            self.fusion.ground(t, g.sog_mps)
        if valid and g.sog_mps is not None and g.cog_true_deg is not None:
            for u in self.uuts.values():
                self._check_heading(t, u, g.sog_mps, g.cog_true_deg)
        for u in self._by_ref.get(port, ()):
            if u.s.reference_field == "gnss":
                u.gnss.append((t, g.sog_mps, g.cog_true_deg, valid))
                self._project(u)

    def _check_heading(self, t: float, u: _Uut, sog: float, cog: float) -> None:
        """Judge the UUT's heading against a GNSS fix (an event when the verdict changes)."""
        if u.stw is None or abs(t - u.stw[0]) > 2.0 or sog < u.s.min_sog_mps:
            return
        psi = self._raw_heading_at(u, t, HEADING_CHECK_TOL_S)
        if psi is None:
            return
        hc = u.heading_check
        was = hc.suspect
        hc.add(t, psi, u.stw[1], sog, cog)
        if hc.suspect != was:
            detail = {"why": hc.reason()} if hc.suspect else {}
            kind = "heading_suspect" if hc.suspect else "heading_consistent"
            self._pending_events.append(Event(t, u.s.port, kind, detail))

    def _project(self, u: _Uut, *, final: bool = False) -> None:
        """Project queued GNSS samples on the hull once the heading covers their time.

        Along the hull ``SOG·cos(COG − ψ)`` with the UUT's heading ψ interpolated at the
        fix's time (a heading sentence usually follows the fix in the same second);
        below ``min_sog_mps`` the course is meaningless and the sample is invalid.
        """
        while u.gnss:
            t, sog, cog, valid = u.gnss[0]
            ring = self._heading_ring(u.s)
            if not final and ring is not None and not ring.covers(t) and self.now - t < 2.0:
                return
            u.gnss.popleft()
            along: float | None = None
            ok = valid and sog is not None and cog is not None
            if ok and sog is not None and cog is not None:
                psi = self._heading_at(u.s.port, t)
                if psi is None or sog < u.s.min_sog_mps:
                    ok = False
                else:
                    u.course_check.add(t, psi, sog, cog)
                    if u.course_check.flagged():
                        u.course_refused += 1  # a wrong heading projects nothing
                        ok = False
                    else:
                        along = sog * math.cos(math.radians(cog - psi))
                        ok = u.ref_jumps.accept(t, along)
            u.cal.add_reference(t, along if ok else None, ok)

    def _heading_ring(self, s: UutSettings) -> SampleRing | None:
        """The ring the UUT's heading comes from now (the first with data)."""
        for port in self._heading_ports(s):
            ph = self.headings.get(port)
            if ph is not None and len(ph.ring):
                return ph.ring
        return None

    def _reading(self, u: _Uut, t: float, sp: SpeedRecord, *, fresh: bool, out: Output) -> None:
        """Correct and emit a UUT reading at once, then queue it for learning."""
        cal = u.cal
        raw = _value(sp, u.s.component)
        if not sp.valid or raw is None:
            return
        if not cal.in_range(raw):
            cal.counters.out_of_range += 1
            return
        if not fresh:
            cal.counters.backlog += 1
            return
        why = u.plausible(t, sp.source, raw)
        if why and self.fusion is not None and sp.source == u.s.uut_source:
            self.fusion.refuse(u.s.port, t, why)
        if why and why != "reacquired":
            return
        value = cal.correct(raw)
        if value is not None and sp.source == u.s.uut_source:
            u.stw = (t, value)
        if value is not None:
            hdg_t, hdg_m = sp.heading_true_deg, sp.heading_mag_deg
            if sp.source == "VHW":
                sentence = encode_vhw(value, hdg_t, hdg_m, u.s.talker)
            else:
                sentence = encode_vbw(value, sp.transverse_mps, u.s.talker)
            if self.fusion is None or not self.fusion.s.only:
                out.emits.append(Emit(t, u.s.port, sentence))
            if self.fusion is not None and sp.source == u.s.uut_source:
                self._fuse(t, u, value, hdg_t, hdg_m, out)
        if sp.source == u.s.uut_source:
            cal.add_reading(t, raw)
            cal.drain(self.now)
        if t - u.t_status >= u.s.status_sentence_interval_s:
            u.t_status = t
            out.emits.append(Emit(t, u.s.port, encode_status(self._status_fields(u))))
            self._vdr(u, t, out)

    def _fuse(
        self,
        t: float,
        u: _Uut,
        value: float,
        hdg_t: float | None,
        hdg_m: float | None,
        out: Output,
    ) -> None:
        """Send the fused speed (port ``fused``, with the log's headings) when one is due."""
        assert self.fusion is not None
        cal = u.cal
        std = cal.output_std(value)
        calibrated = cal.applied is not None and u.s.apply
        cstd = consistency_std(std, u.s.r_raw_mps, value, calibrated)
        fused = self.fusion.update(u.s.port, t, value, std, cstd_mps=cstd, calibrated=calibrated)
        if fused is None:
            return
        talker = self.fusion.s.talker
        if fused.valid:
            sentence = encode_vhw(fused.speed_mps, hdg_t, hdg_m, talker)
        else:
            sentence = encode_vhw_void(hdg_t, hdg_m, talker)
        out.emits.append(Emit(t, FUSED_PORT, sentence))
        if t - self.t_fused_status >= u.s.status_sentence_interval_s:
            self.t_fused_status = t
            out.emits.append(Emit(t, FUSED_PORT, encode_fused_status(fused, u.s.maker)))

    def _vdr(self, u: _Uut, t: float, out: Output) -> None:
        cal = u.cal
        if not cal.ident_current():
            return
        cur = cal.kf.current_mps
        if cur is None:
            return
        drift = math.hypot(cur[0], cur[1])
        set_true = wrap_deg(math.degrees(math.atan2(cur[1], cur[0])))
        var = self._variation(u.s.reference_port)
        set_mag = None if var is None else wrap_deg(set_true - var)
        out.emits.append(
            Emit(t, u.s.port, encode_vdr(set_true, set_mag, drift / KNOT_MPS, u.s.talker))
        )

    def _after(self, t: float, out: Output) -> None:
        for u in self.uuts.values():
            if u.gnss:
                self._project(u)
            cal = u.cal
            if cal.pending:
                cal.drain(self.now)
            if cal.dirty:
                snap = cal.take_snapshot(t)
                if snap is not None:
                    out.persist.append(snap)
        if self._pending_events:
            out.events.extend(self._pending_events)
            self._pending_events.clear()

    # -- time -----------------------------------------------------------------

    def tick(self, t: float) -> Output:
        """Advance to time ``t`` without data: stale detection, queued learning; return
        what that emitted."""
        out = Output()
        if self.startup_events:
            out.events.extend(self.startup_events)
            self.startup_events.clear()
        if t > self.now:
            self.now = t
        for name, p in self.ports.items():
            last = self.last_rx.get(name)
            if last is not None and not self.stale[name] and t - last > p.stale_timeout_s:
                self.stale[name] = True
                out.events.append(Event(t, name, "stale", {"silent_s": round(t - last, 3)}))
        self._after(t, out)
        return out

    def flush(self) -> Output:
        """End of input (replay): flush every decoder and learn from every queued reading."""
        out = Output()
        for port, dec in self.decoders.items():
            t = self.last_rx.get(port, 0.0)
            items = [item for rec in dec.flush() for item in _nav_items(dec, rec)]
            self._route(t, port, items, out)
        for u in self.uuts.values():
            self._project(u, final=True)
            u.cal.drain(self.now, final=True)
        self._after(self.now, out)
        return out

    # -- control --------------------------------------------------------------

    def set_learning(self, on: bool, port: str | None = None) -> list[str]:
        """Switch learning on or off (one UUT or all); returns the UUTs affected."""
        ports = [port] if port is not None else list(self.uuts)
        for p in ports:
            self.uuts[p].cal.learn_on = on
        return ports

    def reset(self, port: str | None = None) -> dict[str, dict[str, object]]:
        """Forget the calibration of one UUT or all: the one in use and those of its other
        models; the lag and the operator's learning switch are kept.

        Returns, per UUT reset, what it ``kept`` (``lag_s``, ``learning_enabled``) and
        what it ``cleared`` (named).
        """
        ports = [port] if port is not None else list(self.uuts)
        done: dict[str, dict[str, object]] = {}
        for p in ports:
            u = self.uuts[p]
            old = u.cal
            cleared = [
                f"{u.s.model} calibration" if old.applied is not None else "no calibration applied",
                "current estimate",
                "learning state (filter, candidate, scores)",
                *(f"{m} calibration (another model)" for m in sorted(self.kept.get(p, {}))),
            ]
            self.kept.pop(p, None)
            done[p] = {
                "kept": {"lag_s": old.lag_s, "learning_enabled": old.learn_on},
                "cleared": cleared,
            }
            fresh = self._new_cal(u.s, None)
            fresh.lag_s = old.lag_s
            fresh.lag_finder = old.lag_finder
            fresh.ref = old.ref
            fresh.learn_on = old.learn_on
            fresh.dirty = True
            fresh.t_persist = -math.inf
            u.cal = fresh
        return done

    def calibrations(self) -> list[Calibration]:
        """The calibration of every UUT (a ``reset`` record when it has none): what is persisted."""
        return [u.cal.snapshot() for u in self.uuts.values()]

    def other_calibrations(self) -> list[Calibration]:
        """Every UUT's calibrations of the models it is not using: persisted beside."""
        return [
            c
            for name, u in self.uuts.items()
            for model, c in sorted(self.kept.get(name, {}).items())
            if model != u.s.model
        ]

    # -- status ---------------------------------------------------------------

    def _status_fields(self, u: _Uut) -> StatusFields:
        cal = u.cal
        p = cal.applied
        return StatusFields(
            port=u.s.port,
            maker=u.s.maker,
            state=cal.state,
            model=u.s.model,
            params=p.as_dict() if p is not None else {},
            std={k: v for k, v in cal.applied_std.items() if v is not None}
            if p is not None
            else {},
            nis_mean=cal.nis_mean(),
            ref_state=cal.ref_state,
        )

    def port_status(self) -> dict[str, dict[str, object]]:
        """Per port: decoded records, rejects by reason, staleness, last receive time."""
        return {
            name: {
                **dec.counters.as_dict(),
                "stale": self.stale[name],
                "last_rx": self.last_rx.get(name),
            }
            for name, dec in self.decoders.items()
        }

    def status(self) -> dict[str, object]:
        """A JSON-ready status: per-port counters and per-UUT calibration state."""
        last = self.fusion.last if self.fusion is not None else None
        return {
            "ports": self.port_status(),
            "uuts": {name: self._uut_status(u) for name, u in self.uuts.items()},
            "fused": None
            if last is None
            else {
                "valid": last.valid,
                "speed_mps": last.speed_mps if last.valid else None,
                "std_mps": last.std_mps if last.valid else None,
                "sources": last.sources,
                "excluded": dict(last.excluded),
            },
        }

    def _uut_status(self, u: _Uut) -> dict[str, object]:
        cal = u.cal
        kf = cal.kf
        ident = cal.ident
        cur = kf.current_mps
        cur_std = kf.current_std_mps
        return {
            "state": cal.state,
            "reason": self._heading_reason(u) or cal.reason,
            "reference": cal.ref_state,
            "heading_port": u.heading_port,
            "heading": self.heading_status(u.s.port),
            "heading_suspect": u.heading_check.reason(),
            "learning_enabled": cal.learn_on,
            "model": u.s.model,
            "params": cal.applied.as_dict() if cal.applied is not None else None,
            "param_std": dict(cal.applied_std) if cal.applied is not None else None,
            "estimate": kf.params.as_dict(),
            "estimate_std": kf.param_std,
            "current": None
            if cur is None or cur_std is None
            else {
                "north_mps": cur[0],
                "east_mps": cur[1],
                "std_north_mps": cur_std[0],
                "std_east_mps": cur_std[1],
                "determined": cal.ident_current(),
            },
            "lag_s": cal.lag_s,
            "determined": list(ident.determined) if ident is not None else [],
            "unidentifiable": list(ident.unidentifiable) if ident is not None else [],
            "identifiability": ident.reason if ident is not None else "",
            "nis_mean": cal.nis_mean(),
            "samples_learnt": cal.n_learnt,
            "freezes": cal.freezes,
            "counters": {**cal.counters.as_dict(), **u.implausible},
            "scored_samples": cal.score.n,
            "rmse_raw": cal.score.rmse_raw,
            "rmse_corrected": cal.score.rmse_corrected,
        }

    def _heading_reason(self, u: _Uut) -> str | None:
        """Why a GNSS reference projects nothing, when the heading is the cause: none, a
        magnetic one without a variation, or one the course check flagged."""
        if u.s.reference_field != "gnss" or u.cal.ref_state == "valid":
            return None
        if u.heading_check.suspect:
            return u.heading_check.reason()
        check = u.course_check
        if check.flagged():
            return f"heading {check.offset_deg():+.1f}° off the course over ground: not used"
        if u.heading_port is not None:
            return None
        refused = sum(ph.refused_magnetic for ph in self.headings.values())
        if refused:
            return (
                f"heading magnetic without a variation ({refused} refused): "
                "set magnetic_variation_deg or give GNSS positions"
            )
        return (
            "no heading for the GNSS reference"
            if u.gnss or u.cal.learner.t_ref_last > -math.inf
            else None
        )

    def heading_status(self, uut: str) -> dict[str, object]:
        """A UUT's heading: its port, the variation used and from where (``log``,
        ``config``, ``model``), the magnetic headings refused for want of one, the
        heading-against-course check and the GNSS fixes it refused."""
        u = self.uuts[uut]
        port = u.heading_port
        var, source = self.variation_source(port if port is not None else u.s.reference_port)
        ph = self.headings.get(port) if port is not None else None
        if ph is None or not ph.magnetic:
            var = source = None  # a true heading: no variation used
        refused = sum(ph.refused_magnetic for ph in self.headings.values())
        return {
            "port": port,
            "variation_deg": None if var is None else round(var, 2),
            "variation_source": source,
            "refused_magnetic": refused,
            "check": u.course_check.as_dict(),
            "refused_by_check": u.course_refused,
        }

    def summary(self) -> str:
        """One line for sd_notify STATUS=."""
        parts = []
        for name, u in self.uuts.items():
            cal = u.cal
            if cal.applied is not None:
                pv = " ".join(f"{k}={v:+.3f}" for k, v in cal.applied.as_dict().items())
                parts.append(f"{name} {cal.state} {u.s.model} {pv} ref {cal.ref_state}")
            else:
                parts.append(f"{name} {cal.state} ref {cal.ref_state}")
        return "; ".join(parts)
