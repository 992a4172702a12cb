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
  course check has not flagged; each UUT reads its heading from its configured port,
  or (``auto``) its reference's, else its own VHW heading, else any with a heading;
- a UUT's **reading** is corrected with the calibration in use and its sentence made
  (the per-UUT :class:`~emlogd.pipeline.uut.UutCalibration` decides how), then queued
  for learning against the reference at ``t − lag``.

``feed``, ``tick`` and ``flush`` return everything they made as an :class:`Output`
(sentences in order, events, calibrations to persist); the caller delivers it. The
pipeline calls nothing of the caller's.

A read that brings several readings of one sentence (a USB-serial stall released
as a burst) carries one receive time for all: only the newest is fresh; the older
ones are backlog — neither learnt from nor emitted as new — though the log's rate
check counts them (a babble arrives in such reads).

Outputs per UUT: VHW → corrected VHW (heading passed through); VBW → corrected VBW; a
status sentence at most once per ``status_sentence_interval_s``; with current states a
``VDR`` (set and drift) whenever the heading determines the current.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from drivers import DecoderOptions, make_decoder
from drivers.base import Decoder
from drivers.records import KNOT_MPS, SpeedRecord
from emlogd.pipeline import status as st
from emlogd.pipeline import twoaxis
from emlogd.pipeline.align import wrap_deg
from emlogd.pipeline.calibration import Calibration, check
from emlogd.pipeline.fusion import Fusion, FusionSettings, consistency_std
from emlogd.pipeline.output import Emit as Emit
from emlogd.pipeline.output import Event as Event
from emlogd.pipeline.output import Output as Output
from emlogd.pipeline.routing import (
    Headings,
    Nav,
    NavFix,
    NavGnss,
    NavHeading,
    UutRoute,
    nav_items,
    speed_of,
)
from emlogd.pipeline.sentences import (
    encode_fused_status,
    encode_status,
    encode_vbw,
    encode_vdr,
    encode_vhw,
    encode_vhw_void,
)
from emlogd.pipeline.settings import PortSettings, UutSettings
from emlogd.pipeline.staleness import HEADING_NEAREST_S, Liveness
from emlogd.pipeline.twoaxis_learn import TwoAxisLearner, encode_two_axis_status
from emlogd.pipeline.uut import UutCalibration

FUSED_PORT = "fused"
"""The port name of the fused speed's emits (a UUT may not be called this)."""

