"""What :class:`~emlogd.pipeline.core.Pipeline` routes: navigation items, headings, GNSS.

- :func:`nav_items` reduces a decoded record to its navigation content: speeds (by
  role), headings (true, or magnetic with the variation when it came along), GNSS speed
  and course, the fix quality;
- :class:`Headings` keeps each port's true headings (a glitch-filtered ring) and the
  magnetic variation known; a UUT reads its heading from the port it is configured
  for, or (``auto``) from its reference's port, else its own VHW heading, else any port
  with a heading. A magnetic heading without a known variation is refused and counted;
- :class:`UutRoute` is one UUT's routing state: its calibration, the glitch filter of
  its reference, and the GNSS fixes waiting for the heading at their time, projected
  on the hull as ``SOG·cos(COG − ψ)`` (:meth:`UutRoute.project`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from typing import NamedTuple

from drivers.base import Decoder, R
from drivers.nmea0183 import Gga, Rmc, Vtg
from drivers.nmea0183 import Heading as NmeaHeading
from drivers.records import Rejected, SpeedRecord
from emlogd.pipeline.align import SampleRing, wrap_deg
from emlogd.pipeline.groundpair import GroundPair
from emlogd.pipeline.headingcheck import HeadingCheck
from emlogd.pipeline.headingsources import HeadingSources, source_name
from emlogd.pipeline.integrity import JumpFilter
from emlogd.pipeline.readings import ReadingCheck
from emlogd.pipeline.settings import UutSettings
from emlogd.pipeline.stalefix import RepeatedFixes
from emlogd.pipeline.staleness import GNSS_HEADING_WAIT_S, HEADING_MAX_GAP_S, HEADING_NEAREST_S
from emlogd.pipeline.uut import UutCalibration
from emlogd.pipeline.variation import CourseOffsetCheck, model_variation

HEADING_RING = 1024
"""Heading samples kept per port (100 s at 10 Hz)."""

HEADING_JUMP_WINDOW_S = 5.0
"""The heading glitch filter's window: a jump is judged against the turn rate over it."""

REFERENCE_JUMP_WINDOW_S = 0.3
"""The reference glitch filter's window, s."""

DEFAULT_TURN_RATE_DPS = 45.0
"""The heading glitch filter's turn rate without a UUT to take ``max_turn_rate_dps`` from."""

GNSS_QUEUE = 256
"""GNSS fixes waiting for their heading, per UUT (the oldest is dropped beyond)."""


OVER_RANGE_FACTOR = 2.0
"""A plausible reading above the log's configured range (``max_speed_mps``) and at most
this many times it goes out raw (:meth:`UutRoute.over_range`); beyond, it is refused: a
survey vessel is not twice as fast as the range it was configured for, a log reading so
has failed."""

MODEL_VARIATION_S = 1.0
"""Least receive time between two look-ups of the model's variation at a GNSS position
(a computation, 0.5 ms, when the position's cell or the fix's day is new)."""


class NavHeading(NamedTuple):
    """A heading, true and/or magnetic, and the variation sent with it, °."""

    true_deg: float | None
    magnetic_deg: float | None
    variation_deg: float | None
    source: str = ""
    """The sentence it came in (``HDT``, ``THS``, ``VHW``, ``PD6``…): a port may carry
    several heading sources, each compared with the others (:mod:`.headingsources`)."""


class NavGnss(NamedTuple):
    """A GNSS speed over ground and course (RMC, VTG), with the position and the fix's
    own time when the sentence carries them."""

    sog_mps: float | None
    cog_true_deg: float | None
    valid: bool
    variation_deg: float | None
    lat_deg: float | None = None
    lon_deg: float | None = None
    fix_t: float | None = None


class NavFix(NamedTuple):
    """A GNSS fix quality (GGA): 0 is no fix; and its position."""

    quality: int
    lat_deg: float | None = None
    lon_deg: float | None = None


Nav = SpeedRecord | NavHeading | NavGnss | NavFix


