"""Benchmark: the live daemon's inputs flooded with hostile bytes, next to an EMlog.

Starts ``emlogd run`` (the tree on ``PYTHONPATH``) with an EMlog (NMEA), a PD0 DVL, a
PD5 and a PD6 aux port and a GNSS aux port (NMEA), each on a pty this script serves.
For ``--seconds`` one process per flooded port writes hostile input as fast as the pty
takes it: NMEA sentences of ten types with a hostile value (``1e308``, ``nan``,
``inf``, -5, 26 nines, ``٣``...) in every field and valid checksums, a line of a
megabyte without newline, 4 KiB of NUL, random bytes (GNSS); PD0 headers claiming
16 000-byte ensembles with wrong checksums, random bytes, random headers (DVL); PD5
frames with random bodies (PD5); PD6 lines with those values (PD6); or (``--ports
dates``) valid RMC whose date moves by a day at each fix (GNSS). Meanwhile the
EMlog sends a VHW every 0.1 s and the script times each corrected VHW on the output
pty. Prints the daemon's CPU (cores), the VHW latency (median, 95th percentile; a VHW
not out within 0.1 s counts as late), the slowest status request and each port's
records and rejects.

Run: ``PYTHONPATH=. python bench/bench_hostile_inputs.py [--ports all|gnss|dvl|pd5|pd6|dates]
[--seconds 8]``
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import random
import select
import tempfile
import time
import tty
from collections.abc import Callable
from pathlib import Path

from emlogd.launch import DaemonProcess
from tests.emlogd.daemon.harness import PD0_CONFIG, raw_pty

CONFIG = PD0_CONFIG.replace(
    "calibration:",
    """\
  - {name: gnss, url: links/gnss, protocol: nmea0183, role: aux}
  - {name: pd5, url: links/pd5, protocol: pd5, role: aux}
  - {name: pd6, url: links/pd6, protocol: pd6, role: aux}
