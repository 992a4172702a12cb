"""``emlogd demo``: the real daemon calibrating two EM logs against a DVL, live.

The bundled example (a figure-8 from ``emlogd simulate``, faults included) is
served by three fake serial devices on ptys at ``speed`` times real time; the real
daemon runs as a subprocess against them with a config written to a temporary
directory; the demo reads the corrected NMEA from the daemon's output pty, shows
the calibration converging from the status sentences, and ends with the error of
the emitted speed against the DVL before and after calibration, as the daemon
itself measured it (control socket ``status``), next to what ``emlogd replay`` (the
same pipeline, offline) gives on the same capture, its times compressed as it was served.

The three ports are served by one :class:`~drivers.io.fake.FakeCapture`, on the
capture's one clock, so the daemon receives them with their recorded offsets.

Because the capture is replayed faster than real time, the sensor latencies the
daemon sees shrink by the same factor: the demo config gives the daemon the
simulator's latencies divided by ``speed``.
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import tempfile
import time
from collections.abc import Callable
from importlib.resources import as_file, files
from pathlib import Path
from typing import TextIO

from drivers.errors import EmlogdError
from drivers.framing import split_nmea
from drivers.io.fake import FakeCapture
from emlogd.launch import DaemonProcess, LaunchError, fake_sensors
from emlogd.pipeline.readings import DEFAULT_MAX_RATE_HZ, ReadingLimits

DEMO_CAPTURE = "demo-figure8.cap.gz"
LATENCIES_S = {"emlog1": 3.2, "emlog2": 0.45}
"""The simulator's EMlog latencies (emlogd.offline.simulate)."""

CONFIG = """\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut, baud: 4800}}
  - {{name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut, baud: 38400}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference, baud: 115200, rest_s: 0}}
calibration:
  - {{uut: emlog1, reference: dvl, model: EM3, lag: {lag1}, excitation_half_life_samples: 120,
     current: false, max_reading_accel_mps2: {accel}, max_rate_hz: {rate},
     max_param_std: {{m: 0.05, b: 0.08}}, validation_s: {val}, recheck_s: {recheck}}}
  - {{uut: emlog2, reference: dvl, model: EM3, lag: {lag2}, excitation_half_life_samples: 600,
     talker: VM,
     current: false, max_reading_accel_mps2: {accel}, max_rate_hz: {rate},
     validation_s: {val}, recheck_s: {recheck}}}
outputs: {{pty: out/emlog0, status_sentence_interval_s: 0.5}}
state_file: state/state.yaml
control_socket: run/control.sock
log_format: json
status_log_interval_s: 5
"""


class DemoError(EmlogdError):
    """The demo could not run to its end (the daemon did not start, died or hung)."""


def _status_line(sentence: str) -> tuple[str, str] | None:
    try:
        body = split_nmea(sentence.encode("ascii"), required=True).decode("ascii")
    except Exception:
        return None
    f = body.split(",")
    if len(f) != 12 or not f[0].endswith("S") or not f[0].startswith("P"):
        return None
    state = {"L": "learning", "F": "frozen", "U": "uncalibrated"}.get(f[2], f[2])
    params = " ".join(f"{n}={v}" for n, v in (("m", f[5]), ("b", f[6])) if v)
    return f[1], f"{state} {params}".strip()


def _config(speed: float) -> str:
    """The demo's config with its times (lags, validation, recheck) divided by ``speed``,
    and the readings' plausible acceleration and rate scaled to the faster clock (a
    reading's acceleration grows with ``speed²``, its rate with ``speed``)."""
    return CONFIG.format(
        accel=round(ReadingLimits().max_reading_accel_mps2 * speed * speed, 3),
        rate=round(DEFAULT_MAX_RATE_HZ * speed, 3),
        lag1=round(LATENCIES_S["emlog1"] / speed, 4),
        lag2=round(LATENCIES_S["emlog2"] / speed, 4),
        val=round(120.0 / speed, 3),
        recheck=round(300.0 / speed, 2),
    )


def improvement_pct(u: dict[str, object]) -> float | None:
    """``100·(1 − RMSE corrected / RMSE raw)`` of a UUT's status, None without both."""
    e_raw, e_cor = u.get("rmse_raw"), u.get("rmse_corrected")
    if isinstance(e_raw, float) and isinstance(e_cor, float) and e_raw > 0:
        return 100.0 * (1.0 - e_cor / e_raw)
    return None