def nav_items(dec: Decoder[R], rec: R | Rejected) -> Sequence[Nav]:
    """The navigation content of one decoded record of ``dec`` (empty for none).

    GNSS and heading sentences are told apart by type; every speed by its record's
    typed role, and a heading sent with a speed (VHW, a DVL's) comes before it.
    """
    if isinstance(rec, Rejected):
        return ()
    if isinstance(rec, Rmc):
        fix_t = None if rec.time_utc is None else rec.time_utc.timestamp()
        return (
            NavGnss(
                rec.sog_mps,
                rec.cog_true_deg,
                rec.valid,
                rec.variation_deg,
                rec.lat_deg,
                rec.lon_deg,
                fix_t,
            ),
        )
    if isinstance(rec, Vtg):
        return (NavGnss(rec.sog_mps, rec.cog_true_deg, rec.valid, None),)
    if isinstance(rec, Gga):
        return (NavFix(rec.quality, rec.lat_deg, rec.lon_deg),)
    if isinstance(rec, NmeaHeading):
        if rec.heading_deg is None:
            return ()
        if rec.true:
            return (NavHeading(rec.heading_deg, None, None, rec.sentence),)
        mag = rec.heading_deg + (rec.deviation_deg or 0.0)
        var = rec.variation_deg
        true = None if var is None else wrap_deg(mag + var)
        return (NavHeading(true, wrap_deg(mag), var, rec.sentence),)
    out: list[Nav] = []
    for sp in dec.speed_records(rec):
        if sp.role == "ground":
            continue  # a log's ground pair (VBW) is no reference
        ht, hm = sp.heading_true_deg, sp.heading_mag_deg
        if ht is not None or hm is not None:
            out.append(NavHeading(ht, hm, None, sp.source.split(":", 1)[0]))
        out.append(sp)
    return out


def speed_of(sp: SpeedRecord, component: str) -> float | None:
    """The speed a UUT compares: along the hull, or the horizontal magnitude."""
    v = sp.longitudinal_mps
    if component == "magnitude" and v is not None:
        return math.hypot(v, sp.transverse_mps or 0.0)
    return v


class PortHeading:
    """The true-heading ring of one port, with its glitch filter."""

    def __init__(self, max_turn_rate_dps: float) -> None:
        self.ring = SampleRing(HEADING_RING, HEADING_MAX_GAP_S, angular=True, cadence=True)
        self.jumps = JumpFilter(max_turn_rate_dps, HEADING_JUMP_WINDOW_S, angular=True)
        self.refused_magnetic = 0
        self.magnetic = 0
        """Magnetic headings made true with a variation."""


