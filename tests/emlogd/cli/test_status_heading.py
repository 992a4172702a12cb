"""``emlogd status``: the heading line under each UUT."""

from __future__ import annotations

from emlogd.cli.daemon import _status_text


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
        "(no variation), +0.4° from the course; learning\n"
    ) in text


def test_a_refused_heading_and_its_reason() -> None:
    """No usable heading: the refusals and the status reason that names them."""
    h = {"port": None, "variation_deg": None, "refused_magnetic": 30, "check": {}}
    reason = "heading magnetic without a variation (30 refused): set magnetic_variation_deg"
    text = _status_text(_resp(h, reason))
    assert (
        f"heading from no port yet, 30 magnetic headings refused (no variation); {reason}" in text
    )
