"""Do the vessel's heading sources agree? Which one lies?

Every true heading the pipeline hears (a DVL's attitude, HDT/HDG/HDM/THS/``$PASHR``
compasses, VHW's heading; one source per port and sentence, ``port.SENTENCE``) and the
GNSS course over ground at speed (a weak source, ``port.course``: a current sets the
course off the heading) are compared two by two on
common times — samples at most :data:`COMMON_S` apart, their circular difference against
a tolerance of :data:`AGREE_DEG` widened by the turn rate times the time between them
plus :data:`LAG_ALLOWANCE_S` (two sources' lags differ by that much in a turn). The
course is compared only on straight legs (both turning below :data:`STRAIGHT_RATE_DPS`,
the ground speed at least :data:`COURSE_MIN_SOG_MPS`) against :data:`COURSE_AGREE_DEG`.
A pair is judged as the course check judges a heading
(:mod:`emlogd.pipeline.headingcheck`): over :data:`~emlogd.pipeline.headingcheck.WINDOW_S`
(at least :data:`~emlogd.pipeline.headingcheck.MIN_SAMPLES` comparisons over half of it)
it *disagrees* when :data:`~emlogd.pipeline.headingcheck.BAD_FRACTION` of them are beyond
the tolerance, and *agrees* again below half that fraction. A constant offset below the
tolerance (a compass's deviation of a few degrees) is no fault.

Two heading sources that disagree are resolved by a third (another compass, or the
course on straight legs) that agrees with one and disagrees with the other: the other is
*wrong*, named, and no UUT reads its heading from it (:meth:`HeadingSources.usable`).
Unresolved, every UUT whose heading may come from either is *suspect*
(:meth:`HeadingSources.suspect`): the pipeline then uses no heading for it, as for a
heading the course check flags — no current learnt with two sources 180° apart, none
projected. A source that repeats one value (within :data:`FROZEN_EPS_DEG`) for
:data:`FROZEN_S` while another source or the course turned by more than
:data:`FROZEN_TURN_DEG` is *frozen*: wrong until its value moves.

No I/O, no clock: times come with the data.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

from emlogd.pipeline.headingcheck import BAD_FRACTION, MIN_SAMPLES, WINDOW_S

AGREE_DEG = 30.0
"""Two headings further apart than this (plus the turn's allowance) disagree, °: a
compass's uncompensated deviation (a few degrees) and a magnetic variation's error stay
below; a heading 90° or 180° wrong does not."""

LAG_ALLOWANCE_S = 2.0
"""How much two heading sources' lags may differ, s: in a turn at ``r`` °/s the
tolerance grows by ``r`` times this (and the time between the samples compared)."""

COMMON_S = 1.0
"""Two sources' samples at most this far apart are compared, s."""

COMPARE_INTERVAL_S = 1.0
"""One comparison per pair at most this often, s (a 10-Hz compass judged at 1 Hz)."""

RATE_BASE_S = 1.0
"""A source's turn rate is taken over at least this much of its series, s."""

COURSE_MIN_SOG_MPS = 1.0
"""Below this ground speed the course is not compared (a current or noise sets it)."""

COURSE_AGREE_DEG = 45.0
"""The course and a right heading stay within this on straight legs, °: the current's
crab angle (a 0.7 m/s current across a 1 m/s course) and the course's noise."""

STRAIGHT_RATE_DPS = 3.0
"""The course is compared only while the heading and the course turn slower, °/s (the
course lags the heading in a turn by the vessel's inertia)."""

FROZEN_EPS_DEG = 0.01
"""A source whose samples stay within this of one value repeats it, °."""

FROZEN_S = 20.0
"""A repeated value is a frozen source only when repeated this long, s."""

FROZEN_TURN_DEG = 20.0
"""... while another source or the course turned by more than this, °."""

REJUDGE_S = 5.0
"""While a pair disagrees its verdict is made again this often, s."""

COURSE = ".course"
"""The suffix of a GNSS port's name that names its course as a source."""


def source_name(port: str, sentence: str) -> str:
    """A heading source's name: its port and the sentence it came in (``compass.HDT``,
    ``dvl.PD6``; the port alone for a sentence not known)."""
    return f"{port}.{sentence}" if sentence else port


def port_of(name: str) -> str:
    """The port of a source's name (:func:`source_name`)."""
    return name.rsplit(".", 1)[0] if "." in name else name


def angle_diff(a: float, b: float) -> float:
    """``a − b`` in (−180, 180], °."""
    d = (a - b + 180.0) % 360.0 - 180.0
    return 180.0 if d == -180.0 else d


class PairWindow:
    """One pair's comparisons over :data:`~emlogd.pipeline.headingcheck.WINDOW_S`."""

    __slots__ = ("_bad", "_samples", "diff_deg", "disagree", "t_last")

    def __init__(self) -> None:
        self._samples: deque[tuple[float, bool]] = deque()
        self._bad = 0
        self.disagree = False
        self.diff_deg = 0.0
        """The last difference, first source minus second, °."""
        self.t_last = -math.inf

    def add(self, t: float, diff_deg: float, bad: bool) -> bool:
        """One comparison; True when the verdict changed (judged agreeing included)."""
        s = self._samples
        self.diff_deg, self.t_last = diff_deg, t
        s.append((t, bad))
        self._bad += bad
        while s and t - s[0][0] > WINDOW_S:
            self._bad -= s.popleft()[1]
        was = (self.disagree, self.agrees(t))
        if self.judged:
            frac = self._bad / len(s)
            if frac >= BAD_FRACTION:
                self.disagree = True
            elif frac < 0.5 * BAD_FRACTION:
                self.disagree = False
        return (self.disagree, self.agrees(t)) != was

    @property
    def judged(self) -> bool:
        """Enough comparisons over enough time for a verdict."""
        s = self._samples
        return len(s) >= MIN_SAMPLES and s[-1][0] - s[0][0] >= 0.5 * WINDOW_S

    def agrees(self, now: float) -> bool:
        """Judged, recent, and below half the disagreeing fraction."""
        return (
            self.judged
            and now - self.t_last <= WINDOW_S
            and self._bad < 0.5 * BAD_FRACTION * len(self._samples)
        )

    def disagrees(self, now: float) -> bool:
        """Judged disagreeing, and compared within the window."""
        return self.disagree and now - self.t_last <= WINDOW_S


class Source:
    """One source's latest sample, turn rate and repeated value."""

    __slots__ = ("base", "frozen", "h", "h_rate", "rate_dps", "run_h", "run_t0", "t", "t_rate")

    def __init__(self, t: float, h: float) -> None:
        self.t, self.h = t, h
        self.t_rate, self.h_rate = t, h
        self.rate_dps = 0.0
        self.run_t0, self.run_h = t, h
        """Since when the source repeats ``run_h``."""
        self.base: dict[str, float] = {}
        """Each other source's first value since :attr:`run_t0`."""
        self.frozen = ""

    def update(self, t: float, h: float) -> bool:
        """A new sample; True when it ends a frozen run."""
        self.t, self.h = t, h
        if t - self.t_rate >= RATE_BASE_S:
            self.rate_dps = abs(angle_diff(h, self.h_rate)) / (t - self.t_rate)
            self.t_rate, self.h_rate = t, h
        if abs(angle_diff(h, self.run_h)) <= FROZEN_EPS_DEG:
            return False
        self.run_t0, self.run_h = t, h
        self.base.clear()
        thawed = bool(self.frozen)
        self.frozen = ""
        return thawed


class HeadingSources:
    """Every heading source compared with every other (see the module docstring)."""

    def __init__(self) -> None:
        self.sources: dict[str, Source] = {}
        self.pairs: dict[tuple[str, str], PairWindow] = {}
        self.wrong: dict[str, str] = {}
        """The heading ports not to read a heading from, and why."""
        self.unresolved: dict[tuple[str, str], str] = {}
        """The pairs that disagree with nothing to tell which is right, and why."""
        self.events: list[tuple[float, str, str, dict[str, object]]] = []
        """(time, port, kind, detail) of each change of verdict, for the pipeline to hand out."""
        self.version = 0
        """Bumped at each change of :attr:`wrong` or :attr:`unresolved`."""
        self.pairs_disagree = False
        """Some pair disagreed at the last verdict: judged again every :data:`REJUDGE_S`
        (a pair falls silent, a third source's window fills)."""
        self._t_judged = -math.inf

    def heading(self, t: float, port: str, h: float) -> None:
        """A true heading of ``port`` at ``t``, °."""
        self._sample(t, port, h, course=False)

    def course(self, t: float, port: str, sog_mps: float, cog_deg: float) -> None:
        """A GNSS fix's course over ground (ignored below :data:`COURSE_MIN_SOG_MPS`)."""
        if sog_mps >= COURSE_MIN_SOG_MPS and math.isfinite(cog_deg):
            self._sample(t, port + COURSE, cog_deg, course=True)

    def _sample(self, t: float, name: str, h: float, *, course: bool) -> None:
        src = self.sources.get(name)
        changed = False
        if src is None:
            src = self.sources[name] = Source(t, h)
        elif t < src.t:
            return
        else:
            changed = src.update(t, h) and not course
        for other, o in self.sources.items():
            if other == name:
                continue
            if not other.endswith(COURSE):
                changed = self._turned(t, name, h, other, o) or changed
            if abs(t - o.t) <= COMMON_S and not (course and other.endswith(COURSE)):
                changed = self._compare(t, name, src, other, o) or changed
        if changed or (self.pairs_disagree and t - self._t_judged >= REJUDGE_S):
            self._judge(t)

    def _turned(self, t: float, name: str, h: float, other: str, o: Source) -> bool:
        """Whether ``name``'s sample shows ``other`` frozen (newly)."""
        if o.frozen or t - o.t > COMMON_S:
            return False
        base = o.base.setdefault(name, h)
        turned = abs(angle_diff(h, base))
        if turned <= FROZEN_TURN_DEG or t - o.run_t0 < FROZEN_S:
            return False
        o.frozen = (
            f"repeats {o.run_h:.1f}° for {t - o.run_t0:.0f} s while {name} turned {turned:.0f}°"
        )
        return True

    def _compare(self, t: float, name: str, src: Source, other: str, o: Source) -> bool:
        key = (name, other) if name < other else (other, name)
        w = self.pairs.get(key)
        if w is None:
            w = self.pairs[key] = PairWindow()
        elif t - w.t_last < COMPARE_INTERVAL_S:
            return False
        rate = max(src.rate_dps, o.rate_dps)
        if name.endswith(COURSE) or other.endswith(COURSE):
            if rate > STRAIGHT_RATE_DPS:
                return False
            tol = COURSE_AGREE_DEG
        else:
            tol = AGREE_DEG + rate * (LAG_ALLOWANCE_S + abs(t - o.t))
        d = angle_diff(self.sources[key[0]].h, self.sources[key[1]].h)
        return w.add(t, d, abs(d) > tol)

    def _judge(self, t: float) -> None:
        """The wrong sources and the unresolved pairs, from the pairs and frozen runs."""
        wrong = {n: f"{n} frozen: {s.frozen}" for n, s in self.sources.items() if s.frozen}
        unresolved: dict[tuple[str, str], str] = {}
        self._t_judged = t
        self.pairs_disagree = any(w.disagree for w in self.pairs.values())
        for (a, b), w in self.pairs.items():
            if a.endswith(COURSE) or b.endswith(COURSE) or not w.disagrees(t):
                continue
            if a in wrong or b in wrong:
                continue
            gap = f"{a} and {b} {abs(w.diff_deg):.0f}° apart"
            found = self._arbitrate(t, a, b, wrong)
            held = [n for n in (a, b) if n in self.wrong and " frozen: " not in self.wrong[n]]
            if found is not None:
                wrong[found[0]] = f"{gap}: {found[1]}"
            elif held:  # a verdict stands while its pair disagrees (in a turn: no course)
                wrong[held[0]] = self.wrong[held[0]]
            else:
                unresolved[(a, b)] = f"{gap}, nothing tells which is right"
        self._changes(t, wrong, unresolved)

    def _arbitrate(self, t: float, a: str, b: str, wrong: dict[str, str]) -> tuple[str, str] | None:
        """The wrong one of the disagreeing ``a`` and ``b`` and why, by a third source
        agreeing with one and disagreeing with the other; None when none tells."""
        for r in self.sources:
            if r in (a, b) or r in wrong:
                continue
            wa, wb = self._pair(a, r), self._pair(b, r)
            if wa is None or wb is None:
                continue
            if wa.agrees(t) and wb.disagrees(t):
                return b, f"{r} agrees with {a}"
            if wb.agrees(t) and wa.disagrees(t):
                return a, f"{r} agrees with {b}"
        return None

    def _changes(
        self, t: float, wrong: dict[str, str], unresolved: dict[tuple[str, str], str]
    ) -> None:
        """Adopt a verdict: an event for each change (:attr:`events`)."""
        for n in sorted(set(wrong) - set(self.wrong)):
            detail: dict[str, object] = {"source": n, "why": wrong[n]}
            self.events.append((t, port_of(n), "heading_source_wrong", detail))
        for n in sorted(set(self.wrong) - set(wrong)):
            self.events.append((t, port_of(n), "heading_source_right", {"source": n}))
        for a, b in sorted(set(unresolved) - set(self.unresolved)):
            detail = {"sources": [a, b], "why": unresolved[(a, b)]}
            self.events.append((t, port_of(a), "heading_sources_disagree", detail))
        for a, b in sorted(set(self.unresolved) - set(unresolved)):
            detail = {"sources": [a, b]}
            self.events.append((t, port_of(a), "heading_sources_resolved", detail))
        if wrong.keys() != self.wrong.keys() or unresolved.keys() != self.unresolved.keys():
            self.version += 1
        # a verdict kept keeps its words (the difference it was found at)
        self.wrong = {n: self.wrong.get(n, why) for n, why in wrong.items()}
        self.unresolved = {k: self.unresolved.get(k, why) for k, why in unresolved.items()}

    def _pair(self, a: str, b: str) -> PairWindow | None:
        return self.pairs.get((a, b) if a < b else (b, a))

    def usable(self, name: str) -> bool:
        """Whether a heading may be read from source ``name`` (not :attr:`wrong`)."""
        return name not in self.wrong

    def suspect(self, order: Sequence[str]) -> str:
        """Why a UUT reading its heading from the ports of ``order`` has none to trust,
        or ``""``: two of them disagree and nothing tells which is right."""
        for (a, b), why in self.unresolved.items():
            if port_of(a) in order or port_of(b) in order:
                return f"heading sources disagree: {why}"
        return ""

    def status(self) -> dict[str, object]:
        """The sources heard, each pair's last difference and verdict, the wrong ones."""
        return {
            "heard": sorted(self.sources),
            "pairs": {
                f"{a}/{b}": {
                    "diff_deg": round(w.diff_deg, 1),
                    "disagree": w.disagree,
                }
                for (a, b), w in sorted(self.pairs.items())
            },
            "wrong": dict(self.wrong),
            "unresolved": [f"{a}/{b}" for a, b in sorted(self.unresolved)],
        }
