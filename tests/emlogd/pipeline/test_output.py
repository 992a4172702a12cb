"""What one pipeline call returns (:mod:`emlogd.pipeline.output`)."""

from __future__ import annotations

from emlogd.pipeline.output import Emit, Event, Output


def test_outputs_added_keep_each_calls_order_after_the_first() -> None:
    """A caller collecting several calls gets their sentences and events in call order."""
    first, second = Output(), Output()
    first.emits.append(Emit(1.0, "emlog1", "$A"))
    first.events.append(Event(1.0, "emlog1", "stale", {}))
    second.emits += [Emit(2.0, "emlog1", "$B"), Emit(2.5, "emlog2", "$C")]
    second.events.append(Event(2.0, "dvl", "alive", {"n": 1}))
    first.add(second)
    assert [e.sentence for e in first.emits] == ["$A", "$B", "$C"]
    assert [e.kind for e in first.events] == ["stale", "alive"]
    assert first.persist == [] and second.emits[0].t == 2.0  # the other left as it was


def test_a_new_output_is_empty_and_shares_nothing() -> None:
    """Each call's output is its own: two new ones share no list."""
    a, b = Output(), Output()
    a.emits.append(Emit(0.0, "x", "$X"))
    assert b.emits == [] and b.events == [] and b.persist == []
