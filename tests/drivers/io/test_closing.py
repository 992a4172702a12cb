"""The ``with`` protocol shared by the resources that close."""

from __future__ import annotations

import pytest

from drivers.io.closing import Closing


class _Counted(Closing):
    """Counts its closes."""

    def __init__(self) -> None:
        self.closes = 0

    def close(self) -> None:
        self.closes += 1


def test_with_returns_the_resource_and_closes_it() -> None:
    """Entering gives the resource itself; leaving closes it once."""
    r = _Counted()
    with r as entered:
        assert entered is r and r.closes == 0
    assert r.closes == 1


def test_an_exception_closes_and_propagates() -> None:
    """An exception inside the block still closes the resource and is not swallowed."""
    r = _Counted()
    with pytest.raises(RuntimeError, match="boom"), r:
        raise RuntimeError("boom")
    assert r.closes == 1


def test_a_resource_without_close_cannot_be_built() -> None:
    """close is abstract: a subclass that forgets it is refused at construction."""

    class _NoClose(Closing):
        pass

    with pytest.raises(TypeError):
        _NoClose()  # type: ignore[abstract]
