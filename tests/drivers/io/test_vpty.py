"""Virtual serial port: raw mode, symlink, late readers, stuck readers, cleanup."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import stat
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from drivers.io.vpty import DRAIN_BYTES, LDISC_BUF, VirtualPort


def _open(link: Path) -> int:
    return os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)


def _read(fd: int, timeout: float = 2.0) -> bytes:
    end = time.monotonic() + timeout
    out = b""
    while time.monotonic() < end:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            if out:
                break
            time.sleep(0.01)
            continue
        out += chunk
    return out


def test_symlink_mode_and_raw_bytes(tmp_path: Path) -> None:
    """The link points at the pty with the requested mode, bytes pass raw (no CR/LF translation, no
    echo), and closing removes the link."""
    link = tmp_path / "run" / "emlog0"
    with VirtualPort(link, mode=0o640) as vp:
        assert link.is_symlink() and str(link.readlink()) == vp.slave_path
        assert stat.S_IMODE(Path(vp.slave_path).stat().st_mode) == 0o640
        fd = _open(link)
        try:
            assert vp.has_reader()
            data = b"$VWVHW,1*00\r\n\x00\xff\n\r"
            assert vp.write(data) == len(data)
            assert _read(fd) == data  # raw: no CR/LF translation, no echo
        finally:
            os.close(fd)
    assert not link.exists() and not link.is_symlink()


def test_late_reader_sees_no_backlog(tmp_path: Path) -> None:
    """Writes without a reader are dropped and counted, so a reader that opens or reopens later gets
    only what was written after it opened."""
    link = tmp_path / "p"
    with VirtualPort(link) as vp:
        assert not vp.has_reader()
        assert vp.write(b"stale\r\n") == 0
        assert vp.dropped == 7
        fd = _open(link)
        try:
            vp.write(b"fresh\r\n")
            assert _read(fd) == b"fresh\r\n"
        finally:
            os.close(fd)
        time.sleep(0.05)
        assert vp.write(b"nobody\r\n") == 0  # the reader closed again
        fd = _open(link)
        try:
            vp.write(b"again\r\n")
            assert _read(fd) == b"again\r\n"
        finally:
            os.close(fd)


def _sentence(k: int) -> bytes:
    return b"$VWVHW,,T,,M,%05d,N,6.48,K*6A\r\n" % k


def test_a_reader_that_never_reads_never_blocks_the_writer(tmp_path: Path) -> None:
    """Without a backlog limit, a reader that never reads makes writes drop instead of blocking and
    is left the oldest data."""
    # without a backlog limit (kernel behaviour): the pty fills, further writes are dropped
    with VirtualPort(tmp_path / "p", max_backlog=None) as vp:
        fd = _open(tmp_path / "p")
        try:
            # the pty fills long before 20 000 sentences: a blocking writer hangs here
            for k in range(20_000):
                vp.write(_sentence(k))
            assert vp.dropped > 0 and vp.written > 0 and vp.flushes == 0
            got = _read(fd)
            assert got.startswith(_sentence(0))  # the oldest data: a stale backlog
        finally:
            os.close(fd)


def test_a_stalled_reader_resumes_with_recent_data(tmp_path: Path) -> None:
    """With a backlog limit every write is accepted in full (old data flushed), and a stalled reader
    finds only recent sentences, the last one included."""
    with VirtualPort(tmp_path / "p", max_backlog=2048) as vp:
        fd = _open(tmp_path / "p")
        try:
            for k in range(20_000):
                assert vp.write(_sentence(k)) == len(_sentence(k))  # never full, never blocks
            assert vp.dropped == 0 and vp.flushes > 0
            got = _read(fd)
        finally:
            os.close(fd)
    assert got.endswith(_sentence(19_999))
    # only recent data is left: a burst can leave up to the pty's own capacity
    # (~20 KB, ~640 sentences) that the kernel had not yet handed to the line
    # discipline, never the old backlog (without the limit: sentence 0 onwards)
    first = int(got[got.index(b"$") :].split(b",")[5])
    assert first >= 19_000, first


EXCLUSIVE_READER = """
import fcntl, os, sys, termios
from pathlib import Path
from drivers.io.vpty import VirtualPort
link = Path(sys.argv[1])
with VirtualPort(link, max_backlog=2048) as vp:
    fd = os.open(link, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    fcntl.ioctl(fd, termios.TIOCEXCL)
    for k in range(20_000):
        vp.write(b"$VWVHW,,T,,M,%05d,N,,K*00\\r\\n" % k)
    got = b""
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            break
        got += chunk
    print(len(got), got.split(b"\\r\\n")[-2].decode())
"""
"""A writer whose reader holds the slave exclusively (``TIOCEXCL``) and reads only after
20 000 sentences: prints the bytes it read and the last sentence."""


def test_a_stalled_reader_holding_the_pty_exclusively_resumes_with_recent_data(
    tmp_path: Path,
) -> None:
    """A reader that sets ``TIOCEXCL`` on the slave (gpsd, uucp: no other process may open
    it, so the writer's own check cannot) and stalls for 20 000 sentences: it resumes
    with at most the line discipline's 4 KiB of old data and the pty's capacity of
    recent data, the last sentence included (the pty flushed from the master's side).
    Nothing trimmed its backlog: the full pty took no more, and the reader got the
    20 KB written as it stalled, sentence 1 to 1021, none of the newest. Run without
    ``CAP_SYS_ADMIN`` (root opens an exclusive tty all the same)."""
    argv = [sys.executable, "-c", EXCLUSIVE_READER, str(tmp_path / "p")]
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.skip("root without setpriv: an exclusive tty opens all the same")
        argv = [setpriv, "--bounding-set=-sys_admin", *argv]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    done = subprocess.run(argv, capture_output=True, check=True, env=env, timeout=60)
    size, last = done.stdout.decode().split()
    assert last == "$VWVHW,,T,,M,19999,N,,K*00", done.stdout
    assert int(size) <= LDISC_BUF + 20 * 1024


def test_a_live_reader_loses_nothing(tmp_path: Path) -> None:
    """A reader that keeps reading gets every byte in order and the backlog is never flushed."""
    with VirtualPort(tmp_path / "p") as vp:
        fd = _open(tmp_path / "p")
        expected = b"".join(_sentence(k) for k in range(3000))
        got = b""
        try:
            for k in range(3000):
                assert vp.write(_sentence(k)) == len(_sentence(k))
                with contextlib.suppress(BlockingIOError):
                    got += os.read(fd, 65536)
            got += _read(fd)
        finally:
            os.close(fd)
        assert got == expected and vp.flushes == 0


@pytest.mark.parametrize("bad", [0, -1, 4096, 100_000])
def test_max_backlog_range(tmp_path: Path, bad: int) -> None:
    """A max_backlog outside 1..4095 is a ValueError and creates no link."""
    with pytest.raises(ValueError, match="max_backlog"):
        VirtualPort(tmp_path / "p", max_backlog=bad)
    assert not (tmp_path / "p").exists()


def test_replaces_a_stale_link_and_refuses_a_file(tmp_path: Path) -> None:
    """A dangling symlink at the path is replaced, and a regular file there is refused with
    DeviceError and left intact."""
    link = tmp_path / "p"
    link.symlink_to("/dev/pts/does-not-exist")
    with VirtualPort(link) as vp:
        assert str(link.readlink()) == vp.slave_path
    regular = tmp_path / "file"
    regular.write_text("keep me")
    with pytest.raises(DeviceError, match="not a symlink"):
        VirtualPort(regular)
    assert regular.read_text() == "keep me"


def test_close_keeps_a_link_that_is_no_longer_ours(tmp_path: Path) -> None:
    """Closing a port whose path another port has taken over leaves the newer link, and close is
    idempotent."""
    link = tmp_path / "p"
    first = VirtualPort(link)
    second = VirtualPort(link)  # a new daemon took the path over
    first.close()
    assert link.is_symlink() and str(link.readlink()) == second.slave_path
    second.close()
    first.close()  # idempotent
    assert not link.is_symlink()


def test_what_a_reader_writes_back_is_drained_a_bounded_amount_a_write(tmp_path: Path) -> None:
    """A reader that writes into the pty: each write of the port drains and discards at
    most ``DRAIN_BYTES`` of it, so a reader writing as fast as the drain reads cannot
    hold the writer; what is left waits in the pty, and later writes drain it."""
    link = tmp_path / "p"
    with VirtualPort(link) as vp:
        fd = os.open(link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            echoed = 0
            with contextlib.suppress(BlockingIOError):
                while echoed < 3 * DRAIN_BYTES:
                    echoed += os.write(fd, b"e" * 1024)
            time.sleep(0.1)  # the kernel moves it to the master's side
            assert echoed > DRAIN_BYTES
            assert vp.write(b"x\r\n") == 3
            left = _pending(vp.master)
            assert left >= echoed - DRAIN_BYTES - 1024, (echoed, left)
            for _ in range(echoed // DRAIN_BYTES + 1):
                vp.write(b"x\r\n")
            assert _pending(vp.master) == 0
        finally:
            os.close(fd)


def _pending(fd: int) -> int:
    """Bytes waiting to be read from ``fd``."""
    raw = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
    return int(struct.unpack("i", raw)[0])


def test_modes_a_reader_changed_are_put_back_to_raw(tmp_path: Path) -> None:
    """A reader sets canonical mode, signal characters with ``$`` as the interrupt,
    CR to NL and echo, and a 2-s read timeout (``VMIN`` 0, ``VTIME`` 20): ``check_modes``
    puts the input and local modes back to raw (True), keeps the control characters it
    set, and finds nothing to do the next time (False)."""
    with VirtualPort(tmp_path / "p") as vp:
        assert vp.check_modes() is False
        fd = os.open(tmp_path / "p", os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            attrs = termios.tcgetattr(fd)
            attrs[0] |= termios.ICRNL | termios.ISTRIP
            attrs[3] |= termios.ICANON | termios.ISIG | termios.ECHO
            attrs[6][termios.VINTR] = b"$"
            attrs[6][termios.VMIN], attrs[6][termios.VTIME] = 0, 20
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
            assert vp.check_modes() is True
            now = termios.tcgetattr(fd)
            assert not now[0] & (termios.ICRNL | termios.ISTRIP)
            assert not now[3] & (termios.ICANON | termios.ISIG | termios.ECHO)
            assert now[6][termios.VINTR] == b"$"
            assert (now[6][termios.VMIN], now[6][termios.VTIME]) == (0, 20)
            assert vp.check_modes() is False
        finally:
            os.close(fd)
