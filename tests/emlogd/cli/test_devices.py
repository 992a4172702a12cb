"""dump, record and fake through main(argv): outputs, JSON keys, round trips."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from emlogd.cli import main

CONFORMANCE = Path(__file__).resolve().parents[3] / ".." / "shared" / "conformance"


def test_dump_json_summary(
    capsys: pytest.CaptureFixture[str], trial_files: dict[str, Path]
) -> None:
    """dump --json prints one {t, port, record} object per record and ends with a summary per port
    (protocol, record count)."""
    assert main(["dump", str(trial_files["straight"]), "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    first = json.loads(lines[0])
    assert set(first) == {"t", "port", "record"} and "type" in first["record"]
    summary = json.loads(lines[-1])["summary"]
    assert set(summary) == {"emlog1", "emlog2", "dvl", "gnss"}
    assert summary["dvl"]["protocol"] == "pd6" and summary["dvl"]["records"] > 0


@pytest.mark.parametrize(
    "name",
    [
        "nmea/gpsd_bundg_zeus_9.log",
        "nmea/signalk_gofree-merrimac.log",
        "nmea/signalk_plaka_first15000lines.log",
        "nmea/vdrplayer_Hakefjord.txt",
        "nmea/gpsd_humminbird-M37.log",
        "dvl/pd0/ooi_adcp_auv_51.pd0",
        "dvl/pd0/ooi_LB180210_3_corrupted.PD0",
        "dvl/ascii/trdi_pathfinder_guide_pd13_example.txt",
        "dvl/ascii/rowe_rti_unittest_prti_sentences.txt",
    ],
)
def test_dump_every_conformance_file(capsys: pytest.CaptureFixture[str], name: str) -> None:
    """dump exits 0 on every public conformance file and its summary row names the file with at
    least one decoded record."""
    path = CONFORMANCE / name
    if not path.exists():
        pytest.skip("../shared/conformance is not present")
    args = ["dump", str(path)]
    if "prti" in name:
        args += ["--checksum-optional"]
    assert main(args) == 0
    header, row = capsys.readouterr().out.splitlines()[-2:]
    assert header.split()[:4] == ["port", "protocol", "records", "rejected"]
    port, _protocol, records = row.split()[:3]
    assert port == path.stem and int(records) > 0, row


def test_fake_then_record_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`emlogd fake` (a subprocess) serves a capture; `emlogd record` captures it back."""
    import subprocess
    import sys
    import time

    from drivers.io.capture import CaptureReader, CaptureWriter

    src = tmp_path / "src.cap"
    lines = [b"$VWVHW,,T,,M,%d.00,N,,K*00" % k for k in range(50)]
    with CaptureWriter(src, {"emlog1": "nmea0183"}) as w:
        for k, line in enumerate(lines):
            w.write_line(1000.0 + k * 0.01, "emlog1", line)
    link = tmp_path / "links" / "emlog1"
    fake = subprocess.Popen(
        [sys.executable, "-m", "emlogd", "fake", str(src), "--link", str(link), "--speed", "5"],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 20
        while not link.exists():
            assert time.monotonic() < deadline and fake.poll() is None
            time.sleep(0.02)
        out = tmp_path / "rec.cap"
        rc = main(
            ["record", "--port", f"emlog1={link},baud=4800", "--out", str(out), "--duration", "3"]
        )
        assert rc == 0
    finally:
        fake.terminate()
        rc_fake = fake.wait(10)
    assert rc_fake == 0  # SIGTERM ends `emlogd fake` cleanly
    assert "wrote" in capsys.readouterr().err
    got = [r.payload.encode() for r in CaptureReader(out)]
    assert got == lines
    assert CaptureReader(out).ports == {"emlog1": "nmea0183"}


@pytest.mark.parametrize("speed", ["0", "-2", "nan", "x"])
def test_fake_rejects_a_speed_that_is_not_positive(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, speed: str
) -> None:
    """fake --speed 0, -2, nan or a word is a usage error: exit 2, one line, no traceback."""
    assert main(["fake", "any.cap", "--link", str(tmp_path / "l"), "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--speed" in err and "Traceback" not in err
    assert not (tmp_path / "l").exists()


def test_record_missing_device_is_one_line_exit_1(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """record on a device that does not exist fails at once (exit 1, one line) and writes no file."""
    out = tmp_path / "rec.cap"
    missing = tmp_path / "ttyNOPE"
    assert main(["record", "--port", f"emlog1={missing}", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("emlogd record: error: port emlog1:")
    assert str(missing) in err and not out.exists()


def test_fake_ports_of_one_capture_keep_their_offsets(tmp_path: Path) -> None:
    """`emlogd fake` serving two ports (looping) and `emlogd record` capturing them back keep
    every record's offset from the capture (one clock for both ports, the loop included)
    within 45 ms, under half the 0.1 s between records, so a record one slot off fails and
    a loaded machine's scheduling does not; the second port starts 0.55 s after the first."""
    import statistics
    import subprocess
    import sys
    import time

    from drivers.io.capture import CaptureReader, CaptureWriter

    src = tmp_path / "src.cap"
    rows = [(1000.0 + 0.1 * k, "emlog1", b"$VWVHW,,T,,M,%d.00,N,,K*00" % k) for k in range(12)]
    rows += [(1000.55 + 0.2 * k, "emlog2", b"$VMVHW,,T,,M,%d.00,N,,K*00" % k) for k in range(4)]
    rows.sort()
    with CaptureWriter(src, {"emlog1": "nmea0183", "emlog2": "nmea0183"}) as w:
        for t, port, line in rows:
            w.write_line(t, port, line)
    span = rows[-1][0] - rows[0][0]
    period = span + span / (len(rows) - 1)  # the loop starts one mean interval after the end
    links = {p: tmp_path / "links" / p for p in ("emlog1", "emlog2")}
    fake = subprocess.Popen(
        [sys.executable, "-m", "emlogd", "fake", str(src), "--loop"]
        + [f"--link={p}={link}" for p, link in links.items()],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 20
        while not all(link.exists() for link in links.values()):
            assert time.monotonic() < deadline and fake.poll() is None
            time.sleep(0.02)
        out = tmp_path / "rec.cap"
        argv = ["record", "--out", str(out), "--duration", str(2.5 * period)]
        argv += [f"--port={p}={link},baud=38400" for p, link in links.items()]
        assert main(argv) == 0
    finally:
        fake.terminate()
        fake.wait(10)
    got = [(r.t, r.port, r.payload) for r in CaptureReader(out)]
    expected = {
        (port, line.decode()): [t - rows[0][0] + k * period for k in range(3)]
        for t, port, line in rows
    }
    # each received record against its time in the capture (pass by pass), up to one shift
    errors: list[float] = []
    seen: dict[tuple[str, str], int] = {}
    for t, port, payload in got:
        k = seen.get((port, payload), 0)
        seen[(port, payload)] = k + 1
        errors.append(t - expected[(port, payload)][k])
    assert min(seen.values()) >= 2, seen  # two whole passes at least, both ports
    shift = statistics.median(errors)
    worst = max(abs(e - shift) for e in errors)
    assert worst <= 0.045, (worst, errors)


def _raw_files(tmp_path: Path) -> dict[str, Path]:
    """A raw file of each format dump tells apart, written by the decoders' encoders."""
    from datetime import UTC, datetime

    from drivers.nmea0183 import encode_vhw
    from drivers.rdi_ascii import encode_pd6
    from drivers.rdi_pd0 import encode_pd0
    from drivers.rdi_pd45 import encode_pd45

    t = datetime(2026, 3, 1, 12, tzinfo=UTC)
    pd6 = encode_pd6(timestamp=t, heading_deg=10.0, bottom_ship_mps=(0.1, 2.0, 0.0), range_m=9.0)
    contents = {
        "pd0": encode_pd0(ensemble_number=1, timestamp=t, heading_deg=10.0) * 3,
        "pd4": encode_pd45(bottom_ship_mps=(2.0, 0.1), range_m=9.0) * 3,
        "pd6": "".join(line + "\r\n" for line in pd6).encode(),
        "nmea0183": (encode_vhw(2.0) + "\r\n").encode() * 3,
    }
    for name, data in contents.items():
        (tmp_path / name).write_bytes(data)
    return {name: tmp_path / name for name in contents}


def test_dump_tells_the_protocol_of_a_raw_file_by_its_first_bytes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --protocol, dump reads a raw file as the protocol its first bytes name (the
    binary formats by their decoders' headers) and decodes its records."""
    for protocol, path in _raw_files(tmp_path).items():
        assert main(["dump", str(path)]) == 0
        row = capsys.readouterr().out.splitlines()[-1].split()
        assert row[:2] == [path.stem, protocol] and int(row[2]) > 0, (protocol, row)
