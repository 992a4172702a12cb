"""Staleness: one rule (silent longer than the timeout) and the ports' liveness."""

from __future__ import annotations

from emlogd.pipeline.staleness import Liveness, silent


def test_silent_is_strictly_longer_than_the_timeout() -> None:
    """Stale only after more than the timeout; an input never heard is not stale."""
    assert not silent(10.0, 15.0, 5.0)
    assert silent(10.0, 15.001, 5.0)
    assert not silent(None, 1e9, 5.0)


def test_a_port_goes_stale_once_and_comes_back_alive() -> None:
    """Each port has its own timeout; stale is reported once with the silence, and data
    again says so once."""
    live = Liveness({"dvl": 3.0, "log": 5.0})
    assert not live.heard("dvl", 100.0) and not live.heard("log", 100.0)
    assert live.check(103.0) == []
    assert live.check(103.5) == [("dvl", 3.5)]
    assert live.check(104.0) == []  # reported once
    assert live.stale == {"dvl": True, "log": False}
    assert live.check(105.5) == [("log", 5.5)]
    assert live.heard("dvl", 106.0) is True  # alive again
    assert live.heard("dvl", 106.1) is False
    assert live.stale["dvl"] is False and live.last["dvl"] == 106.1


def test_a_reload_takes_over_the_ports_it_keeps() -> None:
    """adopt() carries staleness and last data of the kept ports only."""
    old = Liveness({"dvl": 3.0, "log": 5.0})
    old.heard("dvl", 100.0)
    old.heard("log", 100.0)
    old.check(104.0)
    new = Liveness({"dvl": 3.0, "log": 1.0})
    new.adopt(old, ["dvl"])
    assert new.stale == {"dvl": True, "log": False} and new.last == {"dvl": 100.0}
