"""YAML that may be hostile, read by the config and the state file alike: what PyYAML's
safe loader raises besides ``YAMLError`` (:data:`YAML_FAILURES`), and the nesting refused
before the parser sees the text (:func:`yaml_depth_error`)."""

from __future__ import annotations

import re

import yaml

YAML_FAILURES: tuple[type[Exception], ...] = (
    yaml.YAMLError,
    ValueError,
    TypeError,
    KeyError,
    AttributeError,
    OverflowError,
    RecursionError,
)
"""What PyYAML's safe loading raises on hostile text: besides ``YAMLError``, its
constructors' ``ValueError`` (a date ``2001-02-30``, ``!!int 0x``, an integer of more
than 4300 digits), ``AttributeError`` (``!!timestamp x``), ``KeyError`` (``!!bool x``),
and ``RecursionError`` for nesting deeper than the interpreter's stack (``[[[…]]]``).
The config and the state file turn each into their own error, naming the file."""

MAX_YAML_DEPTH = 32
"""Deepest nesting of flow brackets (``[`` and ``{``) read from a config or a state file
(theirs go two deep). Deeper text is refused before the YAML parser sees it: its
scanner took 1.7 s on a thousand brackets (2 KB; 2 cores at load 10), and nesting past the interpreter's
stack ends in RecursionError."""

_BRACKETS = re.compile(r"[\[\]{}]")


def yaml_depth_error(text: str) -> str:
    """``""``, or why ``text`` is nested too deep to be parsed (:data:`MAX_YAML_DEPTH`;
    brackets in strings and comments count too, which no file of ours has)."""
    depth = 0
    for m in _BRACKETS.finditer(text):
        if m[0] in "[{":
            depth += 1
            if depth > MAX_YAML_DEPTH:
                return f"nested deeper than {MAX_YAML_DEPTH} brackets"
        elif depth:
            depth -= 1
    return ""


def yaml_why(exc: Exception) -> str:
    """One line on a YAML failure: a RecursionError's is the nesting."""
    if isinstance(exc, RecursionError):
        return "nested too deep"
    return " ".join(str(exc).split())[:200] or type(exc).__name__
