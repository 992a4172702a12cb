"""Capture v1 files: what serial ports received, with receive times (README, "Capture files").

Text, like candump's log format but for serial ports::

    # emlogd capture v1
    # port emlog1 nmea0183
    # port dvl pd0
    (1748757600.000000) emlog1 $VWVHW,,T,,M,3.50,N,6.48,K*6A
    (1748757600.051234) dvl hex:7f7f...

The first line is :data:`MAGIC`; ``# port NAME PROTOCOL`` headers come before the
first record; other ``#`` lines are comments. A record is ``(EPOCH.SECONDS) PORT
PAYLOAD``, sorted by time. For a text protocol the payload is the received line
without its CR/LF (it is given back as the line plus CR LF); for a binary protocol,
and for a text chunk that cannot be stored verbatim (non-printable bytes, a line
without terminator), it is ``hex:`` + the bytes in lowercase hex, given back exactly.

The reader streams (constant memory, any file size) and names the file and line
of anything malformed, or counts and skips malformed records (``errors="skip"``); a file whose name ends in ``.gz`` is read through gzip. The
writer refuses unknown ports and times going backwards.

Times are read tolerantly (:class:`CaptureReader`): records up to ``reorder_window_s``
out of order (receive-time jitter between ports) are given back sorted; a record
further back is skipped alone (``out_of_order``), and so is a record that jumps
forward when the records after it do not follow it (a corrupted time: a forward
outlier is judged by the records after it, so it never makes the rest of the file
"go backwards"). A step back followed by the records after it is the clock of the
logger set back (:data:`STEP_RECORDS`): the records from the step on are shifted
forward to follow the ones before it, and the step is reported.
"""

from __future__ import annotations

import binascii
import gzip
import math
import re
import zlib
from collections import deque
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal, TextIO

from drivers.errors import CaptureFormatError
from drivers.io.closing import Closing

MAGIC = "# emlogd capture v1"
HEX_PREFIX = "hex:"
_HEX_B = HEX_PREFIX.encode("ascii")
# a record as the writer writes it: (seconds with decimals) port printable-payload, and
# the line's terminator (any other form is read by the field-by-field checks)
_GOOD_RECORD = re.compile(rb"\(([0-9]{1,12}\.[0-9]{1,9})\) ([!-~]+) ([ -~]+)[\r\n]*").fullmatch
_NAME_OK = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


@dataclass(frozen=True, slots=True)
class CaptureRecord:
    """One record of a capture.

    Attributes:
        t: receive time, s since the Unix epoch.
        port: port name.
        payload: the payload as stored (text line, or ``hex:...``).
        binary: the payload is hex-encoded bytes.
        line: 1-based line number in the file.
    """

    t: float
    port: str
    payload: str
    binary: bool
    line: int

    @property
    def data(self) -> bytes:
        """The received bytes: the text line plus CR LF, or the hex-decoded chunk."""
        if self.binary:
            return binascii.unhexlify(self.payload[len(HEX_PREFIX) :])
        return self.payload.encode("ascii") + b"\r\n"


def _unhex(payload: bytes) -> bytes:
    """A ``hex:`` payload's bytes (none when it is not hex)."""
    try:
        return binascii.unhexlify(payload[4:])
    except binascii.Error:
        return b""


def _open_binary(path: str) -> BinaryIO:
    if path.endswith(".gz"):
        return gzip.open(path, "rb")  # type: ignore[return-value]
    return open(path, "rb")


def _lines(f: BinaryIO) -> Iterator[bytes]:
    """The lines of ``f``; one longer than :data:`MAX_LINE_BYTES` as ``b""`` (no line
    read is empty: each holds its newline, or is the last), read to its end in pieces."""
    readline = f.readline
    while raw := readline(MAX_LINE_BYTES):
        if len(raw) < MAX_LINE_BYTES or raw.endswith(b"\n"):
            yield raw
            continue
        rest = readline(MAX_LINE_BYTES)
        if rest.strip(b"\r\n") == b"":  # the line ends right at the bound
            yield raw + rest
            continue
        while rest and not rest.endswith(b"\n"):
            rest = readline(MAX_LINE_BYTES)
        yield b""


