"""Serial source: real ptys and loop://, chunked reads, unplug/replug, stale, bad URLs."""

from __future__ import annotations

import os
import termios
import time
from pathlib import Path

import pytest
import serial

from drivers.errors import DeviceError
from drivers.io.port import DEVICE_CHECK_S, SerialSource
from drivers.io.vpty import VirtualPort


def _read_all(src: SerialSource, n: int, timeout: float = 5.0) -> bytes:
    out = b""
    end = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < end:
        c = src.read()
        if c is None:
            time.sleep(0.005)
            continue
        t, data = c
        assert t > 0
        out += data
    return out


def _is_open(src: SerialSource) -> bool:
    # a call, not the property: mypy would keep `src.is_open` narrowed across the
    # loops below, which change it
    return src.is_open


def _until(src: SerialSource, is_open: bool, step_s: float) -> bool:
    """Drive ``src`` every ``step_s`` (poll while closed, read while open) until it is open
    (``is_open``) or closed, 5 s at the most; whether it got there."""
    deadline = time.monotonic() + 5
    while _is_open(src) != is_open and time.monotonic() < deadline:
        if is_open:
            src.poll()
        else:
            src.read()
        time.sleep(step_s)
    return _is_open(src) == is_open


def test_reads_a_real_pty_in_chunks(pty_pair: tuple[int, int, str]) -> None:
    """200 sentences written to a real pty arrive intact in fewer than 200 chunks stamped with the
    port and a time, after one connected event, and close drops the descriptor."""
    master, _, path = pty_pair
    src = SerialSource("emlog1", path, baudrate=4800)
    assert src.open()
    assert [e.kind for e in src.events()] == ["connected"]
    assert isinstance(src.fileno(), int)
    data = b"".join(b"$VWVHW,,T,,M,%d.00,N,,K*00\r\n" % k for k in range(200))
    os.write(master, data)
    got = _read_all(src, len(data))
    assert got == data
    assert src.chunks < 200  # chunked, not one read per line
    src.close()
    assert not src.is_open and src.fileno() is None


def test_loop_url_without_file_descriptor() -> None:
    """A loop:// URL, which has no file descriptor, opens and reads back what is written to it."""
    src = SerialSource("l", "loop://", baudrate=9600)
    assert src.open()
    assert isinstance(src._ser, serial.SerialBase)
    src._ser.write(b"hello")
    assert _read_all(src, 5) == b"hello"
    src.close()


def test_missing_device_is_an_event_then_reconnects(tmp_path: Path) -> None:
    """A device missing at start is a disconnected event rather than a crash, is not retried before
    its backoff, and connects once it exists and the backoff has passed."""
    link = tmp_path / "emlog1"
    clock = [0.0]
    src = SerialSource("emlog1", str(link), backoff_s=(0.5, 1.0), monotonic=lambda: clock[0])
    assert not src.open()  # missing at start: not a crash
    ev = src.events()
    assert [e.kind for e in ev] == ["disconnected"] and "cannot open" in ev[0].detail
    assert src.poll() == []  # backoff not elapsed
    with VirtualPort(link) as vp:
        clock[0] = 0.6
        assert [e.kind for e in src.poll()] == ["connected"]
        vp.write(b"$A*41\r\n")
        assert _read_all(src, 7) == b"$A*41\r\n"
        src.close()


def test_unplug_and_replug_at_the_same_path(tmp_path: Path) -> None:
    """An unplugged pty closes the source with one disconnected event, and a new pty at the same
    path is reconnected (reconnects 1) and read."""
    link = tmp_path / "dvl"
    vp = VirtualPort(link)
    src = SerialSource("dvl", str(link), backoff_s=(0.01,))
    assert src.open()
    src.events()
    vp.write(b"one\r\n")
    assert _read_all(src, 5) == b"one\r\n"
    vp.close()  # unplugged
    assert _until(src, False, 0.01)
    assert [e.kind for e in src.events()] == ["disconnected"]
    vp2 = VirtualPort(link)  # replugged: a new pty at the same symlink
    try:
        assert _until(src, True, 0.02) and src.reconnects == 1
        vp2.write(b"two\r\n")
        assert _read_all(src, 5) == b"two\r\n"
    finally:
        src.close()
        vp2.close()


