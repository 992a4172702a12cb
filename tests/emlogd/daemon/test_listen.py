"""AcceptPause: resource errors pause a listener with a growing delay, reported rate-limited;
AcceptBudget: connections per source and in all."""

from __future__ import annotations

import errno

from emlogd.daemon.listen import (
    ALL_BURST,
    ALL_RATE,
    PAUSE_S,
    REPORT_S,
    SOURCE_BURST,
    SOURCE_RATE,
    SOURCES_KEPT,
    AcceptBudget,
    AcceptPause,
)


def _err(code: int) -> OSError:
    return OSError(code, "boom")


def test_a_resource_error_pauses_and_the_pause_ends_once() -> None:
    """EMFILE pauses for PAUSE_S[0]; resume_due is true once, after the pause."""
    now = [0.0]
    reports: list[str] = []
    pause = AcceptPause(reports.append, lambda: now[0])
    assert pause.failed(_err(errno.EMFILE)) and pause.until is not None  # paused
    assert not pause.resume_due()
    now[0] = PAUSE_S[0]
    assert pause.resume_due() and not pause.paused and not pause.resume_due()
    assert len(reports) == 1 and "not accepting" in reports[0]


def test_other_errors_do_not_pause() -> None:
    """An error that concerns one connection (ECONNABORTED) is counted, not paused on."""
    pause = AcceptPause(lambda d: None, lambda: 0.0)
    assert not pause.failed(_err(errno.ECONNABORTED)) and not pause.paused
    assert pause.errors == 1


def test_pauses_grow_and_reports_are_rate_limited() -> None:
    """Consecutive failures pause longer (up to the last delay); one report per REPORT_S
    says how many failures went unreported; an accepted connection resets the delay."""
    now = [0.0]
    reports: list[str] = []
    pause = AcceptPause(reports.append, lambda: now[0])
    for k in range(len(PAUSE_S) + 2):
        pause.failed(_err(errno.EMFILE))
        assert pause.until == now[0] + PAUSE_S[min(k, len(PAUSE_S) - 1)]
        now[0] = pause.until
        assert pause.resume_due()
    assert len(reports) == 1
    now[0] += REPORT_S
    pause.failed(_err(errno.ENFILE))
    assert len(reports) == 2 and f"{len(PAUSE_S) + 1} more" in reports[1]
    pause.accepted()
    pause.failed(_err(errno.EMFILE))
    assert pause.until == now[0] + PAUSE_S[0]


def test_the_accept_budget_holds_a_source_to_its_rate_and_spares_the_others() -> None:
    """One source gets SOURCE_BURST connections at once, then SOURCE_RATE a second; its
    refused excess spends nothing of the budget of all, so another source gets in."""
    now = [0.0]
    budget = AcceptBudget(lambda: now[0])
    assert all(budget.admit("10.0.0.1") for _ in range(SOURCE_BURST))
    assert not any(budget.admit("10.0.0.1") for _ in range(1000))
    assert budget.admit("10.0.0.2")
    now[0] = 1.0 / SOURCE_RATE
    assert budget.admit("10.0.0.1") and not budget.admit("10.0.0.1")


def test_the_budget_of_all_sources_holds_many_sources() -> None:
    """Each a new address: ALL_BURST at once, then ALL_RATE a second in all; the sources
    remembered never pass SOURCES_KEPT."""
    now = [0.0]
    budget = AcceptBudget(lambda: now[0])
    admitted = sum(budget.admit(f"10.1.{k // 256}.{k % 256}") for k in range(5000))
    assert admitted == ALL_BURST
    assert len(budget.sources) <= SOURCES_KEPT
    now[0] = 1.0
    admitted = sum(budget.admit(f"10.2.{k // 256}.{k % 256}") for k in range(1000))
    assert admitted == int(ALL_RATE)
