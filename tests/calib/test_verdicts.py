"""The verdicts of a window: which unknowns it determines, and why not the others."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from calib.errors import ModelError
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
    assert w.identifiable


def test_one_unknowns_verdict_and_an_unknown_that_is_not_there() -> None:
    """verdict() finds an unknown's own verdict; a name the window does not hold is a
    ModelError naming it; one refusal makes the window not identifiable."""
    b = Verdict("b", False, "bias not determinable", None)
    w = _Window((Verdict("m", True, "", 0.01), b))
    assert w.verdict("b") is b
    assert not w.identifiable
    with pytest.raises(ModelError, match="'alpha' is not an unknown"):
        w.verdict("alpha")
