"""The hypothesis profiles: which one a run loads, and what a fuzz test reads from it."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import settings

from tests.profiles import ENV, LONG, LONG_EXAMPLES, QUICK, by_profile, choose


@pytest.mark.parametrize(
    ("markexpr", "environ", "profile"),
    [
        ("not soak and not real and not root", {}, QUICK),  # the default run
        ("fuzz", {}, LONG),  # pytest -m fuzz
        ("fuzz and not soak", {}, LONG),
        ("not fuzz", {}, QUICK),
        ("", {ENV: LONG}, LONG),  # HYPOTHESIS_PROFILE=fuzz, whatever the marks
        ("fuzz", {ENV: QUICK}, QUICK),  # the variable wins
    ],
)
def test_the_run_chooses_its_profile(markexpr: str, environ: dict[str, str], profile: str) -> None:
    """The long profile for -m fuzz or HYPOTHESIS_PROFILE=fuzz; the quick one otherwise."""
    assert choose(markexpr, environ) == profile


@pytest.fixture
def restore_profile() -> Iterator[None]:
    before = settings.get_current_profile_name()
    yield
    settings.load_profile(before)


@pytest.mark.usefixtures("restore_profile")
def test_a_fuzz_test_reads_its_size_from_the_profile() -> None:
    """A fuzz test's own quick count in the quick profile, the long count in the long one."""
    settings.load_profile(QUICK)
    assert by_profile(300) == 300 and by_profile(25, 3000) == 25
    settings.load_profile(LONG)
    assert by_profile(300) == LONG_EXAMPLES and by_profile(25, 3000) == 3000
    assert settings.default is not None
    assert settings.default.max_examples == LONG_EXAMPLES
