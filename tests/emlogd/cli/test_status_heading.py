"""``emlogd status``: the heading line under each UUT."""

from __future__ import annotations

from emlogd.cli.daemon import _change_text, _status_text


def _resp(heading: dict[str, object], reason: str) -> dict[str, object]:
    uut = {"state": "uncalibrated", "reference": "stale", "model": "EM3", "heading": heading}
    return {"ok": True, "status": {"uuts": {"nmea": {**uut, "reason": reason}}, "ports": {}}}


def test_the_variation_and_its_source_are_shown() -> None:
    """The heading's port, the variation with where it came from, the check's offset."""
    h = {
        "port": "nmea",
        "variation_deg": 1.34,
        "variation_source": "model",
        "refused_magnetic": 2,
        "check": {"offset_deg": 0.4, "flagged": False},
    }
    text = _status_text(_resp(h, ""))
    assert (
        "  heading from nmea, variation +1.34° (model), 2 magnetic headings refused "
        "(no variation), +0.4° from the course\n"
    ) in text


def test_a_refused_heading_and_its_reason() -> None:
    """No usable heading: the refusals and the status reason that names them."""
    h: dict[str, object] = {
        "port": None,
        "variation_deg": None,
        "refused_magnetic": 30,
        "check": {},
    }
    reason = "heading magnetic without a variation (30 refused): set magnetic_variation_deg"
    text = _status_text(_resp(h, reason))
    assert f"nmea: uncalibrated ({reason}), reference stale" in text
    assert "  heading from no port yet, 30 magnetic headings refused (no variation)\n" in text


def test_the_unknowns_held_and_the_inputs_freshness() -> None:
    """What a UUT holds and why, and how old its reading, reference and heading are."""
    uut = {
        "state": "learning",
        "reason": "estimating the lag, 29 of 300 s",
        "reference": "stale",
        "model": "EM3",
        "unidentifiable": ["scale"],
        "identifiability": "scale not determinable: speed through water nearly constant",
        "inputs": {
            "reading": {"port": "emlog1", "age_s": 0.4, "stale": False},
            "reference": {"port": "dvl", "age_s": 12.0, "stale": True, "used_age_s": 12.3},
            "heading": {"port": None, "age_s": None, "stale": False},
        },
    }
    text = _status_text({"status": {"uuts": {"emlog1": uut}, "ports": {}}})
    lines = text.splitlines()
    assert lines[0].startswith("emlog1: learning (estimating the lag, 29 of 300 s), ")
    assert lines[1] == (
        "  holding scale: scale not determinable: speed through water nearly constant"
    )
    assert lines[2] == (
        "  inputs: reading emlog1 0.4 s ago, reference dvl 12.0 s ago STALE "
        "(last used 12.3 s ago), heading no port yet"
    )


def test_ports_open_not_open_and_stale() -> None:
    """A port never opened says so and why; a stale one says STALE, not a quiet count."""
    ports = {
        "dvl": {"records": 5, "rejects": {}, "stale": True, "state": "stale"},
        "emlog2": {
            "records": 0,
            "rejects": {},
            "stale": True,
            "state": "not open",
            "why_closed": "cannot open /dev/missing: no such file",
        },
        "emlog1": {"records": 9, "rejects": {"checksum": 1}, "stale": False, "state": "open"},
    }
    text = _status_text({"status": {"uuts": {}, "ports": ports}})
    assert text.splitlines() == [
        "port dvl: stale, 5 records, 0 rejects",
        "port emlog2: not open (cannot open /dev/missing: no such file), 0 records, 0 rejects",
        "port emlog1: open, 9 records, 1 rejects (checksum 1)",
    ]


def test_freeze_reply_matches_the_state_left() -> None:
    """freeze of a calibrated UUT says frozen; of an uncalibrated one, that there is nothing
    to apply (not "frozen")."""
    resp = {"uuts": ["a", "b"], "states": {"a": "frozen", "b": "uncalibrated"}}
    assert _change_text("freeze", resp) == (
        "a: frozen (learning off, the calibration applied)\n"
        "b: learning off; no calibration to apply (raw readings pass through)\n"
    )
