"""The verdicts of a window: which unknowns it determines, and why not the others."""

from __future__ import annotations

from dataclasses import dataclass

from calib.verdicts import Verdict, Verdicts


@dataclass(frozen=True, slots=True)
class _Window(Verdicts):
    verdicts: tuple[Verdict, ...]


def test_determined_refused_and_each_reason_once() -> None:
    """The order is the verdicts'; a reason two unknowns share is given once."""
    why = "current not separable from bias: heading covered 1 of 8 sectors"
    w = _Window(
        (
            Verdict("m", True, "", 0.01),
            Verdict("b", False, why, None),
            Verdict("current", False, why, None),
            Verdict("a", False, "scale not determinable", None),
        )
    )
    assert w.determined == ("m",)
    assert w.unidentifiable == ("b", "current", "a")
    assert w.reason == f"{why}; scale not determinable"


def test_all_determined_gives_no_reason() -> None:
    w = _Window((Verdict("m", True, "", 0.01), Verdict("b", True, "", 0.002)))
    assert w.unidentifiable == ()
    assert w.reason == ""