def _check_name(name: str) -> bool:
    return bool(name) and all(c in _NAME_OK for c in name)


def _printable(line: bytes) -> bool:
    return all(32 <= c < 127 for c in line)


SKIP_REASONS = (
    "non_ascii",
    "bad_record",
    "bad_time",
    "unknown_port",
    "missing_payload",
    "bad_hex",
    "out_of_order",
    "late_header",
    "truncated",
    "too_long",
)
"""Why a record is skipped (``errors="skip"``): the keys of :attr:`CaptureReader.skipped`."""

CONFIRM_RECORDS = 3
"""How many records after a forward jump in time may fail to follow it before it is judged
a bad time (``out_of_order``); one that follows it makes the jump real."""

STEP_RECORDS = 10
"""How many records from a step back in time on must follow one another (none back on
the time before the step) for it to be judged the logger's clock set back: the records
from the step on are shifted to follow the ones before it (:attr:`CaptureReader.steps`).
Fewer, and each is a bad time (``out_of_order``): one record with a wrong time, or a few,
cost themselves; a clock set back (a logger's clock corrected by NTP or GNSS time in the
middle of a recording) cost every record after it, half a capture."""

REORDER_WINDOW_S = 0.2
"""Default of ``reorder_window_s``: how far (s) a record may come before one it follows and
still be put back in order (receive-time jitter of a busy machine is tens of ms)."""

MAX_LINE_BYTES = 1 << 20
"""A line longer than this is no record (the longest the writer writes, a 4 KiB read as
hex, is under 9 KiB): skipped (``too_long``) and read in pieces of this size, never held
whole, so a file of one huge line costs no more memory than this."""

MAX_SKIPPED_LINES = 10
"""How many skipped lines :attr:`CaptureReader.skipped_lines` keeps (the first ones)."""


_Scanned = tuple[float, str, bytes, bytes, int]
"""A well-formed record as read: (t, port, payload, data, line)."""


class _BadRecordError(Exception):
    """A malformed record: the reason key and the message."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.message = message


class _Order:
    """The time order of :meth:`CaptureReader._scan` (see :class:`CaptureReader`): the
    window of records not yet given back, the newest time accepted, and a forward jump
    being judged by the records after it."""

    def __init__(self, reader: CaptureReader, window: float) -> None:
        self.reader = reader
        self.window = window
        self.buf: deque[_Scanned] = deque()
        """The window: records by time, equal times in file order."""
        self.top = -math.inf
        """The newest time accepted."""
        self.held: _Scanned | None = None
        """A record that jumped forward, being judged."""
        self.followers: list[_Scanned] = []
        """The records after it that do not follow it."""
        self.back: list[_Scanned] = []
        """A step back in time and the records after it that follow it, being judged."""
        self.shift = 0.0
        """What the steps judged the logger's clock set back add to every time from them on, s."""

    def push(self, rec: _Scanned) -> list[_Scanned]:
        """Take one record; return the records it releases, in time order."""
        out: list[_Scanned] = []
        window, buf = self.window, self.buf
        queue = deque([rec])
        while queue:
            rec = queue.popleft()
            t = rec[0]
            held = self.held
            if held is not None:
                if t >= held[0] - window:  # the jump is followed: real
                    self.top = held[0] - window  # it is taken in order now
                    queue.extendleft(reversed([held, *self.followers, rec]))
                    self.held, self.followers = None, []
                    continue
                self.followers.append(rec)
                if len(self.followers) >= CONFIRM_RECORDS:  # nothing follows it: a bad time
                    self.reader._jumped(held, self.followers[0])
                    queue.extendleft(reversed(self.followers))
                    self.held, self.followers = None, []
                continue
            top = self.top
            if self.back and t >= top - window:  # not after the step back: bad times
                self._drop_back()
            if t > top + window:  # a jump forward (or the first record): judge it
                self.held = rec
                continue
            if t >= top:
                self.top = t
                buf.append(rec)
                while buf[0][0] < t - window:
                    out.append(buf.popleft())
                continue
            if t < top - window:
                queue.extendleft(reversed(self._behind(rec)))
                continue
            i = len(buf)  # within the window: put it back in its place
            while i and buf[i - 1][0] > t:
                i -= 1
            buf.insert(i, rec)
            self.reader.reordered += 1
        return out

    def _behind(self, rec: _Scanned) -> list[_Scanned]:
        """Judge a record more than the window before the newest time: the records to take
        again, shifted, once :data:`STEP_RECORDS` of them make a step back the clock's."""
        back = self.back
        if back and rec[0] < back[-1][0] - self.window:  # follows neither: a bad time
            self._out_of_order(rec)
            return []
        back.append(rec)
        if len(back) < STEP_RECORDS:
            return []
        step = self.top - back[0][0]  # the clock was set back: shift the rest
        self.reader._stepped(back[0], step)
        self.shift += step
        again = [(r[0] + step, *r[1:]) for r in back]
        back.clear()
        return again

    def _drop_back(self) -> None:
        """The records held after a step back, each a bad time (``out_of_order``)."""
        for r in self.back:
            self._out_of_order(r)
        self.back.clear()

    def _out_of_order(self, rec: _Scanned) -> None:
        self.reader._skip(
            rec[4],
            _BadRecordError(
                "out_of_order",
                f"time {rec[0]:.6f} more than {self.window:g} s before {self.top:.6f}",
            ),
        )

    def end(self) -> list[_Scanned]:
        """The end of the records: judge a jump still held (it stands unless records after
        it contradict it), then give back the window (a step back too few records long
        for a clock set back: bad times)."""
        out: list[_Scanned] = []
        self._drop_back()
        while self.held is not None:
            held, followers = self.held, self.followers
            self.held, self.followers = None, []
            if followers:
                self.reader._jumped(held, followers[0])
                again = followers
            else:
                self.top = held[0] - self.window  # it is taken in order now
                again = [held]
            for rec in again:
                out.extend(self.push(rec))
        out.extend(self.buf)
        self.buf.clear()
        return out


