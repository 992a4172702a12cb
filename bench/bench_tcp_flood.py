"""Benchmark: what clients sending data to the daemon's TCP output port cost it.

Starts ``emlogd run`` (the tree on ``PYTHONPATH``) with a TCP output and no sensors
(its ports retry in the background), then for ``--seconds`` two client threads send
64 KiB blocks to the output port as fast as the sockets take them, in one of three
modes: ``once`` (each client connects once and keeps sending; the daemon's answer
is its business), ``reconnect`` (a client that is closed connects again at once and
sends on) and ``connect`` (connect and close in a loop, sending nothing: a plain
connect loop, for comparison). Prints the daemon's CPU (user + system, in cores)
over that time, what the clients got into their sockets, their connections, and
the output's status counters.

Run: ``PYTHONPATH=. python bench/bench_tcp_flood.py [--mode once|reconnect|connect]
[--seconds 10]``
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
import threading
import time
from pathlib import Path

from emlogd.launch import DaemonProcess
from tests.emlogd.daemon.harness import PD0_CONFIG, make_work, tcp_port

CONFIG = PD0_CONFIG.replace("outputs: {pty: out/emlog0}", 'outputs: {tcp: "127.0.0.1:{tcp}"}')
"""The tests' EMlog and PD0 DVL, never served (their ports retry), and a TCP output."""

CLIENTS = 2
"""Flooding clients (threads)."""

BLOCK = 64 * 1024
"""Bytes per send."""


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _client(port: int, mode: str, until: float, sent: list[int], conns: list[int]) -> None:
    block = b"x" * BLOCK
    while time.monotonic() < until:
        if mode == "once" and conns[0]:
            time.sleep(0.05)
            continue
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
                conns[0] += 1
                while mode != "connect" and time.monotonic() < until:
                    sent[0] += s.send(block)
        except OSError:
            pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mode", choices=("once", "reconnect", "connect"), default="once")
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = make_work(Path(tmp), CONFIG)
        port = tcp_port(work)
        daemon = DaemonProcess("emlogd.yaml", socket="run/control.sock", log="log", cwd=work)
        try:
            sent = [[0] for _ in range(CLIENTS)]
            conns = [[0] for _ in range(CLIENTS)]
            until = time.monotonic() + args.seconds
            threads = [
                threading.Thread(target=_client, args=(port, args.mode, until, sent[i], conns[i]))
                for i in range(CLIENTS)
            ]
            cpu0, t0 = _cpu_s(daemon.pid), time.monotonic()
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            cpu1, t1 = _cpu_s(daemon.pid), time.monotonic()
            status = daemon.ask(cmd="status")["outputs"]
            assert isinstance(status, dict)
            counters = status[f"tcp:127.0.0.1:{port}"]
        finally:
            daemon.stop()
    elapsed = t1 - t0
    total = sum(s[0] for s in sent)
    print(
        f"mode {args.mode}: daemon CPU {(cpu1 - cpu0) / elapsed:.3f} cores over {elapsed:.1f} s; "
        f"clients sent {total / elapsed / 1e6:.1f} MB/s into their sockets over "
        f"{sum(c[0] for c in conns)} connections"
    )
    print(f"output counters: {counters}")


if __name__ == "__main__":
    main()
