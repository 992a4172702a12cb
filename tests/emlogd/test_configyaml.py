"""Hostile YAML: the nesting refused before parsing, and the one-line reasons."""

from __future__ import annotations

import time

import pytest
import yaml

from emlogd.configyaml import MAX_YAML_DEPTH, YAML_FAILURES, yaml_depth_error, yaml_why


def test_nesting_past_the_bound_is_refused_and_within_it_passes() -> None:
    """``MAX_YAML_DEPTH`` brackets deep passes, one more is refused; closing brackets
    count down, so a long flat file of shallow lists passes."""
    ok = "a: " + "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH
    assert yaml_depth_error(ok) == ""
    deep = "a: " + "{x: " * (MAX_YAML_DEPTH + 1) + "1" + "}" * (MAX_YAML_DEPTH + 1)
    assert "nested deeper" in yaml_depth_error(deep)
    assert yaml_depth_error("a: [1, [2]]\n" * 10000) == ""


def test_the_check_is_fast_where_the_parser_is_not() -> None:
    """A megabyte of brackets is judged in well under a second (the parser's scanner took
    1.7 s on two kilobytes of them)."""
    t0 = time.process_time()
    assert yaml_depth_error("[" * (1 << 20))
    assert yaml_depth_error("[]" * (1 << 19)) == ""
    assert time.process_time() - t0 < 1.0


@pytest.mark.parametrize("text", ["a: 2001-02-30", "a: !!timestamp x", "a: !!bool x"])
def test_each_failure_of_the_safe_loader_is_listed(text: str) -> None:
    """What the safe loader raises on these is one of ``YAML_FAILURES``, with a reason."""
    with pytest.raises(YAML_FAILURES) as info:
        yaml.safe_load(text)
    assert yaml_why(info.value)


def test_a_recursion_error_reads_as_nesting() -> None:
    assert yaml_why(RecursionError("maximum recursion depth exceeded")) == "nested too deep"