class CaptureReader:
    """Stream the records of a capture file.

    The header (magic and port lines) is read when the reader is created;
    iterating reads the records lazily, from the start each time.

    With ``errors="raise"`` (the default) the first malformed record raises; with
    ``errors="skip"`` a record that cannot be parsed (not ASCII, no time, a bad time,
    an unknown port, no payload, bad hex, a time out of order, a port header after
    the records) is counted by reason in :attr:`skipped`, its line and message kept in
    :attr:`skipped_lines` (the first :data:`MAX_SKIPPED_LINES`), and reading goes on;
    a gzip stream cut short ends the records (reason ``truncated``). A malformed
    header always raises. Line numbers count ``\\n`` from 1, as editors and
    ``sed -n`` do, in the decompressed text of a ``.gz`` file.

    Times: records are held back ``reorder_window_s`` (of file time) and given back
    sorted by time (equal times in file order), so jitter within the window costs
    nothing; :attr:`reordered` counts the records that came back in another place. A
    record older than one already given back is ``out_of_order``. A record more than
    the window ahead of the newest time read is held until the next record: if that
    one is more than the window before it, the jump was a corrupted time and the
    record is ``out_of_order``; otherwise the jump is real (a pause in the capture). The
    first record is judged the same way.
    So one record with a wrong time, before or after, costs that record only.

    Args:
        path: the capture file.
        errors: ``"raise"`` or ``"skip"``.
        reorder_window_s: the window (s, ≥ 0; 0: every record must follow the last).

    Raises:
        CaptureFormatError: (on creation or while iterating) naming file and line.
        OSError: the file cannot be opened.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        errors: Literal["raise", "skip"] = "raise",
        reorder_window_s: float = REORDER_WINDOW_S,
    ) -> None:
        if errors not in ("raise", "skip"):
            raise ValueError(f"errors must be 'raise' or 'skip', not {errors!r}")
        if not (math.isfinite(reorder_window_s) and reorder_window_s >= 0.0):
            raise ValueError(f"reorder_window_s must be ≥ 0, not {reorder_window_s!r}")
        self.path = str(path)
        self.errors = errors
        self.reorder_window_s = float(reorder_window_s)
        self.reordered = 0
        """Records the last (or current) iteration put back before records read earlier
        (in time order, within the window)."""
        self.ports: dict[str, str] = {}
        self.skipped: dict[str, int] = {}
        self.skipped_lines: list[tuple[int, str]] = []
        self.steps: list[tuple[int, float]] = []
        """The steps back of the logger's clock the last (or current) iteration found
        (:data:`STEP_RECORDS`): (line, s); the records from each on are shifted by it."""
        try:
            with _open_binary(self.path) as f:
                self._read_header(f)
        except (gzip.BadGzipFile, EOFError, zlib.error) as exc:
            raise self._fail(1, f"not a readable gzip file: {exc}") from None

    @property
    def n_skipped(self) -> int:
        """Records skipped by the last (or current) iteration."""
        return sum(self.skipped.values())

    def skip_report(self) -> dict[str, object]:
        """``{"skipped": n, "reasons": {reason: n}, "reordered": n, "steps": [{"line",
        "step_s"}], "first": [{"line", "error"}]}``."""
        return {
            "skipped": self.n_skipped,
            "reasons": dict(self.skipped),
            "reordered": self.reordered,
            "steps": [{"line": n, "step_s": step} for n, step in self.steps],
            "first": [{"line": n, "error": msg} for n, msg in self.skipped_lines],
        }

    def _fail(self, line: int, msg: str) -> CaptureFormatError:
        return CaptureFormatError(self.path, line, msg)

    def _read_header(self, f: BinaryIO) -> None:
        first = f.readline(256)
        if first.rstrip(b"\r\n") != MAGIC.encode("ascii"):
            raise self._fail(1, f"not a capture v1 file (first line must be {MAGIC!r})")
        n = 1
        for raw in _lines(f):
            n += 1
            if not raw.startswith(b"#"):
                break
            try:
                line = raw.decode("ascii").rstrip("\r\n")
            except UnicodeDecodeError:
                raise self._fail(n, "non-ASCII bytes in a header line") from None
            self._header_line(line, n)

    def _header_line(self, line: str, n: int) -> None:
        parts = line[1:].split()
        if not parts or parts[0] != "port":
            return  # a comment
        if len(parts) != 3:
            raise self._fail(n, "port header must be '# port NAME PROTOCOL'")
        name, proto = parts[1], parts[2]
        if not _check_name(name):
            raise self._fail(n, f"bad port name {name!r}")
        if name in self.ports and self.ports[name] != proto:
            raise self._fail(n, f"port {name!r} declared twice")
        self.ports[name] = proto

    def _skip(self, n: int, bad: _BadRecordError) -> None:
        if self.errors == "raise":
            raise self._fail(n, bad.message)
        self.skipped[bad.reason] = self.skipped.get(bad.reason, 0) + 1
        if len(self.skipped_lines) < MAX_SKIPPED_LINES:
            self.skipped_lines.append((n, bad.message))

    def __iter__(self) -> Iterator[CaptureRecord]:
        for t, port, payload, _, n in self._scan():
            yield CaptureRecord(t, port, payload.decode("ascii"), payload[:4] == _HEX_B, n)

    def received(self) -> Iterator[tuple[float, str, bytes, int]]:
        """``(t, port, data, line)`` of every record: the records :meth:`__iter__` gives,
        as the time, the port, the received bytes (:attr:`CaptureRecord.data`) and the
        line, without building a :class:`CaptureRecord` (what the replay reads)."""
        for t, port, _, data, n in self._scan():
            yield t, port, data, n

    def _scan(self) -> Iterator[tuple[float, str, bytes, bytes, int]]:
        """``(t, port, payload, data, line)`` of every good record, in time order (see the
        class docstring); the bad ones raise or are skipped. A record in order within the
        window of the newest (nearly every one) is taken here; :class:`_Order` judges the
        others."""
        self.skipped = {}
        self.skipped_lines = []
        self.reordered = 0
        self.steps = []
        window = self.reorder_window_s
        order = _Order(self, window)
        buf = order.buf
        for rec in self._parse():
            if order.shift:
                rec = (rec[0] + order.shift, *rec[1:])
            t = rec[0]
            top = order.top
            if top <= t <= top + window and order.held is None and not order.back:
                order.top = t
                buf.append(rec)
                limit = t - window
                while buf[0][0] < limit:
                    yield buf.popleft()
                continue
            yield from order.push(rec)
        yield from order.end()

    def _stepped(self, rec: _Scanned, step: float) -> None:
        """The logger's clock judged set back by ``step`` s at ``rec`` (raise mode: an error)."""
        if self.errors == "raise":
            raise self._fail(rec[4], f"time {rec[0]:.6f} steps back {step:.3f} s")
        self.steps.append((rec[4], step))

    def _jumped(self, rec: _Scanned, after: _Scanned) -> None:
        self._skip(
            rec[4],
            _BadRecordError(
                "out_of_order",
                f"time {rec[0]:.6f} jumps ahead of the records after it ({after[0]:.6f} "
                f"on line {after[4]})",
            ),
        )

    def _parse(self) -> Iterator[_Scanned]:
        """``(t, port, payload, data, line)`` of every well-formed record in file order;
        the bad ones raise or are skipped. A line of the form the writer writes is read
        by one pattern match; any other line (a comment, an odd but valid record, a bad
        one) by the checks of :meth:`_record`, which name what is wrong."""
        ports = {name.encode("ascii"): name for name in self.ports}
        good = _GOOD_RECORD
        in_header = True
        n = 0
        with _open_binary(self.path) as f:
            try:
                for raw in _lines(f):
                    n += 1
                    if not raw:
                        self._skip(
                            n,
                            _BadRecordError(
                                "too_long", f"a line longer than {MAX_LINE_BYTES} bytes"
                            ),
                        )
                        continue
                    m = good(raw)
                    if m is not None:
                        stamp, name, payload = m.groups()
                        port = ports.get(name)
                        if port is not None:
                            data = payload + b"\r\n" if payload[:4] != _HEX_B else _unhex(payload)
                            if data:  # else named by _record's checks below
                                in_header = False
                                yield float(stamp), port, payload, data, n
                                continue
                    if n == 1:
                        continue
                    in_header, rec = self._other(raw, n, in_header)
                    if rec is not None:
                        yield rec.t, rec.port, rec.payload.encode("ascii"), rec.data, n
            except (gzip.BadGzipFile, EOFError, zlib.error) as exc:
                self._skip(
                    n + 1, _BadRecordError("truncated", f"the gzip stream ends early: {exc}")
                )

    def _other(self, raw: bytes, n: int, in_header: bool) -> tuple[bool, CaptureRecord | None]:
        """A line the writer's pattern does not match: a comment (a port header only
        before the first record), a blank line, or a record read by :meth:`_record`
        (skipped, or raising, when bad). Returns whether the header goes on, and the
        record."""
        try:
            line = raw.rstrip(b"\r\n").decode("ascii")
            if not line:
                return in_header, None
            if line.startswith("#"):
                if not in_header and line[1:].split()[:1] == ["port"]:
                    raise _BadRecordError("late_header", "port header after the first record")
                return in_header, None
            in_header = False
            return False, self._record(line, n)
        except UnicodeDecodeError:
            self._skip(n, _BadRecordError("non_ascii", "non-ASCII bytes (payloads must be hex:)"))
        except _BadRecordError as bad:
            self._skip(n, bad)
        return in_header, None

    def _record(self, line: str, n: int) -> CaptureRecord:
        if not line.startswith("("):
            raise _BadRecordError("bad_record", "record must start with '(EPOCH.SECONDS)'")
        close = line.find(") ")
        if close < 0:
            raise _BadRecordError("bad_record", "record must be '(EPOCH.SECONDS) PORT PAYLOAD'")
        try:
            t = float(line[1:close])
        except ValueError:
            raise _BadRecordError("bad_time", f"bad time {line[1:close]!r}") from None
        if not math.isfinite(t):
            raise _BadRecordError("bad_time", f"bad time {line[1:close]!r}")
        port, sep, payload = line[close + 2 :].partition(" ")
        if port not in self.ports:
            raise _BadRecordError(
                "unknown_port",
                f"unknown port {port!r} (declared: {', '.join(self.ports) or 'none'})",
            )
        if not sep or not payload:
            raise _BadRecordError("missing_payload", "missing payload")
        binary = payload.startswith(HEX_PREFIX)
        if binary:
            digits = payload[len(HEX_PREFIX) :]
            if not digits or len(digits) % 2:
                raise _BadRecordError("bad_hex", "hex payload must have an even number of digits")
            try:
                binascii.unhexlify(digits)
            except binascii.Error:
                raise _BadRecordError("bad_hex", "bad hex payload") from None
        return CaptureRecord(t, port, payload, binary, n)


