"""Benchmarks of the real daemon: start → READY, latency, CPU and memory.

1. start → READY=1: ``emlogd run`` as a subprocess with a notify socket.
2. Latency: a VHW sentence written into an input pty → the corrected VHW readable on
   the daemon's output pty, at 10 Hz with a 10 Hz PD6 DVL alongside; median and p99,
   and the same through a bare single-threaded Python pty forwarder timed in the same
   run, sentence by sentence in turn with the daemon's.
3. CPU and RSS at live rates: three fake devices replay the simulated figure-8 at real
   speed (1 Hz VHW, 10 Hz VBW + 5 Hz VHW, 10 Hz PD6) for ``--live-seconds``.
4. RSS growth over 24 simulated hours replayed fast through the pipeline (in a child
   process, the trial repeated with shifted times).

Targets (issue 6): READY ≤ 1.5 s; latency median ≤ 1 ms, p99 ≤ 5 ms, ≤ 2× the
forwarder; CPU ≤ 1 % of a core; RSS ≤ 80 MiB; growth ≤ 1 MiB. Prints figures only.

Run: ``python bench/bench_daemon.py [--live-seconds 60] [--trial DIR]``
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

from calib.estimate import Estimate
from calib.models import Params
from drivers.io.vpty import VirtualPort
from drivers.nmea0183 import encode_vhw
from drivers.rdi_ascii import encode_pd6
from emlogd.daemon.statefile import StateStore
from emlogd.launch import DaemonProcess, fake_sensors
from emlogd.pipeline.calibration import Calibration

CONFIG = """\
ports:
  - {name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}
  - {name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut}
  - {name: dvl, url: links/dvl, protocol: pd6, role: reference}
  - {name: junk, url: links/junk, protocol: nmea0183, role: aux}
calibration:
  - {uut: emlog1, reference: dvl, lag: 0.0}
  - {uut: emlog2, reference: dvl, lag: 0.0, talker: VM, pty: out/emlog2}
outputs: {pty: out/emlog0, status_sentence_interval_s: 1}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
log_level: warning
status_log_interval_s: 10
"""

FORWARDER = r"""
import os, select, sys, tty
src = os.open(sys.argv[1], os.O_RDONLY | os.O_NOCTTY)
m, s = os.openpty(); tty.setraw(s)
os.symlink(os.ttyname(s), sys.argv[2])
os.close(s)
print("ready", flush=True)
while True:
    select.select([src], [], [])
    data = os.read(src, 4096)
    if not data:
        break
    os.write(m, data)
"""


REST_S: float | None = None
"""``--rest-s``: the rest of the reference and aux ports (None: the config's default)."""


def _setup(work: Path) -> Path:
    for sub in ("links", "out", "state", "run"):
        (work / sub).mkdir(parents=True, exist_ok=True)
    cfg = work / "emlogd.yaml"
    text = CONFIG
    if REST_S is not None:  # --rest-s: the reference and aux ports' rest, s
        text = text.replace("role: reference}", f"role: reference, rest_s: {REST_S}}}")
        text = text.replace("role: aux}", f"role: aux, rest_s: {REST_S}}}")
    cfg.write_text(text)
    StateStore(work / "state" / "state.yaml").save(
        {"emlog1": Calibration("emlog1", Estimate(Params("EM3", m=0.1, b_mps=0.05), {}), None)}
    )
    return cfg


READY_TIMEOUT_S = 30.0  # the longest wait for READY=1 before the bench gives up


def _start(
    work: Path, cfg: Path, launcher: list[str] | None = None
) -> tuple[DaemonProcess, float, socket.socket]:
    """``emlogd run`` (or ``launcher`` + ``run ...``) through :mod:`emlogd.launch`, its log
    in ``work/daemon.log``, until READY=1 on its notify socket; the seconds it took."""
    notify = work / "notify.sock"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind(str(notify))
    srv.settimeout(0.2)  # short waits, so a daemon that exits is noticed at once
    t0 = time.perf_counter()
    daemon = DaemonProcess(
        cfg,
        socket="run/control.sock",
        log="daemon.log",
        cwd=work,
        argv=[*launcher, "run", "--config", str(cfg)] if launcher else None,
        env={"NOTIFY_SOCKET": str(notify)},
        wait=False,  # READY=1 is what is timed; it comes before the socket answers
    )
    while True:
        try:
            if srv.recv(4096) == b"READY=1":
                return daemon, time.perf_counter() - t0, srv
        except TimeoutError:
            pass
        if not daemon.running or time.perf_counter() - t0 > READY_TIMEOUT_S:
            daemon.stop()
            srv.close()
            why = "exited" if not daemon.running else f"no READY=1 in {READY_TIMEOUT_S:.0f} s"
            raise SystemExit(f"bench_daemon: the daemon {why}:\n{daemon.tail()}")


def _stop(daemon: DaemonProcess, srv: socket.socket) -> None:
    """SIGTERM the daemon and wait for it; close the notify socket."""
    daemon.stop()
    srv.close()


def _open_reader(path: Path) -> int:
    deadline = time.monotonic() + 10
    while not path.exists():
        if time.monotonic() > deadline:
            raise RuntimeError(f"{path} never appeared")
        time.sleep(0.01)
    return os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)