class Headings:
    """Every port's true headings and the magnetic variation known.

    Args:
        ports: the input ports, in config order (``auto`` searches them in this order).
        uuts: the UUTs' settings (their turn rates and configured variations).
    """

    def __init__(self, ports: Sequence[str], uuts: Sequence[UutSettings]) -> None:
        self.ports = list(ports)
        self.rings: dict[str, PortHeading] = {}
        self.variation: dict[str, float] = {}
        """The variation each port sent last (HDG, RMC), ° east."""
        self.fix_quality: dict[str, int] = {}
        self.repeats = RepeatedFixes()
        """Each GNSS port's run of repeated fixes (a receiver sending its last fix again)."""
        self.sources = HeadingSources()
        """The sources compared: a wrong one's samples are not kept (:meth:`add`)."""
        self.model_var: float | None = None
        """The IGRF model's variation at the last GNSS position and date, ° east."""
        self._model_t = -math.inf
        """When the model was last looked up (receive time)."""
        rates = [u.max_turn_rate_dps for u in uuts]
        self.turn_rate_dps = max(rates) if rates else DEFAULT_TURN_RATE_DPS
        self.configured_variation = next(
            (u.magnetic_variation_deg for u in uuts if u.magnetic_variation_deg is not None),
            None,
        )

    def order(self, s: UutSettings) -> list[str]:
        """The ports a UUT's heading is looked for on, in order."""
        if s.heading != "auto":
            return [s.heading]
        order = [s.reference_port, s.port]
        order += [p for p in self.ports if p not in order]
        return order

    def at(
        self, order: Sequence[str], t: float, nearest_s: float = HEADING_NEAREST_S
    ) -> tuple[float, str] | None:
        """The true heading at ``t`` on the first port of ``order`` (:meth:`order`) that
        has one, and that port; or None. Outside an interpolation a sample within
        ``nearest_s`` of ``t`` is used as it is."""
        for port in order:
            ph = self.rings.get(port)
            if ph is None:
                continue
            h = ph.ring.at(t)
            if h is None:
                h = ph.ring.nearest(t, nearest_s)
            if h is not None:
                return h, port
        return None

    def ring(self, order: Sequence[str]) -> SampleRing | None:
        """The ring a UUT's heading comes from now: the first of ``order`` with data."""
        for port in order:
            ph = self.rings.get(port)
            if ph is not None and len(ph.ring):
                return ph.ring
        return None

    def add(self, t: float, port: str, h: NavHeading) -> None:
        """A heading received on ``port`` at ``t``."""
        ph = self.rings.get(port)
        if ph is None:
            ph = self.rings[port] = PortHeading(self.turn_rate_dps)
        if h.variation_deg is not None:
            self.variation[port] = h.variation_deg
        true = h.true_deg
        if true is None and h.magnetic_deg is not None:
            var = self.variation_of(port)
            if var is None:
                ph.refused_magnetic += 1
                return
            true = wrap_deg(h.magnetic_deg + var)
            ph.magnetic += 1
        if true is None or not math.isfinite(true):
            return
        name = source_name(port, h.source)
        self.sources.heading(t, name, wrap_deg(true))
        if name not in self.sources.wrong and ph.jumps.accept(t, true):
            ph.ring.add(t, wrap_deg(true))

    def variation_of(self, port: str) -> float | None:
        """The variation for ``port``'s magnetic values (:meth:`variation_source`)."""
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
        if self.configured_variation is not None:
            return self.configured_variation, "config"
        if self.model_var is not None:
            return self.model_var, "model"
        return None, None

    def position(
        self, t: float, lat: float | None, lon: float | None, fix_t: float | None = None
    ) -> None:
        """A GNSS position (RMC, GGA) received at ``t``, fixed at ``fix_t`` (its own date
        and time, else ``t``): the model's variation there and then, looked up at most once
        per :data:`MODEL_VARIATION_S` of ``t`` (a fix whose date or cell changes at every
        sentence would make each one a computation of the model)."""
        if lat is None or lon is None or t - self._model_t < MODEL_VARIATION_S:
            return
        self._model_t = t
        mv = model_variation(lat, lon, t if fix_t is None else fix_t)
        if mv is not None:
            self.model_var = mv

    def adopt(self, old: Headings, port: str) -> None:
        """Take over ``port``'s headings, variation and fix quality from ``old``."""
        if port in old.rings:
            self.rings[port] = old.rings[port]
        if port in old.variation:
            self.variation[port] = old.variation[port]
        if port in old.fix_quality:
            self.fix_quality[port] = old.fix_quality[port]
        self.repeats.adopt(old.repeats, port)

    def repeated_fix(self, port: str, g: NavGnss) -> bool | None:
        """Whether ``port``'s fix ``g`` repeats a moving one for long enough, by its own
        time, to be stale (:class:`~emlogd.pipeline.stalefix.RepeatedFixes`; None: it
        has just become so)."""
        parts = (g.lat_deg, g.lon_deg, g.sog_mps, g.cog_true_deg)
        if None in parts or g.fix_t is None:
            return self.repeats.stale(0.0, port, None)
        lat, lon, sog, cog = (float(x) for x in parts if x is not None)
        return self.repeats.stale(g.fix_t, port, (lat, lon, sog, cog))