HEADING_CHECK_TOL_S = 1.5
"""A GNSS fix is judged with the heading nearest its time within this, s (a heading
sentence often follows the fix; a wrong heading is tens of degrees off, not a turn's
1.5 s)."""


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
            One of a UUT the config does not have is kept aside too, persisted with
            :meth:`other_calibrations`.
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
        self.headings = Headings(list(self.ports), uuts)
        self.uuts: dict[str, UutRoute] = {}
        self.two_axis: dict[str, TwoAxisLearner] = {}
        """The UUTs that learn two axes (``axes: 2``), by port."""
        self._by_ref: dict[str, list[UutRoute]] = {}
        cals = calibrations or {}
        self.kept: dict[str, dict[str, Calibration]] = {}
        """Per UUT, by model: its calibrations of the error models it is not using now
        (restored when its config switches back to that model)."""
        for c in others:
            self.kept.setdefault(c.uut, {})[c.params.model] = c
        configured = {s.port for s in uuts}
        for name, c in cals.items():  # a UUT the config leaves out: kept for its return
            if name not in configured and not c.reset:
                self.kept.setdefault(name, {})[c.params.model] = c
        for s in uuts:
            if fusion is not None and s.port == FUSED_PORT:
                raise ValueError(f"a UUT port may not be called {FUSED_PORT!r} with a fused output")
            if s.port not in self.ports or s.reference_port not in self.ports:
                raise ValueError(f"UUT {s.port}: unknown port {s.port!r} or {s.reference_port!r}")
            if s.heading != "auto" and s.heading not in self.ports:
                raise ValueError(f"UUT {s.port}: unknown heading port {s.heading!r}")
            latest = cals.get(s.port)
            prior = self._prior(s, latest)
            u = UutRoute(s, self._new_cal(s, prior), self.headings.order(s))
            if u.cal.lag_s is None:  # the lag is the sensor's, whatever the model or a reset
                for rec in (prior, latest):
                    if (
                        rec is not None
                        and rec.lag_s is not None
                        and not check(rec, s.envelope, s.max_lag_s)
                    ):
                        u.cal.lag_s, u.cal.lag_finder = rec.lag_s, None  # known: none estimated
                        break
            self.uuts[s.port] = u
            if s.axes == 2:
                self.two_axis[s.port] = self._two_axis(s, latest)
            self._by_ref.setdefault(s.reference_port, []).append(u)
        self.liveness = Liveness({p.name: p.stale_timeout_s for p in ports})
        self.now = -math.inf
        self._pending_events: list[Event] = []
        self._waiting = True  # whether _after may have work without a record's items
        self._sources_version = 0
        """The heading sources' verdict last handed to the UUTs (:meth:`_heading_sources`)."""

    def _two_axis(self, s: UutSettings, latest: Calibration | None) -> TwoAxisLearner:
        """A two-axis learner; the saved figures of a record its checks accept restored
        (they validate again, early in the record's sea, before they are applied)."""
        ax = TwoAxisLearner(s, self._hooks(s.port)[1])
        saved = latest.two_axis if latest is not None else None
        if latest is not None and saved is not None and not check(latest, s.envelope, s.max_lag_s):
            ax.restore(latest)
        return ax

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

        A port with equal settings keeps its decoder (counters, a partial line), heading
        ring and staleness; a UUT with equal settings its whole calibration object
        (learning state, lag estimate, the operator's learning switch, scores). A UUT
        whose settings changed starts from the calibration this pipeline was built
        with, keeping the operator's learning switch unless its ``learn`` changed.
        """
        for name, p in self.ports.items():
            if old.ports.get(name) != p:
                continue
            self.decoders[name] = old.decoders[name]
            self.liveness.adopt(old.liveness, [name])
            self.headings.adopt(old.headings, name)
        self.headings.model_var = old.headings.model_var
        self.headings.sources = old.headings.sources
        kept: list[str] = []
        for name, u in self.uuts.items():
            o = old.uuts.get(name)
            if o is None:
                continue
            if o.s == u.s:
                o.cal.heading_at, o.cal._event = self._hooks(name)
                o.heading_order = self.headings.order(o.s)  # this config's ports
                self.uuts[name] = o
                if name in old.two_axis and name in self.two_axis:
                    self.two_axis[name] = old.two_axis[name]
                    self.two_axis[name].sup._event = self.two_axis[name]._event = o.cal._event
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

    def _heading_at(self, uut: str, t: float) -> float | None:
        """The UUT's true heading at ``t``, unless the course over ground says it is wrong
        or two of its sources disagree with nothing to tell which is right."""
        u = self.uuts.get(uut)
        if u is None or u.heading_check.suspect or u.sources_why:
            return None
        return self._raw_heading_at(u, t)

    def _raw_heading_at(
        self, u: UutRoute, t: float, tol_s: float = HEADING_NEAREST_S
    ) -> float | None:
        """The UUT's true heading at ``t`` (noting the port it came from), or None."""
        found = self.headings.at(u.heading_order, t, tol_s)
        if found is None:
            return None
        u.heading_port = found[1]
        return found[0]

    # -- input ----------------------------------------------------------------

    def feed(self, t: float, port: str, data: bytes) -> Output:
        """Decode received bytes of ``port`` stamped ``t`` and run the pipeline on them;
        return what that emitted."""
        out = Output()
        dec = self.decoders.get(port)
        if dec is None:
            return out
        if t > self.now:
            self.now = t
        if self.liveness.heard(port, t):
            out.events.append(Event(t, port, "alive", {}))
        items: list[Nav] = []
        for rec in dec.feed(data):
            items += nav_items(dec, rec)
        if items:
            self._route(t, port, items, out)
        if items or self._waiting:  # else nothing routed and nothing due (see _after)
            self._after(t, out)
        return out

    def _route(self, t: float, port: str, items: list[Nav], out: Output) -> None:
        u = self.uuts.get(port)
        # a UUT reading is fresh when the chunk's last of its sentence; the rate check
        # counts them all (a chunk of one item: fresh, the one of its sentence)
        last: dict[str, int] = {}
        count: dict[str, int] = {}
        if u is not None and len(items) > 1:
            for i, it in enumerate(items):
                if isinstance(it, SpeedRecord) and it.role == "speed":
                    last[it.source] = i
                    count[it.source] = count.get(it.source, 0) + 1
        for i, item in enumerate(items):
            if isinstance(item, NavHeading):
                self.headings.add(t, port, item)
            elif isinstance(item, NavGnss):
                self._gnss(t, port, item)
            elif isinstance(item, NavFix):
                self.headings.fix_quality[port] = item.quality
                if item.quality > 0:
                    self.headings.position(t, item.lat_deg, item.lon_deg)
            else:
                self._reference(t, port, item)
                if u is not None and item.role == "speed":
                    fresh = last.get(item.source, i) == i
                    n = count.get(item.source, 1) if fresh else 1
                    self._reading(u, t, item, fresh=fresh, out=out, n=n)

    def _reference(self, t: float, port: str, sp: SpeedRecord) -> None:
        for u in self._by_ref.get(port, ()):
            u.ground.bottom(t, sp)  # the corrected VBW's ground pair
            if u.s.reference_field != sp.role:
                continue
            u.reference(t, speed_of(sp, u.s.component), sp.valid)
            ax = self.two_axis.get(u.s.port) if self.two_axis else None
            if ax is not None:
                ax.reference(t, sp.longitudinal_mps, sp.transverse_mps, sp.valid)

    def _gnss(self, t: float, port: str, g: NavGnss) -> None:
        """A GNSS speed and course: queued until the heading at its time is known."""
        if g.variation_deg is not None:
            self.headings.variation[port] = g.variation_deg
        if g.valid:
            self.headings.position(t, g.lat_deg, g.lon_deg, g.fix_t)
        valid = g.valid and self.headings.fix_quality.get(port, 1) > 0
        if valid:  # the last fix sent again and again: no reference (stalefix)
            stale = self.headings.repeated_fix(port, g)
            if stale is None:
                self._pending_events.append(Event(t, port, "gnss_repeated", {}))
            valid = stale is False
        if valid and g.sog_mps is not None and self.fusion is not None:
            self.fusion.ground(t, g.sog_mps)
        if valid and g.sog_mps is not None and g.cog_true_deg is not None:
            self.headings.sources.course(t, port, g.sog_mps, g.cog_true_deg)
            for u in self.uuts.values():
                self._check_heading(t, u, g.sog_mps, g.cog_true_deg)
        for u in self._by_ref.get(port, ()):
            if u.s.reference_field == "gnss":
                u.gnss.append((t, g.sog_mps, g.cog_true_deg, valid))
                self._project(u)

    def _check_heading(self, t: float, u: UutRoute, sog: float, cog: float) -> None:
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

    def _project(self, u: UutRoute, *, final: bool = False) -> None:
        """Project the UUT's queued GNSS fixes (:meth:`UutRoute.project`)."""
        port = u.s.port
        u.project(
            self.headings.ring(u.heading_order),
            lambda t: self._heading_at(port, t),
            self.now,
            final=final,
        )

    def _reading(
        self, u: UutRoute, t: float, sp: SpeedRecord, *, fresh: bool, out: Output, n: int = 1
    ) -> None:
        """Correct a UUT reading and emit its sentence, then queue it for learning; ``n``:
        the readings of its sentence in its read (the rate check counts them)."""
        cal = u.cal
        raw, source = speed_of(sp, u.s.component), sp.source
        if not sp.valid or raw is None or not self._admit(u, t, source, raw, fresh, n):
            return
        over = not cal.in_range(raw)  # above the range: raw goes out (UutRoute.over_range)
        trans = sp.transverse_mps
        if source == "VBW" and trans is not None and u.why_athwart_implausible(t, trans):
            return  # neither emitted nor learnt, as an implausible reading
        learnt = source == u.s.uut_source and not over
        if learnt:
            # judged first when its reference is already in (a log that lags the
            # reference): a change the supervisor sees in it is not emitted corrected
            cal.add_reading(t, raw)
            cal.drain(self.now)
        value = u.passed_raw(t, raw, source == u.s.uut_source) if over else cal.correct(raw)
        if value is not None:
            if learnt:
                u.stw = (t, value)
            hdg_t, hdg_m = sp.heading_true_deg, sp.heading_mag_deg
            sentence = self._sentence(u, t, sp, value, over)
            if self.fusion is None or not self.fusion.s.only:
                out.emits.append(Emit(t, u.s.port, sentence))
            if self.fusion is not None and learnt:
                self._fuse(t, u, value, hdg_t, hdg_m, out)
        if t - u.t_status >= u.s.status_sentence_interval_s:
            u.t_status = t
            out.emits.append(Emit(t, u.s.port, encode_status(st.status_fields(u))))
            ax = self.two_axis.get(u.s.port)
            if ax is not None:
                out.emits.append(Emit(t, u.s.port, encode_two_axis_status(u.s.port, u.s.maker, ax)))
            self._vdr(u, t, out)

    def _sentence(self, u: UutRoute, t: float, sp: SpeedRecord, value: float, over: bool) -> str:
        """A reading's sentence: VHW; VBW with the learnt two-axis figures (then learnt
        from, ``axes: 2``; ``TwoAxisLearner.forward`` for a VHW), else the configured ones,
        else the athwart read; ground pair the reference's; ``over`` the range: both raw."""
        ax = None if over else self.two_axis.get(u.s.port)
        if sp.source == "VHW":
            v = value if ax is None else ax.forward(t, sp.longitudinal_mps, value, u.cal.guard)
            return encode_vhw(v, sp.heading_true_deg, sp.heading_mag_deg, u.s.talker)
        trans, g = sp.transverse_mps, u.ground.at(t)
        if ax is not None and trans is not None:
            hull = ax.correct(t, value, trans, sp.longitudinal_mps, u.cal.guard)
            if sp.longitudinal_mps is not None:
                ax.reading(t, value, sp.longitudinal_mps, trans)
                ax.drain(self.now, u.cal.lag_s, u.cal.heading_at, u.cal.learn_on)
            if hull is not None:
                return encode_vbw(*hull, u.s.talker, g)
        if trans is not None and not over and twoaxis.configured(u.s):
            return encode_vbw(*twoaxis.hull_frame(u.s, value, trans), u.s.talker, g)
        return encode_vbw(value, trans, u.s.talker, g)

    def _prior(self, s: UutSettings, latest: Calibration | None) -> Calibration | None:
        """The calibration a UUT starts from: its latest when of its model, else its own
        model's from before (another model's latest kept for a switch back); one the
        UUT's checks refuse is left out with a ``calibration_refused`` event."""
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
                return None
        return prior

    def _admit(
        self, u: UutRoute, t: float, source: str, raw: float, fresh: bool, n: int = 1
    ) -> bool:
        """Whether a UUT's reading is emitted: in the log's range (or passed raw above it),
        not a backlog's, plausible (an implausible one is refused to the fusion too); the
        ones left out are counted by why."""
        cal = u.cal
        if not cal.in_range(raw) and not u.over_range(raw):
            cal.counters.out_of_range += 1
            if fresh:
                u.arrived(t, source, n)
            return False
        if not fresh:
            cal.counters.backlog += 1
            return False
        why = u.plausible(t, source, raw, n)
        if why and self.fusion is not None and source == u.s.uut_source:
            self.fusion.refuse(u.s.port, t, why)
        return not why or why == "reacquired"

    def _fuse(
        self,
        t: float,
        u: UutRoute,
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
        fused = self.fusion.update(
            u.s.port,
            t,
            value,
            std,
            cstd_mps=cstd,
            calibrated=calibrated,
            referenced=cal.ref_state == "valid",
        )
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

    def _vdr(self, u: UutRoute, t: float, out: Output) -> None:
        cal = u.cal
        if not cal.ident_current():
            return
        cur = cal.kf.current_mps
        if cur is None:
            return
        drift = math.hypot(cur[0], cur[1])
        set_true = wrap_deg(math.degrees(math.atan2(cur[1], cur[0])))
        var = self.headings.variation_of(u.s.reference_port)
        set_mag = None if var is None else wrap_deg(set_true - var)
        out.emits.append(
            Emit(t, u.s.port, encode_vdr(set_true, set_mag, drift / KNOT_MPS, u.s.talker))
        )

    def _after(self, t: float, out: Output) -> None:
        """Project GNSS fixes, learn from the readings whose time came, hand out a changed
        calibration and the events; note in :attr:`_waiting` whether time alone can make
        anything due (a fix or reading queued, a calibration not persisted yet)."""
        two_axis = self.two_axis
        waiting = False
        for u in self.uuts.values():
            if u.gnss:
                self._project(u)
            cal = u.cal
            if cal.pending:
                cal.drain(self.now)
            ax = two_axis.get(u.s.port) if two_axis else None
            if ax is not None and ax.sup.changed:
                ax.sup.changed, cal.dirty = False, True
            if cal.sup.dirty:
                snap = cal.take_snapshot(t)
                if snap is not None:
                    out.persist.append(self._with_two_axis(snap))
            waiting = waiting or bool(u.gnss or cal.pending or cal.sup.dirty)
        self._waiting = waiting
        if self.headings.sources.version != self._sources_version:
            self._heading_sources(t)
        if self._pending_events:
            out.events.extend(self._pending_events)
            self._pending_events.clear()

    def _heading_sources(self, t: float) -> None:
        """The heading sources' new verdict: their events, and each UUT's heading
        suspect (or trusted again) when two sources it reads disagree unresolved."""
        src = self.headings.sources
        self._sources_version = src.version
        for ts, port, kind, detail in src.events:
            self._pending_events.append(Event(ts, port, kind, detail))
        src.events.clear()
        for u in self.uuts.values():
            why = src.suspect(u.heading_order)
            if why != u.sources_why:
                u.sources_why = why
                kind = "heading_suspect" if why else "heading_consistent"
                self._pending_events.append(Event(t, u.s.port, kind, {"why": why} if why else {}))

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
        for name, silent_s in self.liveness.check(t):
            out.events.append(Event(t, name, "stale", {"silent_s": round(silent_s, 3)}))
        self._after(t, out)
        return out

    def flush(self) -> Output:
        """End of input (replay): flush every decoder and learn from every queued reading."""
        out = Output()
        for port, dec in self.decoders.items():
            t = self.liveness.last.get(port, 0.0)
            items = [item for rec in dec.flush() for item in nav_items(dec, rec)]
            self._route(t, port, items, out)
        for u in self.uuts.values():
            self._project(u, final=True)
            u.cal.drain(self.now, final=True)
            ax = self.two_axis.get(u.s.port)
            if ax is not None:
                ax.drain(self.now, u.cal.lag_s, u.cal.heading_at, u.cal.learn_on, final=True)
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

        Returns, per UUT reset, what it ``kept`` (``lag_s``, ``learning_enabled``) and what
        it ``cleared`` (named).
        """
        ports = [port] if port is not None else list(self.uuts)
        done: dict[str, dict[str, object]] = {}
        for p in ports:
            u = self.uuts[p]
            old = u.cal
            cleared = [
                f"{u.s.model} calibration" if old.sup.kept is not None else "no calibration kept",
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
            self._waiting = True
            if p in self.two_axis:
                self.two_axis[p] = TwoAxisLearner(u.s, self._hooks(p)[1])
                cleared.append("two-axis figures")
        return done

    def calibrations(self) -> list[Calibration]:
        """The calibration of every UUT (a ``reset`` record when it has none): what is persisted."""
        return [self._with_two_axis(u.cal.snapshot()) for u in self.uuts.values()]

    def _with_two_axis(self, snap: Calibration) -> Calibration:
        """A UUT's record with its last good two-axis figures (``axes: 2``)."""
        ax = self.two_axis.get(snap.uut)
        kept = ax.sup.kept if ax is not None else None
        return snap if kept is None else dataclasses.replace(snap, two_axis=kept.as_dict())

    def other_calibrations(self) -> list[Calibration]:
        """Every UUT's calibrations of the models it is not using, and those of the UUTs
        the config leaves out (a log taken out of the config for a while starts from its
        calibration when it comes back): persisted beside."""
        return [
            c
            for name, by_model in sorted(self.kept.items())
            for model, c in sorted(by_model.items())
            if name not in self.uuts or model != self.uuts[name].s.model
        ]

    # -- status ---------------------------------------------------------------

    def port_status(self) -> dict[str, dict[str, object]]:
        """Per port: decoded records, rejects by reason, staleness, last receive time."""
        return st.port_status(self.decoders, self.liveness)

    def status(self) -> dict[str, object]:
        """A JSON-ready status: per-port counters and per-UUT calibration state."""
        return {
            "ports": self.port_status(),
            "uuts": {
                name: st.uut_status(u, self.headings, self.liveness, self.now)
                | ({"two_axis": self.two_axis[name].status()} if name in self.two_axis else {})
                for name, u in self.uuts.items()
            },
            "fused": st.fused_status(self.fusion.last if self.fusion is not None else None),
        }

    def variation_source(self, port: str) -> tuple[float | None, str | None]:
        """The variation for magnetic headings of ``port`` and where it comes from
        (:meth:`Headings.variation_source`)."""
        return self.headings.variation_source(port)

    def heading_status(self, uut: str) -> dict[str, object]:
        """A UUT's heading (:func:`emlogd.pipeline.status.heading_status`)."""
        return st.heading_status(self.uuts[uut], self.headings)

    def summary(self) -> str:
        """One line for sd_notify STATUS=."""
        return st.summary(self.uuts)
