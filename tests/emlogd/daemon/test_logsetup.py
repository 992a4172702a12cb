"""structlog configuration."""

from __future__ import annotations

import io
import json

import pytest
import structlog

from emlogd.daemon.logsetup import configure_logging, is_console, status_line


class TestConfigureLogging:
    """JSON off a terminal, console on one, level filtering."""

    def test_json_when_not_a_tty(self) -> None:
        """With format auto and a non-tty stream, each event is one JSON line."""
        buf = io.StringIO()
        configure_logging("auto", "info", buf)
        structlog.get_logger("t").info("port_opened", port="dvl")
        event = json.loads(buf.getvalue())
        assert event["event"] == "port_opened"
        assert event["port"] == "dvl"
        assert event["level"] == "info"

    def test_level_filters(self) -> None:
        """Events below the configured level are not written."""
        buf = io.StringIO()
        configure_logging("json", "warning", buf)
        structlog.get_logger("t").info("quiet")
        assert buf.getvalue() == ""

    def test_console_format(self) -> None:
        """The console renderer writes a human line, not JSON."""
        buf = io.StringIO()
        configure_logging("console", "info", buf)
        structlog.get_logger("t").info("hello", n=3)
        assert "hello" in buf.getvalue()
        assert not buf.getvalue().startswith("{")

    def test_console_status_is_one_short_line(self) -> None:
        """On a terminal the periodic status is a few words per UUT and port, not the dicts."""
        buf = io.StringIO()
        configure_logging("console", "info", buf)
        assert is_console()
        status = {
            "uuts": {"emlog1": {"state": "frozen", "params": {"m": 0.1, "b": 0.05},
                                "reference": "valid", "counters": {"learnt": 9} }},
            "ports": {"emlog1": {"records": 12, "rejects": {"checksum": 0}}},
        }  # fmt: skip
        line = status_line(status)
        assert line == {"emlog1": "frozen m=+0.100 b=+0.050 ref valid", "records": "emlog1=12"}
        configure_logging("json", "info", io.StringIO())
        assert not is_console()

    @pytest.mark.parametrize(("fmt", "level"), [("xml", "info"), ("json", "loud")])
    def test_bad_values(self, fmt: str, level: str) -> None:
        """Unknown formats and levels raise ValueError."""
        with pytest.raises(ValueError):
            configure_logging(fmt, level, io.StringIO())  # type: ignore[arg-type]
