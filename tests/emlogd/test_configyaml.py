"""Hostile YAML: the nesting refused before parsing, and the one-line reasons."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any, TypeAlias

import pytest
import yaml

from emlogd.configyaml import MAX_YAML_DEPTH, YAML_FAILURES, yaml_depth_error, yaml_why

TraceFunction: TypeAlias = Callable[[FrameType, str, Any], "TraceFunction | None"]
"""What ``sys.settrace`` takes."""

YAML_PACKAGE = Path(yaml.__file__).parent


def test_nesting_past_the_bound_is_refused_and_within_it_passes() -> None:
    """``MAX_YAML_DEPTH`` brackets deep passes, one more is refused; closing brackets
    count down, so a long flat file of shallow lists passes."""
    ok = "a: " + "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH
    assert yaml_depth_error(ok) == ""
    deep = "a: " + "{x: " * (MAX_YAML_DEPTH + 1) + "1" + "}" * (MAX_YAML_DEPTH + 1)
    assert "nested deeper" in yaml_depth_error(deep)
    assert yaml_depth_error("a: [1, [2]]\n" * 10000) == ""


LINEAR_GROWTH = 4.5
"""Most the check's work may grow when its text grows fourfold: linear (4) and a margin
for the constant part; a pass over the text per bracket grows sixteenfold."""


def _python_lines(check: Callable[[str], str], text: str, limit: int) -> int:
    """Python lines run by ``check(text)`` and everything it calls (the machine's speed
    aside); past ``limit`` it fails at once rather than run a quadratic scan to its end,
    and so does a call into the YAML parser (whose scanner's quadratic part is in C)."""
    lines = 0

    def local(frame: FrameType, event: str, arg: Any) -> TraceFunction:
        nonlocal lines
        if event == "line":
            lines += 1
            if lines > limit:
                raise AssertionError(f"more than {limit} lines for {len(text)} characters")
        return local

    def call(frame: FrameType, event: str, arg: Any) -> TraceFunction:
        if Path(frame.f_code.co_filename).is_relative_to(YAML_PACKAGE):
            raise AssertionError(f"the check ran the YAML parser ({frame.f_code.co_name})")
        return local

    previous = sys.gettrace()
    sys.settrace(call)
    try:
        check(text)
    finally:
        sys.settrace(previous)
    return lines


@pytest.mark.parametrize(
    "brackets",
    [
        pytest.param(lambda n: "[" * n, id="deep"),
        pytest.param(lambda n: "[]" * (n // 2), id="flat"),
        pytest.param(lambda n: "a: [1, [2]]\n" * (n // 12), id="a-long-file"),
    ],
)
def test_the_check_is_linear_where_the_parser_is_not(brackets: Callable[[int], str]) -> None:
    """The check's work on four times the brackets is at most LINEAR_GROWTH times its work
    on them, counted in Python lines run, and it never calls the YAML parser (whose scanner
    took 1.7 s on two kilobytes of nested brackets, and four times as long on twice as
    many)."""
    n = 1 << 8
    small = _python_lines(yaml_depth_error, brackets(n), limit=1 << 30)
    assert _python_lines(yaml_depth_error, brackets(4 * n), int(LINEAR_GROWTH * small)) > 0


@pytest.mark.parametrize("text", ["a: 2001-02-30", "a: !!timestamp x", "a: !!bool x"])
def test_each_failure_of_the_safe_loader_is_listed(text: str) -> None:
    """What the safe loader raises on these is one of ``YAML_FAILURES``, with a reason."""
    with pytest.raises(YAML_FAILURES) as info:
        yaml.safe_load(text)
    assert yaml_why(info.value)


def test_a_recursion_error_reads_as_nesting() -> None:
    assert yaml_why(RecursionError("maximum recursion depth exceeded")) == "nested too deep"