def replay_improvements(capture: Path, work: Path, speed: float = 1.0) -> dict[str, float | None]:
    """The improvement per UUT of ``emlogd replay`` of ``capture`` as the daemon received
    it at ``speed`` times real time: its times compressed by ``speed`` about its first
    record (``work/served.cap``), with the demo's config for that speed. The daemon's own
    time constants (the change detector's baseline, the restored calibration's retry)
    are not scaled with the config; compressed alike, the replay meets them as the
    daemon did."""
    from drivers.io.capture import CaptureReader, CaptureWriter
    from emlogd.config import load_config
    from emlogd.offline.replay import replay
    from emlogd.pipeline.core import Pipeline
    from emlogd.settings import pipeline_from_config

    reader = CaptureReader(capture)
    served = work / "served.cap"
    with CaptureWriter(served, reader.ports) as w:
        t0: float | None = None
        for rec in reader:
            t0 = rec.t if t0 is None else t0
            w.write_chunk(t0 + (rec.t - t0) / speed, rec.port, rec.data)
    cfg = work / "replay.yaml"
    cfg.write_text(_config(speed), encoding="utf-8")
    ports, uuts = pipeline_from_config(load_config(cfg))
    doc = replay(Pipeline(ports, uuts), [served]).to_dict()["uuts"]
    assert isinstance(doc, dict)
    return {name: improvement_pct(u) for name, u in doc.items()}


def run_demo(
    *,
    speed: float = 10.0,
    out: TextIO | None = None,
    live: bool | None = None,
    workdir: str | Path | None = None,
    python: str = sys.executable,
    timeout_s: float = 120.0,
    progress: Callable[[str], None] | None = None,
) -> dict[str, dict[str, object]]:
    """Run the demo; return the daemon's final per-UUT status.

    Each UUT's status gains ``improvement_pct`` (the daemon's, live) and
    ``replay_improvement_pct`` (``emlogd replay`` of the same capture).

    Args:
        speed: replay speed (multiple of real time).
        out: where the text goes (default: ``sys.stdout`` at the time of the call).
        live: redraw a progress line (default: when ``out`` is a terminal).
        workdir: directory for config, ptys, state (default: a temporary one).
        python: the interpreter that runs the daemon subprocess.
        timeout_s: give up after this long.
        progress: called with each live line (tests).

    Raises:
        DemoError: the daemon did not start, died or did not finish in time.
    """
    out = sys.stdout if out is None else out  # looked up now: the caller may have replaced it
    live = out.isatty() if live is None else live
    with tempfile.TemporaryDirectory(prefix="emlogd-demo-") as tmp:
        # absolute: the daemon runs in it, with the config named from outside it
        work = Path(workdir).resolve() if workdir is not None else Path(tmp)
        for sub in ("links", "out", "state", "run"):
            (work / sub).mkdir(parents=True, exist_ok=True)
        cfg = work / "emlogd.yaml"
        cfg.write_text(_config(speed), encoding="utf-8")
        with as_file(files("emlogd") / "data" / DEMO_CAPTURE) as capture:
            return _run(
                work,
                cfg,
                Path(capture),
                speed,
                out,
                live,
                python,
                timeout_s,
                progress,
                workdir is None,
            )