def test_stale_and_alive_events(pty_pair: tuple[int, int, str]) -> None:
    """No data for stale_timeout_s gives one stale event, not repeated, and the next data an alive
    event."""
    master, _, path = pty_pair
    clock = [100.0]
    src = SerialSource("p", path, stale_timeout_s=2.0, monotonic=lambda: clock[0])
    src.open()
    src.events()
    clock[0] = 101.0
    assert src.poll() == []
    clock[0] = 102.5
    assert [e.kind for e in src.poll()] == ["stale"]
    assert src.counters_dict()["stale"] is True
    assert "stale" not in src.counters_dict(stale=False)  # the daemon's figures: none of it
    clock[0] = 110.0
    assert src.poll() == []  # reported once
    os.write(master, b"x\n")
    _read_all(src, 2)
    assert [e.kind for e in src.events()] == ["alive"]
    src.close()


def test_bad_url_scheme_is_a_device_error() -> None:
    """An unknown URL scheme is a DeviceError and an empty backoff a ValueError, both at
    construction."""
    with pytest.raises(DeviceError, match="invalid URL"):
        SerialSource("x", "nonsense://here")
    with pytest.raises(ValueError, match="backoff"):
        SerialSource("x", "loop://", backoff_s=())


def _replug_cycles(tmp_path: Path, cycles: int) -> None:
    link = tmp_path / "emlog1"
    src = SerialSource("emlog1", str(link), backoff_s=(0.005,))
    fds_before = None
    rss_before = 0
    for k in range(cycles):
        vp = VirtualPort(link)
        if k == 0:
            src.open()
        assert _until(src, True, 0.002), f"cycle {k}: no reconnect"
        msg = b"$cycle,%d*00\r\n" % k
        vp.write(msg)
        assert _read_all(src, len(msg)) == msg
        vp.close()  # unplug
        assert _until(src, False, 0.002)
        if k == 1:
            fds_before = sum(1 for _ in Path("/proc/self/fd").iterdir())
            rss_before = _rss()
    src.close()
    assert src.reconnects == cycles - 1
    assert fds_before is not None and sum(1 for _ in Path("/proc/self/fd").iterdir()) <= fds_before
    assert _rss() - rss_before < 2 * 2**20  # no memory growth beyond allocator noise


def _rss() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    return 0


@pytest.mark.parametrize("cycles", [10, pytest.param(100, marks=pytest.mark.soak)])
def test_replug_cycles_leak_no_descriptors(tmp_path: Path, cycles: int) -> None:
    """Unplug/replug cycles (10; 100 in the soak run) each reconnect and read, and leak no
    file descriptor or memory."""
    _replug_cycles(tmp_path, cycles)


def test_a_silent_device_whose_path_names_another_is_opened_again(tmp_path: Path) -> None:
    """The link moved to a new pty while the old one stays open and silent: once silent
    DEVICE_CHECK_S the source closes the old one (``disconnected``, naming why) and opens
    the new one; a silent device whose path still names it is kept, and so is one whose
    data flow while its path moved. It read the old pty, silent, for ever."""
    link = tmp_path / "emlog1"
    clock = [0.0]
    old = VirtualPort(link)
    src = SerialSource("emlog1", str(link), backoff_s=(0.01,), monotonic=lambda: clock[0])
    new: VirtualPort | None = None
    try:
        assert src.open()
        src.events()
        clock[0] = DEVICE_CHECK_S
        assert src.poll() == [] and _is_open(src)  # its path names it: kept
        link.unlink()
        new = VirtualPort(link)
        old.write(b"one\r\n")
        assert _read_all(src, 5) == b"one\r\n"  # data: the path is not looked at
        assert src.poll() == []
        clock[0] += DEVICE_CHECK_S
        events = src.poll()
        assert [e.kind for e in events] == ["disconnected"]
        assert "now names another device" in events[0].detail
        clock[0] += 1.0
        assert [e.kind for e in src.poll()] == ["connected"]
        new.write(b"two\r\n")
        assert _read_all(src, 5) == b"two\r\n"
    finally:
        src.close()
        old.close()
        if new is not None:
            new.close()


