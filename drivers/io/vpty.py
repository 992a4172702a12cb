"""A virtual serial port: a pty whose slave is published at a stable symlink.

The daemon writes corrected NMEA to the pty master; an autopilot (or a test) opens
the symlink like a serial device. Properties:

- The slave is put in raw mode (no echo, no CR/LF translation) and chmod-ed to
  ``mode`` (default 0660, optionally chown-ed to ``group``); the settings persist
  while the master is open, whoever opens the slave afterwards. The modes are the
  line discipline's, shared by every reader: one that changes them (``stty -F``, a
  program that sets canonical mode, signal characters, CR/LF translation) changes
  what the others read, and they stay after it has gone. :meth:`check_modes` puts the
  input and local modes back to raw (the control characters, ``VMIN``/``VTIME`` and
  the rest as the reader set them).
- The symlink is replaced atomically (temporary symlink + rename); a stale
  symlink is replaced, a regular file or directory at that path is refused. It is
  removed on :meth:`close` if it still points at this pty; :meth:`check_link`
  publishes it again if it was removed meanwhile.
- Readers may open and close the slave at any time without blocking the writer:
  the master is non-blocking, and while no process has the slave open (the master
  polls ``POLLHUP``) nothing is written at all, so a reader that opens late sees no
  stale backlog, only what is written after it opened. Anything a reader writes back
  is drained and discarded, at most ``DRAIN_BYTES`` at each write.
- A reader that keeps the slave open but stops reading does not get a stale backlog
  either: after every ``max_backlog // 4`` bytes written (and whenever the pty is
  full) the writer opens the slave briefly, asks how much waits unread in its line
  discipline (``FIONREAD``) and, above ``max_backlog``, discards it
  (``tcflush(TCIFLUSH)``, which also empties the kernel's flip buffers). A reader
  that resumes therefore gets about ``max_backlog`` bytes of old data (the first
  line may be cut) and then live data. FIONREAD does not see bytes the kernel has
  not yet moved from its flip buffers to the line discipline (it does so
  asynchronously): at serial rates that is nothing, but a writer bursting faster
  than that can leave up to the pty's capacity (~20 KB); never more, because a
  full pty is flushed before the next write. A reader that holds the slave
  exclusively (``TIOCEXCL``) cannot be opened: its full pty is flushed from the
  master's side, which leaves the line discipline's 4 KiB of old data to it, then
  recent data. ``max_backlog=None`` keeps the kernel
  behaviour (a real serial port: up to ~68 KB queue, further writes dropped), which
  fake devices use so that a slow test reader still gets every byte.

Why not keep a slave descriptor open and flush periodically: the master reports
``POLLHUP`` only while *no* descriptor of the slave is open, which is the one
reliable way on Linux to know whether a reader is attached at all.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import grp
import os
import select
import struct
import termios
import tty
from pathlib import Path

from drivers.errors import DeviceError
from drivers.io.closing import Closing

LDISC_BUF = 4096
"""Bytes the Linux line discipline buffers for a reader (``N_TTY_BUF_SIZE``); FIONREAD
never reports more, so ``max_backlog`` must stay below it."""

DRAIN_BYTES = 4 * LDISC_BUF
"""The most of what readers wrote into the pty that one write drains and discards: a
reader writing as fast as the drain reads never lets the pty be empty, and an
unbounded drain held the writer (the daemon's one thread) for as long as it wrote.
What is left waits in the pty, whose full buffer then stops the reader's writes."""


class VirtualPort(Closing):
    """A pty published at ``link``.

    Args:
        link: the symlink path (its parent directory is created).
        mode: permission bits of the slave device.
        group: group name or id to own the slave device (None: unchanged).
        max_backlog: unread bytes a stalled reader may keep queued before they are
            discarded (1 .. 4095), or None for no limit (kernel behaviour).

    Attributes:
        written: bytes the pty accepted.
        dropped: bytes not written (no reader, or the pty was full).
        flushes: times a stalled reader's backlog was discarded.

    Raises:
        DeviceError: the pty cannot be created or the link cannot be published.
        ValueError: ``max_backlog`` out of range.
    """

    def __init__(
        self,
        link: str | Path,
        *,
        mode: int = 0o660,
        group: str | int | None = None,
        max_backlog: int | None = 2048,
    ) -> None:
        if max_backlog is not None and not 0 < max_backlog < LDISC_BUF:
            raise ValueError(f"max_backlog must be 1 .. {LDISC_BUF - 1} or None, not {max_backlog}")
        self.link = Path(link)
        self.max_backlog = max_backlog
        self.written = 0
        self.dropped = 0
        self.flushes = 0
        self._unchecked = 0
        try:
            master, slave = os.openpty()
        except OSError as exc:
            raise DeviceError(f"cannot create a pty: {exc.strerror}") from None
        try:
            tty.setraw(slave)
            raw = termios.tcgetattr(slave)
            self._raw_modes: tuple[int, int] = (raw[0], raw[3])
            """The raw input and local modes (``c_iflag``, ``c_lflag``)."""
            self.slave_path = os.ttyname(slave)
            self.set_access(mode, group)
        except DeviceError:
            os.close(master)
            raise
        except OSError as exc:
            os.close(master)
            raise DeviceError(f"cannot configure the pty for {self.link}: {exc}") from None
        finally:
            os.close(slave)
        os.set_blocking(master, False)
        self.master = master
        self._poll = select.poll()
        self._poll.register(master, select.POLLHUP | select.POLLIN)
        try:
            self._publish()
        except OSError as exc:
            os.close(master)
            raise DeviceError(f"cannot publish {self.link}: {exc.strerror or exc}") from None

    def set_access(self, mode: int, group: str | int | None) -> None:
        """Give the pty ``mode`` and ``group`` (None: unchanged), in place: a reader that
        has it open reads on.

        Raises:
            DeviceError: the mode or group cannot be set (an unknown group).
        """
        try:
            Path(self.slave_path).chmod(mode)
            if group is not None:
                gid = group if isinstance(group, int) else grp.getgrnam(group).gr_gid
                os.chown(self.slave_path, -1, gid)
        except (OSError, KeyError, ValueError) as exc:  # ValueError: a NUL in the group
            raise DeviceError(f"cannot configure the pty for {self.link}: {exc}") from None

    def _publish(self) -> None:
        link = self.link
        link.parent.mkdir(parents=True, exist_ok=True)
        if link.exists() and not link.is_symlink():
            raise OSError(errno.EEXIST, f"{link} exists and is not a symlink")
        tmp = link.with_name(f".{link.name}.{os.getpid()}.tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(self.slave_path)
        tmp.replace(link)

    def check_link(self) -> str:
        """Publish the link again if it was removed.

        Returns:
            ``""`` while the link names this pty, ``"restored"`` when it was removed and
            is published again, else what is wrong (another file or link at its path,
            left as it is; or why it cannot be made again).
        """
        try:
            target = str(self.link.readlink())
        except FileNotFoundError:
            try:
                self._publish()
            except OSError as exc:
                return f"removed, and cannot be made again: {exc.strerror or exc}"
            return "restored"
        except OSError:  # EINVAL: a file or a directory, no symlink
            return "no symlink now: left as it is"
        if target == self.slave_path:
            return ""
        return f"names {target} now: left as it is"

    def check_modes(self) -> bool:
        """Put the pty's input and local modes back to raw if a reader changed them; True
        when it did. A reader that set canonical mode with ``$`` as its interrupt
        character (``stty -F LINK icanon isig intr '$'``) left every later reader lines
        cut at each ``$`` and flushed: no sentence whole. Modes are read and set through
        the master (Linux applies a pty master's termios requests to its slave)."""
        try:
            attrs = termios.tcgetattr(self.master)
            if (attrs[0], attrs[3]) == self._raw_modes:
                return False
            attrs[0], attrs[3] = self._raw_modes
            termios.tcsetattr(self.master, termios.TCSANOW, attrs)
        except (termios.error, OSError):
            return False
        return True

    def fileno(self) -> int:
        """The master's file descriptor."""
        return self.master

    def has_reader(self) -> bool:
        """True while some process has the slave open."""
        hup = False
        for _, ev in self._poll.poll(0):
            if ev & select.POLLIN:
                self._drain()
            if ev & select.POLLHUP:
                hup = True
        return not hup

    def _drain(self) -> None:
        """Discard up to ``DRAIN_BYTES`` a reader wrote into the pty."""
        left = DRAIN_BYTES
        with contextlib.suppress(BlockingIOError, OSError):
            while left > 0:
                got = len(os.read(self.master, left))
                if not got:
                    return
                left -= got

    def _trim_backlog(self, limit: int, *, full: bool) -> bool:
        """Discard a stalled reader's queue if above ``limit`` bytes (or ``full``)."""
        self._unchecked = 0
        try:
            fd = os.open(self.slave_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:  # EBUSY: a reader holds the slave exclusively (TIOCEXCL)
            return full and self._flush_from_master()
        try:
            raw = fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0")
            queued: int = struct.unpack("i", raw)[0]
            if not full and queued <= limit:
                return False
            termios.tcflush(fd, termios.TCIFLUSH)
        except (OSError, termios.error):
            return False
        finally:
            os.close(fd)
        self.flushes += 1
        return True

    def _flush_from_master(self) -> bool:
        """Discard what waits for the reader beyond its line discipline (the kernel's
        buffers behind it) from the master's side: a reader holding the slave
        exclusively (``TIOCEXCL``: gpsd, uucp) cannot be opened, and its full pty took
        no more writes, so on resuming it read the pty's capacity of the oldest data
        and none of the newest. Its line discipline's 4 KiB (:data:`LDISC_BUF`) of old
        data stay."""
        try:
            termios.tcflush(self.master, termios.TCOFLUSH)
        except (OSError, termios.error):
            return False
        self.flushes += 1
        return True

    def _write(self, data: bytes) -> int | None:
        """One write; None when the pty is full."""
        try:
            return os.write(self.master, data)
        except (BlockingIOError, InterruptedError):
            return None

    def write(self, data: bytes) -> int:
        """Write without blocking; return the bytes written (0 when dropped)."""
        if not self.has_reader():
            self.dropped += len(data)
            return 0
        limit = self.max_backlog
        if limit is not None and self._unchecked >= max(1, limit // 4):
            self._trim_backlog(limit, full=False)
        try:
            n = self._write(data)
            if n is None and limit is not None and self._trim_backlog(limit, full=True):
                n = self._write(data)
        except OSError as exc:
            if exc.errno == errno.EIO:  # the reader went away between poll and write
                self.dropped += len(data)
                return 0
            raise
        if n is None:
            self.dropped += len(data)
            return 0
        self.written += n
        self._unchecked += n
        if n < len(data):
            self.dropped += len(data) - n
        return n

    def wait_writable(self, timeout_s: float) -> bool:
        """Wait until a reader is attached and the pty takes data (for fake devices)."""
        p = select.poll()
        p.register(self.master, select.POLLOUT)
        for _, ev in p.poll(max(timeout_s, 0.0) * 1000.0):
            return bool(ev & select.POLLOUT) and not ev & select.POLLHUP
        return False

    def close(self) -> None:
        """Remove the symlink (if it is still ours) and close the pty (idempotent)."""
        if self.master < 0:
            return
        with contextlib.suppress(OSError):
            if self.link.is_symlink() and str(self.link.readlink()) == self.slave_path:
                self.link.unlink()
        os.close(self.master)
        self.master = -1