def _measure(
    targets: list[tuple[VirtualPort, VirtualPort | None, int]], n: int, marker: bytes
) -> list[list[float]]:
    """Write n VHW at 10 Hz to each target in turn (PD6 in between where a DVL port is
    given); time until the next line containing marker on its output. Alternating
    sentence by sentence, every target sees the same moments of this drifting VM."""
    lats: list[list[float]] = [[] for _ in targets]
    bufs = [b""] * len(targets)
    for k in range(n):
        for i, (inp, dvl, out_fd) in enumerate(targets):
            if dvl is not None:
                for line in encode_pd6(
                    timestamp=datetime.now(UTC),
                    heading_deg=10.0,
                    bottom_ship_mps=(0.0, 1.5, 0.0),
                    range_m=20,
                ):
                    dvl.write(line.encode() + b"\r\n")
            time.sleep(0.05)
            sentence = encode_vhw(1.0 + (k % 100) * 0.01).encode() + b"\r\n"
            t0 = time.perf_counter()
            inp.write(sentence)
            deadline = t0 + 2.0
            got = False
            while not got and time.perf_counter() < deadline:
                r, _, _ = select.select([out_fd], [], [], 0.5)
                if not r:
                    continue
                bufs[i] += os.read(out_fd, 65536)
                while b"\n" in bufs[i]:
                    reply, _, bufs[i] = bufs[i].partition(b"\n")
                    if marker in reply:
                        lats[i].append(time.perf_counter() - t0)
                        got = True
            time.sleep(0.05)
    return lats


def _pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, int(q * len(s)))]


class _Flood:
    """Full-speed garbage on a port: random bytes, 10 kB lines without newline, and a
    valid sentence every 10 ms."""

    def __init__(self, link: Path) -> None:
        import threading

        self.vp = VirtualPort(link)
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        junk = [os.urandom(4096), b"A" * 10_000, os.urandom(1000) + b"\n"]
        valid = encode_vhw(2.0).encode() + b"\r\n"
        last = 0.0
        k = 0
        while not self.stop.is_set():
            if not self.vp.wait_writable(0.05):
                continue
            self.sent += self.vp.write(junk[k % 3])
            k += 1
            now = time.monotonic()
            if now - last >= 0.01:
                last = now
                self.sent += self.vp.write(valid)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.vp.close()