def test_a_fifo_or_a_regular_file_at_the_path_is_said_for_what_it_is(tmp_path: Path) -> None:
    """A FIFO or a regular file where the device belongs is refused and retried, the
    reason naming what it is (pyserial's own: ``Could not configure port: (25,
    'Inappropriate ioctl for device')``); a missing path keeps pyserial's reason."""
    fifo, plain, missing = tmp_path / "fifo", tmp_path / "plain", tmp_path / "missing"
    os.mkfifo(fifo)
    plain.write_text("$VWVHW,,T,,M,5.00,N,,K*4F\r\n")
    for path, kind in ((fifo, "a FIFO"), (plain, "a regular file"), (missing, "No such file")):
        src = SerialSource("emlog1", str(path), backoff_s=(0.5,))
        assert not src.open()
        assert src.why_closed is not None and kind in src.why_closed, src.why_closed
        assert src.events()[0].kind == "disconnected"


def _pty_numbered(number: str, tries: int = 50) -> tuple[int, int] | None:
    """A raw pty whose slave is ``number`` (``/dev/pts/N``): the kernel gives the lowest
    free number, so the one just freed comes back unless another process takes it
    first; None when it did not within ``tries``."""
    import tty

    kept: list[tuple[int, int]] = []
    try:
        for _ in range(tries):
            master, slave = os.openpty()
            if os.ttyname(slave) == number:
                tty.setraw(slave)
                return master, slave
            kept.append((master, slave))
        return None
    finally:
        for fds in kept:
            for fd in fds:
                os.close(fd)


def test_a_link_to_a_pty_whose_number_another_program_took_is_not_read(tmp_path: Path) -> None:
    """The pty a link named is gone and a new pty took its number while the link stayed
    as it was: the source does not open it (another program's session), says why, and
    opens the pty once the link is made again; a device that comes back under a link
    made again is read at once."""
    import tty

    link = tmp_path / "emlog1"
    master, slave = os.openpty()
    tty.setraw(slave)
    number = os.ttyname(slave)
    os.close(slave)
    link.symlink_to(number)
    src = SerialSource("emlog1", str(link), backoff_s=(0.01,))
    other: tuple[int, int] | None = None
    try:
        assert src.open()
        src.events()
        os.write(master, b"one\r\n")
        assert _read_all(src, 5) == b"one\r\n"
        os.close(master)  # the device goes away
        assert _until(src, False, 0.01)
        other = _pty_numbered(number)
        if other is None:
            pytest.skip(f"{number} was taken by another process before this test could")
        time.sleep(0.05)
        for _ in range(5):
            src.poll()
            time.sleep(0.02)
        assert not _is_open(src)
        assert src.why_closed is not None
        assert "a pty made since under the number" in src.why_closed
        link.unlink()
        link.symlink_to(number)  # the operator (or the device's program) makes it again
        assert _until(src, True, 0.02)
        os.write(other[0], b"theirs\r\n")
        assert _read_all(src, 8) == b"theirs\r\n"
    finally:
        src.close()
        if other is not None:
            for fd in other:
                os.close(fd)


def test_modes_another_process_changed_are_put_back(tmp_path: Path) -> None:
    """Another process sets the device's modes to canonical with echo and 9600 baud
    (``stty -F /dev/dvl sane 9600`` by hand): the next :meth:`poll` a
    ``DEVICE_CHECK_S`` later puts back the modes of the open (one ``modes_restored``
    event); changed again within ``MODES_EVENT_S``, they are put back without another
    event, ``modes_restored`` counting both."""
    now = [100.0]
    with VirtualPort(tmp_path / "dvl") as vp:
        src = SerialSource(
            "dvl", str(tmp_path / "dvl"), stale_timeout_s=60.0, monotonic=lambda: now[0]
        )
        try:
            assert src.open()
            src.events()
            fd = os.open(vp.slave_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            kinds = []
            try:
                at_open = termios.tcgetattr(fd)
                for _ in range(2):
                    changed = termios.tcgetattr(fd)
                    changed[3] |= termios.ICANON | termios.ECHO
                    changed[4] = changed[5] = termios.B9600
                    termios.tcsetattr(fd, termios.TCSANOW, changed)
                    now[0] += DEVICE_CHECK_S
                    kinds += [e.kind for e in src.poll()]
                    assert termios.tcgetattr(fd) == at_open
            finally:
                os.close(fd)
            assert kinds == ["modes_restored"]
            assert src.modes_restored == 2
            now[0] += DEVICE_CHECK_S
            assert not src.poll()  # nothing changed: nothing to do
            assert src.modes_restored == 2
        finally:
            src.close()
