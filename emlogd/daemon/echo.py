"""The daemon's own output coming back on an input: an NMEA multiplexer forwarding every
talker to every listener wires the autopilot's bus, the corrected sentences on it, back
into the log's input. Read as readings, each echo doubled the log's rate: every reading
was dropped as a babble (``implausible_rate``) and the autopilot had no speed for as long
as the loop lasted; another log's echoed VHW read as this log's.

The proof of a loop is the daemon's own status or fused sentence (``$P<maker>S``,
``$P<maker>F``) arriving on an NMEA input: no device sends them. A read ending in the
beginning of one (``$P``, ``$PEM``: a serial line delivers a sentence a few bytes a read)
holds those bytes back until the next read, so a proof split across reads is seen
whole. Lines before the proof are read as they came. From then on, for
:data:`LOOP_S` after the last such sentence, that port's lines are judged whole (a
partial line waits for its end, as the decoder's would) and each line byte-identical to
one the daemon wrote within :data:`ECHO_S` is its echo: skipped, counted, and that
written line taken (one echo per line written: a log repeating the same reading sends it
again after its echo, and that one is read). The daemon's own sentences are skipped too.
Without that proof nothing is judged: a log whose sentences equal the daemon's (a raw
reading passed through) is never mistaken for an echo of it.

Must not import: serial, time (the clock is handed in).
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable, Iterable

from emlogd.config import Config

ECHO_S = 2.0
"""How long after it was written a sentence may come back as an echo, s (a multiplexer
forwards within milliseconds; a busy one buffers up to a few hundred)."""

LOOP_S = 60.0
"""How long after the daemon's own status sentence was last seen on a port its lines
are judged for echoes, s (the status sentence comes every few seconds)."""

MAX_PARTIAL = 4096
"""The longest unended line held for its end while a port's lines are judged, bytes."""

MAX_SENT = 4096
"""The most written lines remembered (a flood of outputs keeps the newest)."""


class EchoFilter:
    """Skips the daemon's own output read back on its NMEA inputs.

    Args:
        monotonic: the clock of :data:`ECHO_S` and :data:`LOOP_S`.
        on_loop: called with a port's name when its lines begin to be judged.
    """

    def __init__(
        self, monotonic: Callable[[], float], on_loop: Callable[[str], None] | None = None
    ) -> None:
        self.monotonic = monotonic
        self.on_loop = on_loop
        self.ports: frozenset[str] = frozenset()
        """The NMEA inputs judged."""
        self.own: tuple[bytes, ...] = ()
        """How the daemon's own proprietary sentences begin."""
        self.sent: deque[tuple[float, bytes]] = deque()
        self.pending: Counter[bytes] = Counter()
        """The lines written within :data:`ECHO_S` whose echo has not come."""
        self.loop_until: dict[str, float] = {}
        self.partial: dict[str, bytes] = {}
        self.echoes: Counter[str] = Counter()
        """Lines skipped per port."""

    def configure(self, cfg: Config) -> None:
        """The inputs and sentence makers of ``cfg`` (at the start and every reload)."""
        self.ports = frozenset(p.name for p in cfg.ports if p.protocol == "nmea0183")
        self.partial = {k: v for k, v in self.partial.items() if k in self.ports}
        makers = {cfg.outputs.maker, *(c.settings.maker for c in cfg.calibration)}
        self.own = tuple(f"$P{m}{kind},".encode() for m in sorted(makers) for kind in "SF")

    def wrote(self, data: bytes) -> None:
        """Lines the daemon wrote to its outputs (CR LF ended)."""
        now = self.monotonic()
        for line in data.split(b"\r\n"):
            if line:
                self.sent.append((now, line))
                self.pending[line] += 1
        self._forget(now)

    def _forget(self, now: float) -> None:
        while self.sent and (now - self.sent[0][0] > ECHO_S or len(self.sent) > MAX_SENT):
            _, line = self.sent.popleft()
            self.pending[line] -= 1
            if self.pending[line] <= 0:
                del self.pending[line]

    def looping(self, port: str) -> bool:
        """Whether ``port`` has carried the daemon's own sentences within :data:`LOOP_S`."""
        return self.monotonic() < self.loop_until.get(port, -1.0)

    def read(self, port: str, data: bytes) -> bytes:
        """What of ``data``, read on ``port``, is not the daemon's own output."""
        if port not in self.ports:
            return data
        now = self.monotonic()
        buf = self.partial.pop(port, b"") + data
        if now >= self.loop_until.get(port, -1.0) and not any(p in buf for p in self.own):
            self.loop_until.pop(port, None)
            held = self._proof_begun(buf)
            if held:  # the proof may be arriving: its start waits for the next read
                self.partial[port] = buf[-held:]
                return buf[:-held]
            return buf  # no loop: passed as it came
        *lines, tail = buf.split(b"\n")
        long = b""
        if len(tail) > MAX_PARTIAL:  # no sentence is this long: the decoder's to reject
            long, tail = tail, b""
        if tail:
            self.partial[port] = tail
        self._forget(now)
        return b"".join(line + b"\n" for line in self._judge(port, now, lines)) + long

    def _proof_begun(self, buf: bytes) -> int:
        """How many bytes at the end of ``buf`` are the beginning of the daemon's own
        sentence (``$``, ``$P``, ... ``$PEMLS``), 0 if none: a proof split across reads,
        as a serial line's few bytes a read split it, is whole at the next one."""
        for k in range(max((len(p) for p in self.own), default=1) - 1, 0, -1):
            if any(len(p) > k and buf.endswith(p[:k]) for p in self.own):
                return k
        return 0

    def _judge(self, port: str, now: float, lines: Iterable[bytes]) -> Iterable[bytes]:
        for line in lines:
            text = line.rstrip(b"\r")
            if text.startswith(self.own):
                if port not in self.loop_until and self.on_loop is not None:
                    self.on_loop(port)
                self.loop_until[port] = now + LOOP_S
                self.echoes[port] += 1
            elif self.pending.get(text, 0) > 0 and now < self.loop_until.get(port, -1.0):
                self._take(text)
                self.echoes[port] += 1
            else:
                yield line

    def _take(self, text: bytes) -> None:
        """The oldest written ``text`` has had its echo."""
        for i, (_, line) in enumerate(self.sent):
            if line == text:
                del self.sent[i]
                break
        self.pending[text] -= 1
        if self.pending[text] <= 0:
            del self.pending[text]
