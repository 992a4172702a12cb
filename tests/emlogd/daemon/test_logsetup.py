"""structlog configuration."""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import structlog

from emlogd.daemon import logsetup
from emlogd.daemon.logsetup import (
    STATUS_LOG_MAX_ITEMS,
    capped_sections,
    configure_logging,
    is_console,
    status_line,
)
from tests.emlogd.daemon.test_redteam import F_SETPIPE_SZ
from tests.sockets import drain


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

    def test_console_status_of_many_uuts_names_a_few_and_counts_the_rest(self) -> None:
        """1000 UUTs: the terminal's line names the first STATUS_LOG_MAX_ITEMS of the UUTs
        and the ports, ``left_out`` counting the rest (it named all: 60 KB a line)."""
        status = {
            "uuts": {f"e{i}": {"state": "learning", "reference": "valid"} for i in range(1000)},
            "ports": {f"e{i}": {"records": i} for i in range(1001)},
        }
        line = status_line(status)
        n = STATUS_LOG_MAX_ITEMS
        assert line["left_out"] == {"uuts": 1000 - n, "ports": 1001 - n}
        assert len(line) == n + 2
        assert line["records"] == " ".join(f"e{i}={i}" for i in range(n))

    def test_capped_sections_keeps_what_fits_as_it_is(self) -> None:
        """A section within the limit, and a value that is no dict, are kept whole, with no
        ``left_out``; one past it keeps its first entries in order."""
        small = {"ports": {"a": 1, "b": 2}, "state_errors": 0}
        assert capped_sections(small, limit=2) == small
        assert capped_sections({"uuts": {"a": 1, "b": 2, "c": 3}}, limit=2) == {
            "uuts": {"a": 1, "b": 2},
            "left_out": {"uuts": 1},
        }

    @pytest.mark.parametrize(("fmt", "level"), [("xml", "info"), ("json", "loud")])
    def test_bad_values(self, fmt: str, level: str) -> None:
        """Unknown formats and levels raise ValueError."""
        with pytest.raises(ValueError):
            configure_logging(fmt, level, io.StringIO())  # type: ignore[arg-type]


def test_a_reload_moves_the_daemons_log_off_the_nmea_on_stdout(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The daemon's log follows the config at a reload: on stderr once ``outputs.stdout``
    is on, back on stdout once it is off; a log configured otherwise is left alone."""
    out, err = io.StringIO(), io.StringIO()
    monkeypatch.setattr("sys.stdout", out)
    monkeypatch.setattr("sys.stderr", err)
    monkeypatch.setattr(logsetup, "_follows", None)
    assert not logsetup.follow_config("json", "info", True)  # not the daemon's log
    logsetup.configure_daemon_logging("json", "info", False)
    assert not logsetup.follow_config("json", "info", False)
    assert logsetup.follow_config("json", "info", True)
    structlog.get_logger("t").info("on_stderr")
    assert logsetup.follow_config("json", "info", False)
    structlog.get_logger("t").info("on_stdout")
    assert "on_stderr" in err.getvalue() and "on_stderr" not in out.getvalue()
    assert "on_stdout" in out.getvalue() and "on_stdout" not in err.getvalue()
    configure_logging("json", "info", io.StringIO())


@pytest.fixture(params=["pipe", "socket"])
def channel(request: pytest.FixtureRequest) -> Iterator[tuple[int, int]]:
    """(read end, write end) of a pipe of one page, or of a unix stream socket pair of
    small buffers: a log stream and its reader."""
    if request.param == "pipe":
        r, w = os.pipe()
        fcntl.fcntl(w, F_SETPIPE_SZ, 4096)
    else:
        a, b = socket.socketpair()
        b.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        a.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        r, w = a.detach(), b.detach()
    os.set_blocking(r, False)
    yield r, w
    for fd in (r, w):
        with contextlib.suppress(OSError):
            os.close(fd)


class TestLogStream:
    """Log lines never wait for the reader: held back within a bound, the rest counted."""

    def test_a_reader_that_does_not_read_costs_the_lines_past_the_backlog(
        self, channel: tuple[int, int], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """200 lines of 100 bytes into a page nobody reads, with a backlog of 2000 bytes:
        none waits, the lines past the page and the backlog are counted lost, and once
        the reader reads, the others come whole and in order."""
        monkeypatch.setattr(logsetup, "LOG_BACKLOG_BYTES", 2000)
        r, w = channel
        out = logsetup.LogStream(open(w, "w", closefd=False))  # noqa: SIM115
        lost = logsetup.lost_lines()
        t0 = time.monotonic()
        for k in range(200):
            out.write(f"{k:04d}" + "x" * 95 + "\n")
        assert time.monotonic() - t0 < 1.0
        dropped = logsetup.lost_lines() - lost
        assert 100 < dropped < 200
        got = drain(r)
        out.flush()
        got += drain(r)
        lines = got.decode().splitlines()
        assert len(lines) == 200 - dropped and not out.pending
        assert all(len(x) == 99 for x in lines)
        numbers = [int(x[:4]) for x in lines]
        assert numbers == sorted(numbers) and numbers[0] == 0
        out.close()

    def test_a_reader_gone_costs_what_is_held(self, channel: tuple[int, int]) -> None:
        """The reader closes with lines held back: they are counted lost, no exception."""
        r, w = channel
        out = logsetup.LogStream(open(w, "w", closefd=False))  # noqa: SIM115
        for _ in range(100):
            out.write("y" * 99 + "\n")
        assert out.pending
        os.close(r)
        lost = logsetup.lost_lines()
        out.write("z\n")
        assert logsetup.lost_lines() > lost and not out.pending
        out.close()

    def test_a_regular_file_is_written_as_it_goes(self, tmp_path: Path) -> None:
        """A disk does not wait for a reader: each line is in the file when written."""
        with open(tmp_path / "log", "w") as f:
            out = logsetup.LogStream(f)
            out.write("one\n")
            assert (tmp_path / "log").read_text() == "one\n"


def test_control_log_passes_a_burst_per_interval_then_counts_what_it_left_out() -> None:
    """The operators' commands' lines: ``CONTROL_EVENT_BURST`` of each command per
    interval, the first line after it carrying ``suppressed``; each command counted
    apart, and other events never limited."""
    now = [100.0]
    lines: list[tuple[str, str, dict[str, object]]] = []

    class _Log:
        def info(self, kind: str, **kw: object) -> None:
            lines.append(("info", kind, kw))

        def warning(self, kind: str, **kw: object) -> None:
            lines.append(("warning", kind, kw))

    clog = logsetup.ControlLog(_Log(), lambda: now[0])
    for _ in range(logsetup.CONTROL_EVENT_BURST + 5):
        clog.info("control_learn", on=True)
        clog.warning("control_reset", uuts=["emlog1"])
    clog.info("another_event")
    clog.info("another_event")
    assert [k for _, k, _ in lines].count("control_learn") == logsetup.CONTROL_EVENT_BURST
    assert [k for _, k, _ in lines].count("control_reset") == logsetup.CONTROL_EVENT_BURST
    assert [k for _, k, _ in lines].count("another_event") == 2
    now[0] += logsetup.EVENT_INTERVAL_S
    clog.warning("control_reset", uuts=["emlog1"])
    assert lines[-1] == ("warning", "control_reset", {"uuts": ["emlog1"], "suppressed": 5})
    clog.warning("control_reset", uuts=["emlog1"])
    assert "suppressed" not in lines[-1][2]
