"""The hypothesis profiles of the test suite.

A property test marked ``fuzz`` runs in the default run with its quick number of
examples, and with :data:`LONG_EXAMPLES` under the long profile: ``pytest -m fuzz``
(those tests alone) or ``HYPOTHESIS_PROFILE=fuzz`` (whatever runs). The profile is
chosen by ``tests/conftest.py`` before the test modules are imported, so the
``@settings`` of each test read it through :func:`by_profile`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

from hypothesis import settings

QUICK = "quick"
"""The default run's profile: each property test's own number of examples."""

LONG = "fuzz"
"""The long profile."""

LONG_EXAMPLES = 100_000
"""Examples per property test in the long profile (unless the test names another)."""

ENV = "HYPOTHESIS_PROFILE"
"""The environment variable that selects a profile by name."""

settings.register_profile(QUICK, deadline=None)
settings.register_profile(LONG, deadline=None, max_examples=LONG_EXAMPLES)


def choose(markexpr: str, environ: Mapping[str, str]) -> str:
    """The profile of a run: :data:`ENV`'s if set, the long one when the mark expression
    selects ``fuzz`` (not ``not fuzz``), else the quick one."""
    named = environ.get(ENV)
    if named:
        return named
    return LONG if re.search(r"(?<!not )\bfuzz\b", markexpr) else QUICK


def by_profile(quick: int, long: int = LONG_EXAMPLES) -> int:
    """``quick`` in the quick profile, ``long`` in the long one: a fuzz test's number of
    examples, or the size of what it draws."""
    return long if settings.get_current_profile_name() == LONG else quick
