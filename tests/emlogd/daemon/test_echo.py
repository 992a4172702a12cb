"""The daemon's own output read back on an input (emlogd/daemon/echo.py)."""

from __future__ import annotations

from emlogd.config import parse_config
from emlogd.daemon.echo import ECHO_S, LOOP_S, MAX_PARTIAL, EchoFilter

CONFIG = """\
ports:
  - {name: emlog1, url: /dev/null, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/null, protocol: pd0, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
"""

RAW = b"$VWVHW,,T,,M,5.00,N,9.26,K*5C\r\n"
"""A reading as the daemon writes it too (raw passed through)."""

STATUS = b"$PEMLS,emlog1,U,EM3,,,,,,,,N*17\r\n"


def _filter() -> tuple[EchoFilter, list[float], list[str]]:
    now = [100.0]
    loops: list[str] = []
    f = EchoFilter(lambda: now[0], loops.append)
    f.configure(parse_config(CONFIG))
    return f, now, loops


def test_nothing_is_judged_without_the_daemons_own_sentence() -> None:
    """A log's reading equal to what the daemon wrote passes, byte for byte, partial
    lines too, and binary ports are never looked at."""
    f, _, _ = _filter()
    f.wrote(RAW)
    assert f.read("emlog1", RAW) == RAW
    assert f.read("emlog1", RAW[:10]) == RAW[:10]
    f.wrote(STATUS)
    assert f.read("dvl", STATUS) == STATUS
    assert f.echoes["emlog1"] == 0


def test_once_its_status_comes_back_each_written_line_is_skipped_once() -> None:
    """After the daemon's ``$PEMLS`` came back on the port, a line it wrote within
    ``ECHO_S`` is skipped once (its echo), the same reading sent again is read, a
    partial line waits for its end, and ``LOOP_S`` later nothing is judged again."""
    f, now, loops = _filter()
    f.wrote(STATUS)
    assert f.read("emlog1", STATUS) == b""
    assert loops == ["emlog1"]
    f.wrote(RAW)  # the log's reading, passed through: its echo, then the log again
    assert f.read("emlog1", RAW) == b""
    assert f.read("emlog1", RAW) == RAW
    f.wrote(RAW)
    assert f.read("emlog1", RAW[:7]) == b""
    assert f.read("emlog1", RAW[7:]) == b""
    assert f.echoes["emlog1"] == 3
    f.wrote(RAW)
    now[0] += ECHO_S + 0.1  # too late to be its echo
    assert f.read("emlog1", RAW) == RAW
    now[0] += LOOP_S
    f.wrote(RAW)
    assert f.read("emlog1", RAW) == RAW


def test_a_line_without_end_is_not_held_past_its_bound() -> None:
    """While judged, an unended line longer than ``MAX_PARTIAL`` is passed on."""
    f, _, _ = _filter()
    f.read("emlog1", STATUS)
    junk = b"x" * (MAX_PARTIAL + 1)
    assert f.read("emlog1", junk) == junk
    assert f.partial == {}


def test_a_proof_split_across_reads_is_seen_and_what_came_before_it_read() -> None:
    """Reads ending in ``$``, ``$P`` or ``$PEM`` hold those bytes back for the next read;
    the status sentence completed there proves the loop, and the written line after it is
    skipped, while the reading before the proof is passed; a held ``$`` that turns out to
    begin a log's own sentence is passed with it."""
    f, _, loops = _filter()
    f.wrote(RAW + STATUS + RAW)
    assert f.read("emlog1", RAW + STATUS[:4]) == RAW
    assert f.read("emlog1", STATUS[4:] + RAW) == b""
    assert loops == ["emlog1"] and f.echoes["emlog1"] == 2
    g, _, _ = _filter()
    assert g.read("emlog1", RAW + b"$") == RAW
    assert g.read("emlog1", RAW[1:]) == RAW
    assert g.read("emlog1", b"$P") == b""
    assert g.read("emlog1", b"X") == b"$PX"