class UutRoute:
    """One UUT's calibration plus its routing state."""

    def __init__(self, s: UutSettings, cal: UutCalibration, heading_order: list[str]) -> None:
        self.s = s
        self.cal = cal
        self.heading_order = heading_order
        """The ports the UUT's heading is looked for on (:meth:`Headings.order`)."""
        self.ref_jumps = JumpFilter(s.max_accel_mps2, REFERENCE_JUMP_WINDOW_S)
        self.t_status = -math.inf
        self.heading_port: str | None = None
        self.gnss: deque[tuple[float, float | None, float | None, bool]] = deque(maxlen=GNSS_QUEUE)
        self.course_check = CourseOffsetCheck()
        """The heading's offset from the course through the water (variation module)."""
        self.course_refused = 0
        """GNSS fixes not projected because the course check flagged the heading."""
        self.checks: dict[str, ReadingCheck] = {}
        """The plausibility of the readings, per sentence (VHW, VBW)."""
        self.athwart_check = ReadingCheck(s.limits)
        """The plausibility of the athwart speeds of its VBW (the same limits)."""
        self.heading_check = HeadingCheck(s.envelope.max_current_mps)
        self.sources_why = ""
        """Why the heading sources it reads leave it none to trust (``""``: they agree)."""
        self.stw: tuple[float, float] | None = None
        """The latest corrected speed through the water (time, m/s)."""
        self.ground = GroundPair(s.ref_stale_s, s.max_accel_mps2, REFERENCE_JUMP_WINDOW_S)
        """The reference's latest speed over ground on the hull, for the corrected VBW."""
        self.implausible = {"implausible_accel": 0, "implausible_rate": 0}
        """Readings neither emitted nor learnt, by reason (shown with the counters)."""
        self.passed: Callable[[float, float], None] | None = None
        """Offline use (replay's truth scores): receives each reading of the learnt sentence
        passed raw above the range (:meth:`passed_raw`), as the recorder the learnt ones."""

    def plausible(self, t: float, source: str, raw: float, n: int = 1) -> str:
        """``""`` when the reading is plausible, else why not (counted); ``n``: the
        readings of its sentence its read held (:meth:`ReadingCheck.check`)."""
        chk = self.checks.get(source)
        if chk is None:
            chk = self.checks[source] = ReadingCheck(self.s.limits)
        why = chk.check(t, raw, n)
        if why:
            self.implausible[f"implausible_{why}"] += 1
        elif chk.reacquired:
            return "reacquired"
        return why

    def over_range(self, raw: float) -> bool:
        """A reading above the configured range, within :data:`OVER_RANGE_FACTOR` of it.

        Such a reading is a fast vessel or a fault of the log; either way the calibration
        is not known there (it is fitted, and checked monotonic, within the range): it goes
        out raw, the best the log knows, not corrected, learnt nor fused, and is counted
        (``over_range``); silence would leave the autopilot without a speed. A fault that
        jumps there is refused by the plausibility check as any jump."""
        vmax = self.s.envelope.max_speed_mps
        return vmax < raw <= OVER_RANGE_FACTOR * vmax

    def passed_raw(self, t: float, raw: float, learnt: bool) -> float | None:
        """The speed sent for a reading :meth:`over_range`: raw (None while the log has
        a fault, as any reading), counted; ``learnt``: of the learnt sentence (recorded)."""
        self.cal.counters.over_range += 1
        if learnt and self.passed is not None:
            self.passed(t, raw)
        return None if self.cal.sup.health.fault else raw

    def arrived(self, t: float, source: str, n: int = 1) -> None:
        """A reading refused before its check arrived (:meth:`ReadingCheck.arrived`)."""
        chk = self.checks.get(source)
        if chk is not None:
            chk.arrived(t, n)

    def why_athwart_implausible(self, t: float, trans: float) -> str:
        """``""`` when a VBW's athwart speed is plausible (or re-acquired a level), else
        why not (counted with the readings'): a transverse speed jumping by tens of
        knots between two readings is a fault, not a hull moving sideways."""
        why = self.athwart_check.check(t, trans)
        if why:
            self.implausible[f"implausible_{why}"] += 1
        return why

    def reference(self, t: float, v: float | None, valid: bool) -> None:
        """A reference sample along the hull: through the glitch filter to the UUT."""
        ok = valid and v is not None and math.isfinite(v)
        if ok and v is not None and not self.ref_jumps.accept(t, v):
            ok = False
        self.cal.add_reference(t, v if ok else None, ok)

    def project(
        self,
        ring: SampleRing | None,
        heading_at: Callable[[float], float | None],
        now: float,
        *,
        final: bool = False,
    ) -> None:
        """Project queued GNSS samples on the hull once the heading covers their time.

        Along the hull ``SOG·cos(COG − ψ)`` (and across it ``SOG·sin(COG − ψ)``, the
        corrected VBW's ground pair) with the UUT's heading ψ interpolated at the
        fix's time (a heading sentence usually follows the fix in the same second);
        below ``min_sog_mps`` the course is meaningless and the sample is invalid. A fix
        waits for its heading at most :data:`GNSS_HEADING_WAIT_S` (``final``: not at all).
        """
        while self.gnss:
            t, sog, cog, valid = self.gnss[0]
            if (
                not final
                and ring is not None
                and not ring.covers(t)
                and now - t < GNSS_HEADING_WAIT_S
            ):
                return
            self.gnss.popleft()
            along: float | None = None
            across: float | None = None
            ok = valid and sog is not None and cog is not None
            if ok and sog is not None and cog is not None:
                psi = heading_at(t)
                if psi is None or sog < self.s.min_sog_mps:
                    ok = False
                else:
                    self.course_check.add(t, psi, sog, cog)
                    if self.course_check.flagged():
                        self.course_refused += 1  # a wrong heading projects nothing
                        ok = False
                    else:
                        along = sog * math.cos(math.radians(cog - psi))
                        across = sog * math.sin(math.radians(cog - psi))
                        ok = self.ref_jumps.accept(t, along)
            self.cal.add_reference(t, along if ok else None, ok)
            self.ground.add(t, along, across, ok)
