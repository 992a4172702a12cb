"""The verdict on each unknown of a window: whether the data determine it, and why not.

:mod:`calib.excitation` (one axis) and :mod:`calib.twoaxis_ident` (two axes) judge
their windows into these.

Must not import: drivers, emlogd, or any I/O module (the stdlib and :mod:`calib.errors`
only).
"""

from __future__ import annotations

from dataclasses import dataclass

from calib.errors import ModelError


@dataclass(frozen=True, slots=True)
class Verdict:
    """Whether one unknown is determined by a window, and why not.

    Attributes:
        unknown: ``"a"``, ``"m"``, ``"b"`` or ``"current"`` (on two axes also
            ``"alpha"``, ``"m_t"``, ``"b_t"``).
        determined: the data determine it.
        reason: why not, in words a person understands (empty when determined).
        std: its standard deviation from the information matrix (the larger
            component for the current), in its unit; None when not determined.
    """

    unknown: str
    determined: bool
    reason: str
    std: float | None


class Verdicts:
    """What a window's verdicts tell, for the classes that hold them in ``verdicts``
    (:class:`calib.excitation.Identifiability`, :class:`calib.twoaxis.TwoAxisIdent`)."""

    __slots__ = ()
    verdicts: tuple[Verdict, ...]

    def verdict(self, unknown: str) -> Verdict:
        """The verdict on one unknown.

        Raises:
            ModelError: not an unknown of this window.
        """
        for v in self.verdicts:
            if v.unknown == unknown:
                return v
        raise ModelError(f"{unknown!r} is not an unknown of this window")

    @property
    def identifiable(self) -> bool:
        """Every unknown is determined."""
        return not self.unidentifiable

    @property
    def determined(self) -> tuple[str, ...]:
        """The unknowns the window determines."""
        return tuple(v.unknown for v in self.verdicts if v.determined)

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """The unknowns it does not determine (empty when all are)."""
        return tuple(v.unknown for v in self.verdicts if not v.determined)

    @property
    def reason(self) -> str:
        """Every refusal in words, each once, ``"; "``-separated (empty when all are
        determined)."""
        seen: list[str] = []
        for v in self.verdicts:
            if not v.determined and v.reason not in seen:
                seen.append(v.reason)
        return "; ".join(seen)