def bench_latency(n: int, flood: bool = False) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = _setup(work)
        readies = []
        for _ in range(3):
            proc, ready, srv = _start(work, cfg)
            readies.append(ready)
            _stop(proc, srv)
            (work / "notify.sock").unlink()
        print(
            f"start -> READY=1: median {statistics.median(readies):.3f} s over 3 starts "
            f"(target <= 1.5 s)"
        )
        emlog = VirtualPort(work / "links" / "emlog1")
        dvl = VirtualPort(work / "links" / "dvl")
        src = VirtualPort(work / "links" / "fwd-in")
        fwd = subprocess.Popen(
            [
                sys.executable,
                "-c",
                FORWARDER,
                str(work / "links" / "fwd-in"),
                str(work / "fwd-out"),
            ],
            stdout=subprocess.PIPE,
        )
        assert fwd.stdout is not None
        fwd.stdout.readline()
        proc, _, srv = _start(work, cfg)
        flooder = _Flood(work / "links" / "junk") if flood else None
        try:
            time.sleep(1.0)  # the daemon opens the input ptys
            rss0 = _proc_cpu_rss(proc.pid)[1]
            out_fd = _open_reader(work / "out" / "emlog0")
            fwd_fd = _open_reader(work / "fwd-out")
            lat, base = _measure([(emlog, dvl, out_fd), (src, None, fwd_fd)], n, b"VWVHW")
            os.close(out_fd)
            os.close(fwd_fd)
            cpu, rss1 = _proc_cpu_rss(proc.pid)
        finally:
            if flooder is not None:
                flooder.close()
            _stop(proc, srv)
            fwd.kill()
            fwd.wait()
            emlog.close()
            dvl.close()
            src.close()
        if flooder is not None:
            print(
                f"with a garbage flood on a 4th port ({flooder.sent / 2**20:.0f} MiB sent): "
                f"daemon RSS {rss0 / 2**20:.1f} -> {rss1 / 2**20:.1f} MiB, CPU {cpu:.1f} s"
            )
    med, p99 = statistics.median(lat), _pct(lat, 0.99)
    bmed, bp99 = statistics.median(base), _pct(base, 0.99)
    print(f"latency input pty -> corrected VHW on the output pty, {len(lat)} of {n} sentences:")
    print(f"  daemon    median {med * 1e3:.3f} ms  p99 {p99 * 1e3:.3f} ms  (targets 1 ms, 5 ms)")
    print(f"  forwarder median {bmed * 1e3:.3f} ms  p99 {bp99 * 1e3:.3f} ms")
    print(f"  ratio     median {med / bmed:.2f}x  p99 {p99 / bp99:.2f}x  (target <= 2x)")


def _proc_cpu_rss(pid: int) -> tuple[float, int]:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    rss = 0
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            rss = int(line.split()[1]) * 1024
    return cpu, rss


FLOOR = r"""
import os, select, sys, time, tty
rate, seconds = float(sys.argv[1]), float(sys.argv[2])
m, s = os.openpty(); tty.setraw(s); tty.setraw(m)
pid = os.fork()
if pid == 0:  # the writer: one line per wake-up
    t = time.monotonic()
    while True:
        t += 1.0 / rate
        time.sleep(max(0.0, t - time.monotonic()))
        os.write(m, b":BS,+00123,-01234,+00005,A\r\n")
os.set_blocking(s, False)
ep = select.epoll(); ep.register(s, select.EPOLLIN)
def cpu():
    f = open("/proc/self/stat").read().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
c0, t0, n = cpu(), time.monotonic(), 0
while time.monotonic() - t0 < seconds:
    for fd, ev in ep.poll(0.2):
        os.read(fd, 4096); n += 1
w = time.monotonic() - t0
print(f"{n / w:.1f} {100 * (cpu() - c0) / w:.3f}")
os.kill(pid, 9)
"""


