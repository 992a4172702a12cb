"""Benchmark: ``emlogd import`` of large synthetic logs, time and peak memory.

Writes an NMEA log (RMC, HDG, VHW and wind/depth sentences at 1 Hz, the yacht logs'
mix) and an Expedition-style CSV of the given sizes, imports each in a fresh process
(``emlogd import``) and prints the wall time and the child's peak resident memory
(``ru_maxrss``). The import streams, so the peak stays near the interpreter's own
whatever the size: compare two sizes.

Run from the repository root: ``PYTHONPATH=. python bench/bench_import.py [--mb 62 8]``.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

from drivers.framing import with_checksum
from drivers.nmea0183 import encode_rmc, encode_vhw

T0 = datetime(2014, 6, 27, 12, tzinfo=UTC).timestamp()


def write_nmea(path: Path, mb: float) -> int:
    """An NMEA log of about ``mb`` MB; returns its lines."""
    n = 0
    with open(path, "w") as f:
        k = 0
        while f.tell() < mb * 1e6:
            t = T0 + k
            psi = (k // 60 * 45.0) % 360.0
            u = 3.0 + math.sin(k / 40.0)
            lines = [
                encode_rmc(datetime.fromtimestamp(t, UTC), u, psi, lat_deg=46.2, lon_deg=6.2),
                with_checksum(f"IIHDG,{psi:.0f},,,,"),
                encode_vhw(u, heading_mag_deg=psi, talker="II"),
                with_checksum("IIMWV,045,R,12.0,N,A"),
                with_checksum("IIDPT,009.4,-1.0,"),
                with_checksum("IIVLW,01554,N,000.0,N"),
            ]
            f.write("\r\n".join(lines) + "\r\n")
            n += len(lines)
            k += 1
    return n


def write_csv(path: Path, mb: float) -> int:
    """An Expedition-style CSV of about ``mb`` MB; returns its rows."""
    n = 0
    with open(path, "w") as f:
        f.write("Utc,Bsp,Awa,Aws,Hdg,Lat,Lon,Cog,Sog,iSet,iDrift\n")
        k = 0
        while f.tell() < mb * 1e6:
            ole = 41817.5 + k / 86400.0
            psi = (k // 60 * 45.0) % 360.0
            u = 6.0 + math.sin(k / 40.0)
            sog = round(u + 0.2, 1) if k % 2 else ""
            f.write(f"{ole:.6f},{u:.3f},-30.5,12.1,{psi:.1f},46.2,6.2,{psi:.1f},{sog},120.0,0.3\n")
            n += 1
            k += 1
    return n


CHILD = (
    "import resource, sys\n"
    "from emlogd.cli import main\n"
    "rc = main(sys.argv[1:])\n"
    "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n"
    "sys.exit(rc)\n"
)
"""The child: ``emlogd`` with the arguments, then its own peak RSS (KiB) on stderr."""


def run(args: list[str]) -> tuple[float, float]:
    """(wall s, peak RSS MB) of ``emlogd import ARGS`` in a fresh child process."""
    t0 = time.perf_counter()
    root = str(Path(__file__).resolve().parent.parent)
    env = {**os.environ, "PYTHONPATH": root}
    done = subprocess.run(
        [sys.executable, "-c", CHILD, "import", *args],
        check=True,
        env=env,
        cwd=root,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    dt = time.perf_counter() - t0
    return dt, int(done.stderr.strip().splitlines()[-1]) / 1024.0


def main() -> None:
    """Write, import and measure each size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, nargs="+", default=[62.0])
    parser.add_argument("--format", choices=["nmea", "csv"], nargs="+", default=["nmea", "csv"])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        for fmt in args.format:
            for mb in args.mb:
                src = Path(d) / f"log.{fmt}"
                n = write_nmea(src, mb) if fmt == "nmea" else write_csv(src, mb)
                size = src.stat().st_size / 1e6
                dt, rss = run([str(src), "--format", fmt, "--out", str(Path(d) / "o.cap.gz")])
                print(f"{fmt:4} {size:6.1f} MB, {n:8d} lines: {dt:6.1f} s, peak RSS {rss:6.1f} MB")
                src.unlink()


if __name__ == "__main__":
    main()