calibration:""",
)
"""The EMlog and the PD0 DVL, and three aux ports: GNSS, PD5, PD6."""

HOSTILE = ["1e308", "-1e308", "nan", "inf", "-inf", "-5", "9" * 26, "", "1e-320", "360.0001", "٣"]
"""Values put in every field."""

TYPES = {
    "GPRMC": 12,
    "GPGGA": 14,
    "GPVTG": 9,
    "GPZDA": 6,
    "HCHDG": 5,
    "HEHDT": 2,
    "VWVHW": 8,
    "VWVBW": 10,
    "GPGLL": 7,
    "HEHDM": 2,
}
"""NMEA sentence types and their field counts."""

PD0_HEADER = bytes([0x7F, 0x7F, 0x80, 0x3E, 0x00, 0x01])
"""A PD0 header claiming a 16 000-byte ensemble."""

LATE_S = 0.1
"""A corrected VHW not out within this long after its reading is late."""


def sentence(body: str) -> bytes:
    """``$body*CS`` with its checksum, CR LF."""
    cs = 0
    for ch in body.encode():
        cs ^= ch
    return f"${body}*{cs:02X}\r\n".encode()


def gnss(rng: random.Random) -> bytes:
    r = rng.random()
    if r < 0.05:
        return b"$GPRMC," + b"9" * 1_000_000  # a megabyte without newline
    if r < 0.2:
        return bytes(4096)
    if r < 0.3:
        return rng.randbytes(2048)
    kind, n = rng.choice(list(TYPES.items()))
    fields = [rng.choice([*HOSTILE, "1.0", "A", "N", "E", "T", "120000.00"]) for _ in range(n)]
    return sentence(kind + "," + ",".join(fields))


def dvl(rng: random.Random) -> bytes:
    r = rng.random()
    if r < 0.9:
        return PD0_HEADER * 50
    if r < 0.95:
        return rng.randbytes(300)
    header = [0x7F, 0x7F, rng.randrange(256), rng.randrange(256), 0, rng.randrange(1, 33)]
    return bytes(header) + rng.randbytes(60)


def pd5(rng: random.Random) -> bytes:
    if rng.random() < 0.5:
        return bytes([0x7D, 1, 86, 0]) + rng.randbytes(84)
    return bytes([0x7D, 0, 45, 0]) * 30


def pd6(rng: random.Random) -> bytes:
    kind = rng.choice([":BS", ":BE", ":BD", ":SA", ":TS", ":WI", ":WS", ":BI"])
    fields = [rng.choice([*HOSTILE, "+00123", "-00050", "A", "V"]) for _ in range(5)]
    return (kind + "," + ",".join(fields) + "\r\n").encode()


def dates(rng: random.Random) -> bytes:
    """50 valid RMC with a position, each fix a day after the one before (25 years)."""
    out = b""
    for _ in range(50):
        k = rng.randrange(9125)
        day = f"{1 + k % 28:02d}{1 + k // 28 % 12:02d}{k // 336 % 25:02d}"
        out += sentence(f"GPRMC,120000.00,A,4500.000,N,01000.000,E,5.0,90.0,{day},2.0,E,A")
    return out


FLOODS: dict[str, tuple[str, Callable[[random.Random], bytes]]] = {
    "gnss": ("gnss", gnss),
    "dvl": ("dvl", dvl),
    "pd5": ("pd5", pd5),
    "pd6": ("pd6", pd6),
    "dates": ("gnss", dates),
}
"""What ``--ports`` floods: the port, and its input (``all``: the first four)."""


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _flood(fd: int, make: Callable[[random.Random], bytes], until: float, seed: str) -> None:
    rng = random.Random(seed)
    pending = b""
    while time.monotonic() < until:
        pending = pending or make(rng)
        try:
            pending = pending[os.write(fd, pending[:65536]) :]
        except BlockingIOError:
            select.select([], [fd], [], 0.01)
        except OSError:
            time.sleep(0.01)


def _vhw_latency(fd: int, emlog: int, k: int) -> float:
    """Send the EMlog's k-th VHW; seconds until a VHW is out (inf: later than LATE_S)."""
    sent = time.monotonic()
    os.write(emlog, sentence(f"VWVHW,,T,,M,5.0{k % 2},N,,K"))  # alternating: not stuck
    data = b""
    while b"VHW" not in data and (left := sent + LATE_S - time.monotonic()) > 0:
        if select.select([fd], [], [], left)[0]:
            data += os.read(fd, 65536)
    return time.monotonic() - sent if b"VHW" in data else math.inf


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ports", choices=("all", "none", *FLOODS), default="all")
    ap.add_argument("--seconds", type=float, default=8.0)
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="emlogd-hostile-"))
    for sub in ("links", "state", "run", "out"):
        (work / sub).mkdir()
    (work / "emlogd.yaml").write_text(CONFIG)
    links = ("emlog1", "gnss", "dvl", "pd5", "pd6")
    masters = {name: raw_pty(work / "links" / name) for name in links}
    daemon = DaemonProcess("emlogd.yaml", socket="run/control.sock", log="log", cwd=work)
    out = os.open(work / "out" / "emlog0", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(out)
    try:
        until = time.monotonic() + args.seconds + 1.0
        for name, (port, make) in FLOODS.items():
            wanted = args.ports == name or (args.ports == "all" and name != "dates")
            if wanted and os.fork() == 0:  # a process each: no GIL
                _flood(masters[port], make, until, name)
                os._exit(0)
        time.sleep(1.0)
        cpu0, t0 = _cpu_s(daemon.pid), time.monotonic()
        latencies: list[float] = []
        worst_status = 0.0
        while time.monotonic() < until:
            started = time.monotonic()
            latencies.append(_vhw_latency(out, masters["emlog1"], len(latencies)))
            if len(latencies) % 10 == 0:
                t = time.monotonic()
                daemon.ask(cmd="status")
                worst_status = max(worst_status, time.monotonic() - t)
            time.sleep(max(started + 0.1 - time.monotonic(), 0.0))
        cpu1, t1 = _cpu_s(daemon.pid), time.monotonic()
        ports = daemon.ask(cmd="status")["status"]
        assert isinstance(ports, dict)
    finally:
        os.close(out)
        daemon.stop()
        with contextlib.suppress(ChildProcessError):
            while os.wait()[0] > 0:
                pass
    latencies.sort()
    late = sum(math.isinf(x) for x in latencies)
    print(
        f"ports {args.ports}: daemon CPU {(cpu1 - cpu0) / (t1 - t0):.2f} cores; VHW latency "
        f"median {latencies[len(latencies) // 2] * 1e3:.1f} ms, 95th percentile "
        f"{latencies[int(len(latencies) * 0.95)] * 1e3:.0f} ms, {late} of {len(latencies)} "
        f"later than {LATE_S:g} s; slowest status {worst_status * 1e3:.0f} ms"
    )
    for name, port in ports["ports"].items():
        rejects = {k: v for k, v in port["rejects"].items() if v}
        print(f"  {name}: records {port['records']}, rejects {rejects}")


if __name__ == "__main__":
    main()