def read_ports(path: str | Path) -> dict[str, str]:
    """The ``# port`` headers of a capture: name -> protocol."""
    return CaptureReader(path).ports


def capture_name(path: str | Path) -> str:
    """A capture's file name without ``.cap``/``.gz`` (``runs/2-figure8.cap.gz``:
    ``2-figure8``), the name tables and reports give it."""
    name = Path(path).name
    for suffix in (".gz", ".cap"):
        name = name.removesuffix(suffix)
    return name


class CaptureWriter(Closing):
    """Write a capture v1 file (context manager).

    Args:
        path: the file to create (replaced if it exists); a ``.gz`` name is written
            gzip-compressed.
        ports: port name -> protocol, written as headers.

    Raises:
        ValueError: a bad port name or unknown protocol.
    """

    def __init__(self, path: str | Path, ports: Mapping[str, str]) -> None:
        from drivers import protocol_names

        known = set(protocol_names())
        for name, proto in ports.items():
            if not _check_name(name):
                raise ValueError(f"bad port name {name!r} (letters, digits, _ - . only)")
            if proto not in known:
                raise ValueError(f"port {name!r}: unknown protocol {proto!r}")
        self.path = str(path)
        self.ports = dict(ports)
        self._last_t = -math.inf
        self._f: TextIO | None = (
            gzip.open(self.path, "wt", encoding="ascii", newline="\n")  # noqa: SIM115
            if self.path.endswith(".gz")
            else open(self.path, "w", encoding="ascii", newline="\n")  # noqa: SIM115
        )
        self._f.write(MAGIC + "\n")
        for name, proto in self.ports.items():
            self._f.write(f"# port {name} {proto}\n")

    def comment(self, text: str) -> None:
        """A ``#`` comment line (before or between records; one line, printable ASCII)."""
        if "\n" in text or "\r" in text or not text.isascii():
            raise ValueError("a comment is one line of ASCII")
        if text.split()[:1] == ["port"]:
            raise ValueError("a comment cannot start with 'port'")
        self._file().write(f"# {text}\n")

    def _file(self) -> TextIO:
        if self._f is None:
            raise ValueError("capture writer is closed")
        return self._f

    def _stamp(self, t: float, port: str) -> str:
        if port not in self.ports:
            raise ValueError(f"unknown port {port!r}")
        if not math.isfinite(t) or t < self._last_t:
            raise ValueError(f"time {t!r} is not finite or goes backwards (last {self._last_t})")
        self._last_t = t
        return f"({t:.6f}) {port} "

    def write_line(self, t: float, port: str, line: bytes) -> None:
        """A received text line without its CR/LF (stored as hex if not printable ASCII)."""
        if line and _printable(line) and not line.startswith(HEX_PREFIX.encode()):
            self._file().write(self._stamp(t, port) + line.decode("ascii") + "\n")
        else:
            self.write_chunk(t, port, line + b"\r\n")

    def write_chunk(self, t: float, port: str, data: bytes) -> None:
        """Received bytes, stored exactly as ``hex:``."""
        if not data:
            return
        self._file().write(self._stamp(t, port) + HEX_PREFIX + data.hex() + "\n")

    def flush(self) -> None:
        """Flush buffered records to the file."""
        self._file().flush()

    def close(self) -> None:
        """Flush and close (idempotent)."""
        if self._f is not None:
            self._f.close()
            self._f = None