def _run(
    work: Path,
    cfg: Path,
    capture: Path,
    speed: float,
    out: TextIO,
    live: bool,
    python: str,
    timeout_s: float,
    progress: Callable[[str], None] | None,
    keep_note: bool,
) -> dict[str, dict[str, object]]:
    ports = ("emlog1", "emlog2", "dvl")
    span = _span(capture)
    out.write(
        "emlogd demo: the daemon calibrating two EM logs against a DVL, live\n"
        f"  capture  {capture.name}: a simulated figure-8 ({span / 60:.1f} min, sensor faults "
        f"included) served at {speed:g}x by 3 fake serial devices on ptys, on one clock\n"
    )
    with fake_sensors(capture, work / "links", ports, speed=speed) as device:
        try:
            daemon = DaemonProcess(
                cfg, socket="run/control.sock", log="daemon.log", cwd=work, python=python
            )
        except LaunchError as exc:
            raise DemoError(str(exc)) from None
        with daemon:
            out.write(f"  daemon   emlogd run --config {cfg} (pid {daemon.pid})\n")
            out.write(f"  output   corrected NMEA on {work / 'out' / 'emlog0'}\n\n")
            out.flush()
            counts, final = _watch(work, daemon, device, out, live, timeout_s, progress)
    rc = daemon.returncode
    if live:
        out.write("\r\x1b[K")
    st = final.get("status", {})
    uuts: dict[str, dict[str, object]] = st.get("uuts", {}) if isinstance(st, dict) else {}
    out.write(
        f"read from the output pty: {counts['VHW']} corrected VHW, {counts['VBW']} corrected VBW, "
        f"{counts['status']} status sentences (daemon exit code {rc})\n\n"
    )
    replayed = replay_improvements(capture, work, speed)
    out.write(
        "error of the emitted speed against the DVL bottom track (where both valid), and the\n"
        "improvement emlogd replay (the same pipeline, offline, on the capture as served) gives:\n"
    )
    for name, u in sorted(uuts.items()):
        params = u.get("params") or {}
        assert isinstance(params, dict)
        ptxt = ", ".join(f"{k}={v:+.4f}" for k, v in params.items())
        gain, gain_replay = improvement_pct(u), replayed.get(name)
        u["improvement_pct"], u["replay_improvement_pct"] = gain, gain_replay
        if gain is not None:
            e_raw, e_cor = u["rmse_raw"], u["rmse_corrected"]
            assert isinstance(e_raw, float) and isinstance(e_cor, float)
            rtxt = "-" if gain_replay is None else f"{gain_replay:.0f} %"
            out.write(
                f"  {name}: raw {e_raw:.3f} m/s -> corrected {e_cor:.3f} m/s "
                f"({gain:.0f} % better; replay {rtxt}), {u.get('model')} {ptxt}\n"
            )
        else:
            out.write(f"  {name}: no calibration yet ({u.get('state')})\n")
    out.write(
        "\nWhat this shows: the daemon learnt each EM log's scale and bias online from the DVL\n"
        "while the capture played, and corrected every reading before learning from it, so\n"
        "the error above is that of the speed an autopilot would have received (one step\n"
        "ahead, calibrating from the start, not of a calibration fitted afterwards). The\n"
        "replay figure is the same pipeline run offline over the same capture, its times\n"
        f"compressed {speed:g}x as it was served: the live figure matches it when the daemon\n"
        "got the data as recorded, over real serial ports.\n"
    )
    state = work / "state" / "state.yaml"
    if state.exists():
        out.write(f"\nfrozen calibration persisted to {state}")
        out.write(" (a temporary directory: keep it with --workdir DIR)\n" if keep_note else "\n")
    else:
        out.write(f"\nno calibration persisted (no {state}; see {work / 'daemon.log'})\n")
    return uuts


def _watch(
    work: Path,
    daemon: DaemonProcess,
    device: FakeCapture,
    out: TextIO,
    live: bool,
    timeout_s: float,
    progress: Callable[[str], None] | None,
) -> tuple[dict[str, int], dict[str, object]]:
    """Read the daemon's output pty until the capture has been served; the counts of
    sentences read and the daemon's final answer to a status request."""
    status: dict[str, str] = {}
    counts = {"VHW": 0, "VBW": 0, "status": 0}
    t0 = time.monotonic()
    last_draw = 0.0
    buf = b""
    # the control socket answers: the daemon's outputs are open
    fd = os.open(work / "out" / "emlog0", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        while time.monotonic() - t0 < timeout_s:
            if not daemon.running:
                raise DemoError(
                    f"the daemon exited with {daemon.returncode}; see {daemon.log_path}"
                )
            ready, _, _ = select.select([fd], [], [], 0.2)
            if ready:
                with contextlib.suppress(BlockingIOError):
                    buf += os.read(fd, 65536)
                *lines, buf = buf.split(b"\n")
                for raw in lines:
                    s = raw.strip().decode("ascii", "replace")
                    if s[3:6] in ("VHW", "VBW"):
                        counts[s[3:6]] += 1
                    parsed = _status_line(s)
                    if parsed is not None:
                        counts["status"] += 1
                        status[parsed[0]] = parsed[1]
            now = time.monotonic()
            if now - last_draw > 0.5 and status:
                last_draw = now
                line = f"[{now - t0:5.1f} s] " + " | ".join(
                    f"{k}: {v}" for k, v in sorted(status.items())
                )
                if progress is not None:
                    progress(line)
                if live:
                    out.write("\r" + line[:150] + "\x1b[K")
                    out.flush()
            if device.finished.is_set():
                time.sleep(0.3)
                break
        else:
            raise DemoError(f"the demo did not finish within {timeout_s:.0f} s")
        return counts, daemon.ask(cmd="status")
    finally:
        os.close(fd)


def _span(capture: Path) -> float:
    from drivers.io.capture import CaptureReader

    first = last = None
    for rec in CaptureReader(capture):
        if first is None:
            first = rec.t
        last = rec.t
    return 0.0 if first is None or last is None else last - first