def _wakeups(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("voluntary_ctxt_switches:"):
            return int(line.split()[1])
    return 0


def trial_dir(given: str | None) -> Path:
    """``--trial``'s folder (else a temporary one), the simulated trial (seed 1) written
    into it unless its figure-8 is there already."""
    from emlogd.offline.simulate import simulate

    trial = Path(given) if given else Path(tempfile.mkdtemp(prefix="emlogd-trial-"))
    if not (trial / "2-figure8.cap").exists():
        simulate(trial, seed=1)
    return trial


def run_wrapped(trial: Path, seconds: float, launcher: list[str]) -> None:
    """``LAUNCHER run --config CFG`` (a wrapper around the daemon that writes what it
    measured itself) for ``seconds`` after READY=1, on the three fake devices replaying
    the trial's figure-8 at real speed: the live rates of :func:`bench_live`."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = _setup(work)
        capture = trial / "2-figure8.cap"
        with fake_sensors(capture, work / "links", ("emlog1", "emlog2", "dvl"), speed=1.0):
            proc, _, srv = _start(work, cfg, launcher)
            try:
                time.sleep(seconds)
            finally:
                _stop(proc, srv)


def bench_live(trial: Path, seconds: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = _setup(work)
        capture = trial / "2-figure8.cap"
        with fake_sensors(capture, work / "links", ("emlog1", "emlog2", "dvl"), speed=1.0):
            proc, _, srv = _start(work, cfg)
            try:
                time.sleep(5.0)  # warm up: ports open, imports done
                cpu0, _ = _proc_cpu_rss(proc.pid)
                wake0 = _wakeups(proc.pid)
                t0 = time.monotonic()
                peak = 0
                while time.monotonic() - t0 < seconds:
                    time.sleep(1.0)
                    peak = max(peak, _proc_cpu_rss(proc.pid)[1])
                cpu1, rss = _proc_cpu_rss(proc.pid)
                wall = time.monotonic() - t0
                wakes = (_wakeups(proc.pid) - wake0) / wall
            finally:
                _stop(proc, srv)
    print(f"live rates for {wall:.0f} s (1 Hz VHW + 10 Hz VBW + 5 Hz VHW + 10 Hz PD6):")
    print(f"  CPU {100 * (cpu1 - cpu0) / wall:.2f} % of one core (target <= 1 %)")
    floor = subprocess.run(
        [sys.executable, "-c", FLOOR, f"{wakes:.1f}", "30"],
        check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    print(
        f"  {wakes:.1f} wake-ups/s; a bare Python epoll loop reading a pty at "
        f"{float(floor[0]):.1f} wake-ups/s costs {float(floor[1]):.2f} % (the floor)"
    )
    print(f"  RSS {rss / 2**20:.1f} MiB, peak {peak / 2**20:.1f} MiB (target <= 80 MiB)")


GROWTH = r"""
import resource, sys
from pathlib import Path
from drivers.io.capture import CaptureReader
from emlogd.config import load_config
from emlogd.pipeline.core import Pipeline
from emlogd.settings import pipeline_from_config
def rss():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
cfg = load_config(sys.argv[2])
p = Pipeline(*pipeline_from_config(cfg))
files = sorted(Path(sys.argv[1]).glob("[1-5]-*.cap"))
span = 0.0
t_last = 0.0
hour = None
offset = 0.0
n = 0
while span < 24 * 3600:
    first = None
    for f in files:
        for r in CaptureReader(f):
            t = r.t + offset
            if first is None:
                first = t
            p.feed(t, r.port, r.data)
            n += 1
            if n % 2000 == 0:
                p.tick(t)
            t_last = t
    span += t_last - first
    offset = t_last + 1.0 - (first - offset)
    if hour is None:
        hour = rss()
print(f"{n} {span} {hour} {rss()}")
"""


def bench_growth(trial: Path) -> None:
    root = Path(__file__).resolve().parents[1]
    code = GROWTH.replace(
        "    offset = t_last + 1.0 - files and (t_last + 1.0 - (first - offset)) or 0.0",
        "    offset = t_last + 1.0 - (first - offset)",
    )
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-c", code, str(trial), str(root / "examples" / "emlogd.yaml")],
        capture_output=True, text=True, check=True, cwd=root,
    )  # fmt: skip
    n, span, first, last = r.stdout.split()
    print(
        f"24 simulated hours through the pipeline: {int(n)} records, {float(span) / 3600:.1f} h "
        f"in {time.perf_counter() - t0:.0f} s"
    )
    print(
        f"  RSS after the first pass {int(first) / 2**20:.1f} MiB, at the end {int(last) / 2**20:.1f} MiB, "
        f"growth {(int(last) - int(first)) / 2**20:+.2f} MiB (target <= 1 MiB)"
    )


def main() -> None:
    """Run the daemon benchmarks and print figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--live-seconds", type=float, default=60.0)
    ap.add_argument("--trial", help="directory with the simulated trial (default: simulate one)")
    ap.add_argument("--sentences", type=int, default=300)
    ap.add_argument("--skip", nargs="*", default=[], choices=["latency", "live", "growth"])
    ap.add_argument(
        "--flood", action="store_true", help="latency with a garbage flood on a 4th port"
    )
    ap.add_argument(
        "--rest-s",
        type=float,
        help="rest_s of the reference and aux ports (0: read as soon as readable)",
    )
    args = ap.parse_args()
    global REST_S
    REST_S = args.rest_s
    trial = Path(args.trial) if args.trial else None
    if trial is None or len(list(trial.glob("[1-5]-*.cap"))) != 5:
        from emlogd.offline.simulate import simulate

        trial = Path(tempfile.mkdtemp(prefix="emlogd-trial-"))
        simulate(trial, seed=1)
    if "latency" not in args.skip:
        bench_latency(args.sentences, args.flood)
    if "live" not in args.skip:
        bench_live(trial, args.live_seconds)
    if "growth" not in args.skip:
        bench_growth(trial)


if __name__ == "__main__":
    main()
