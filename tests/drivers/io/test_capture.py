"""Capture v1: exact round trip, malformed files named by file:line, streaming, gzip."""

from __future__ import annotations

import gzip
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.errors import CaptureFormatError
from drivers.io.capture import (
    MAGIC,
    MAX_LINE_BYTES,
    STEP_RECORDS,
    CaptureReader,
    CaptureWriter,
    capture_name,
    read_ports,
)
from tests.profiles import by_profile


def test_round_trip_text_and_binary(tmp_path: Path) -> None:
    """Text lines, binary chunks, NUL bytes and hex:-looking lines read back exactly, with the port
    headers, the comment and each record's line number, and a reader iterates twice."""
    path = tmp_path / "a.cap"
    with CaptureWriter(path, {"emlog1": "nmea0183", "dvl": "pd0"}) as w:
        w.comment("a test capture")
        w.write_line(1.0, "emlog1", b"$VWVHW,,T,,M,3.50,N,6.48,K*6A")
        w.write_chunk(1.05, "dvl", b"\x7f\x7f\x00\xff")
        w.write_line(1.1, "emlog1", b"bad\x00bytes")
        w.write_line(1.1, "emlog1", b"hex:looks like hex")
    text = path.read_text()
    assert text.startswith(MAGIC + "\n# port emlog1 nmea0183\n# port dvl pd0\n# a test capture\n")
    assert "(1.000000) emlog1 $VWVHW" in text
    r = CaptureReader(path)
    assert r.ports == {"emlog1": "nmea0183", "dvl": "pd0"} == read_ports(path)
    recs = list(r)
    assert [x.data for x in recs] == [
        b"$VWVHW,,T,,M,3.50,N,6.48,K*6A\r\n",
        b"\x7f\x7f\x00\xff",
        b"bad\x00bytes\r\n",
        b"hex:looks like hex\r\n",
    ]
    assert [x.line for x in recs] == [5, 6, 7, 8]
    assert list(r) == recs  # iterating again starts over


lines = st.binary(max_size=120)


@settings(
    max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(items=st.lists(st.tuples(st.booleans(), lines), max_size=30))
def test_any_bytes_round_trip_exactly(tmp_path: Path, items: list[tuple[bool, bytes]]) -> None:
    """Any bytes written as a line (CRLF added) or as a non-empty chunk read back byte for byte."""
    path = tmp_path / "p.cap"
    expected = []
    with CaptureWriter(path, {"p": "nmea0183"}) as w:
        for k, (is_line, data) in enumerate(items):
            if is_line:
                w.write_line(float(k), "p", data)
                expected.append(data + b"\r\n")
            elif data:
                w.write_chunk(float(k), "p", data)
                expected.append(data)
    assert [r.data for r in CaptureReader(path)] == expected


@pytest.mark.parametrize(
    ("content", "line", "message"),
    [
        ("hello\n", 1, "not a capture v1 file"),
        (MAGIC + "\n# port a\n", 2, "port header must be"),
        (MAGIC + "\n# port a nmea0183\n# port a pd0\n", 3, "declared twice"),
        (MAGIC + "\n# port a nmea0183\n(1.0) b $X\n", 3, "unknown port 'b'"),
        (MAGIC + "\n# port a nmea0183\n(x) a $X\n", 3, "bad time"),
        (MAGIC + "\n# port a nmea0183\n(inf) a $X\n", 3, "bad time"),
        (MAGIC + "\n# port a nmea0183\n(2.0) a $X\n(1.0) a $Y\n", 3, "jumps ahead"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a $X\n(1.1) a $Y\n(0.5) a $Z\n", 5, "before"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a hex:abc\n", 3, "even number"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a hex:zz\n", 3, "bad hex"),
        (MAGIC + "\n# port a nmea0183\n(1.0)\n", 3, "must be '(EPOCH.SECONDS) PORT PAYLOAD'"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a \n", 3, "missing payload"),
        (MAGIC + "\n# port a nmea0183\n1.0 a $X\n", 3, "must start with"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a $X\n# port b pd0\n", 4, "after the first record"),
        (MAGIC + "\n# port a nmea0183\n(1.0) a $X\n(2.0) a caf\u00e9\n", 4, "non-ASCII"),
    ],
)
def test_malformed_files_name_file_and_line(
    tmp_path: Path, content: str, line: int, message: str
) -> None:
    """Each kind of malformed capture raises CaptureFormatError starting 'FILE:LINE: ' with its
    reason and line number."""
    path = tmp_path / "bad.cap"
    path.write_bytes(content.encode("utf-8"))
    with pytest.raises(CaptureFormatError) as exc:
        list(CaptureReader(path))
    assert str(exc.value).startswith(f"{path}:{line}: "), str(exc.value)
    assert message in str(exc.value)
    assert exc.value.line == line


def test_writer_refuses_bad_input(tmp_path: Path) -> None:
    """CaptureWriter refuses an unknown protocol, a bad port name, time going backwards, an unknown
    port, a two-line comment and a write after close."""
    with pytest.raises(ValueError, match="unknown protocol"):
        CaptureWriter(tmp_path / "x.cap", {"a": "nmea9"})
    with pytest.raises(ValueError, match="bad port name"):
        CaptureWriter(tmp_path / "x.cap", {"a b": "pd6"})
    with CaptureWriter(tmp_path / "x.cap", {"a": "pd6"}) as w:
        w.write_line(2.0, "a", b":SA")
        with pytest.raises(ValueError, match="backwards"):
            w.write_line(1.0, "a", b":SA")
        with pytest.raises(ValueError, match="unknown port"):
            w.write_line(3.0, "b", b":SA")
        with pytest.raises(ValueError, match="comment"):
            w.comment("two\nlines")
    with pytest.raises(ValueError, match="closed"):
        w.write_line(4.0, "a", b":SA")


def test_gzip_and_streaming(tmp_path: Path) -> None:
    """A gzip capture of 50 000 records streams through the reader to its last record; a .gz file
    that is not gzip is a CaptureFormatError."""
    plain = tmp_path / "big.cap"
    with CaptureWriter(plain, {"a": "nmea0183"}) as w:
        for k in range(50_000):
            w.write_line(k * 0.01, "a", b"$VWVHW,,T,,M,3.50,N,6.48,K*6A")
    gz = tmp_path / "big.cap.gz"
    gz.write_bytes(gzip.compress(plain.read_bytes()))
    n = 0
    for n, rec in enumerate(CaptureReader(gz), start=1):  # noqa: B007
        pass
    assert n == 50_000 and rec.t == pytest.approx(499.99)
    bad = tmp_path / "bad.cap.gz"
    bad.write_bytes(b"not gzip")
    with pytest.raises(CaptureFormatError, match="gzip"):
        CaptureReader(bad)


def _read_any(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "fz.cap"
    path.write_bytes(b"# emlogd capture v1\n# port a nmea0183\n" + content)
    try:
        for rec in CaptureReader(path):
            assert rec.port == "a"
            rec.data  # noqa: B018 - decoding the payload must not raise either
    except CaptureFormatError as exc:
        assert str(exc).startswith(f"{path}:")


@pytest.mark.fuzz
@settings(
    max_examples=by_profile(300),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(st.binary(max_size=400))
def test_reader_only_raises_capture_format_errors(tmp_path: Path, content: bytes) -> None:
    """Random bytes after a valid header give records of the declared port or a CaptureFormatError
    naming the file, never another exception."""
    _read_any(tmp_path, content)


def _long_capture_with_a_bad_byte(path: Path, bad_line: int, total: int) -> list[int]:
    """A capture of ``total`` lines whose line ``bad_line`` holds a non-ASCII byte."""
    lines = [MAGIC.encode(), b"# port a nmea0183"]
    good: list[int] = []
    for n in range(3, total + 1):
        payload = b"$VWVHW,,T,,M,3.50,N,6.48,K*6A"
        if n == bad_line:
            payload = b"$VWVHW,,T,,M,3.\xb50,N,6.48,K*6A"
        else:
            good.append(n)
        lines.append(b"(%.6f) a " % (n * 0.1) + payload)
    data = b"\n".join(lines) + b"\n"
    path.write_bytes(gzip.compress(data) if path.name.endswith(".gz") else data)
    return good


@pytest.mark.parametrize("name", ["long.cap", "long.cap.gz"])
def test_non_ascii_byte_reported_at_its_own_line(tmp_path: Path, name: str) -> None:
    """A non-ASCII byte deep in a file (plain or gzip) is reported at its line, 12299."""
    path = tmp_path / name
    good = _long_capture_with_a_bad_byte(path, 12299, 20_000)
    with pytest.raises(CaptureFormatError) as exc:
        list(CaptureReader(path))
    assert exc.value.line == 12299 and "non-ASCII" in str(exc.value)
    reader = CaptureReader(path, errors="skip")
    assert [r.line for r in reader] == good
    assert reader.skipped == {"non_ascii": 1}
    assert reader.skipped_lines == [(12299, "non-ASCII bytes (payloads must be hex:)")]


def test_skip_mode_counts_every_kind_of_bad_record(tmp_path: Path) -> None:
    """errors="skip" keeps the good records and counts each bad one by reason, with its line."""
    path = tmp_path / "mixed.cap"
    path.write_bytes(
        MAGIC.encode()
        + b"\n# port a nmea0183\n"
        + b"(1.0) a $A\n"  # 3 ok
        + b"(1.1) a \n"  # 4 missing payload
        + b"(x) a $B\n"  # 5 bad time
        + b"(1.2) a caf\xc3\xa9\n"  # 6 non-ASCII
        + b"(1.3) b $C\n"  # 7 unknown port
        + b"(1.4) a hex:zz\n"  # 8 bad hex
        + b"1.5 a $D\n"  # 9 no time
        + b"(0.5) a $E\n"  # 10 backwards
        + b"# port c pd0\n"  # 11 late header
        + b"(2.0) a $F\n"  # 12 ok
    )
    reader = CaptureReader(path, errors="skip")
    assert [(r.line, r.payload) for r in reader] == [(3, "$A"), (12, "$F")]
    assert reader.skipped == {
        "missing_payload": 1,
        "bad_time": 1,
        "non_ascii": 1,
        "unknown_port": 1,
        "bad_hex": 1,
        "bad_record": 1,
        "out_of_order": 1,
        "late_header": 1,
    }
    assert sorted(n for n, _ in reader.skipped_lines) == list(range(4, 12))
    assert reader.skip_report()["skipped"] == 8
    # iterating again starts the counts again
    assert len(list(reader)) == 2 and reader.n_skipped == 8


def test_truncated_gzip(tmp_path: Path) -> None:
    """A gzip capture cut short raises, or in skip mode ends its records and counts it."""
    plain = tmp_path / "p.cap"
    with CaptureWriter(plain, {"a": "nmea0183"}) as w:
        for k in range(20_000):
            w.write_line(k * 0.01, "a", b"$VWVHW,,T,,M,3.50,N,6.48,K*6A")
    whole = gzip.compress(plain.read_bytes())
    cut = tmp_path / "cut.cap.gz"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(CaptureFormatError, match="gzip"):
        list(CaptureReader(cut))
    reader = CaptureReader(cut, errors="skip")
    n = len(list(reader))
    assert 0 < n < 20_000 and reader.skipped == {"truncated": 1}


def test_received_gives_what_iterating_gives(tmp_path: Path) -> None:
    """received() yields each good record's time, port, bytes and line exactly as iterating
    does, for the records the writer writes and for odd but valid ones, and skips the same
    bad ones."""
    path = tmp_path / "odd.cap"
    path.write_bytes(
        MAGIC.encode()
        + b"\n# port a nmea0183\n# port d pd0\n"
        + b"(1.000000) a $A\r\n"  # 4 as written, CR LF
        + b"(1.1) d hex:7f7f00ff\n"  # 5 binary
        + b"(1.2) a  $B with a leading blank\n"  # 6
        + b"(2) a $C\n"  # 7 time without decimals
        + b"(.5) a $D\n"  # 8 backwards, in a form the pattern does not read
        + b"(2.5) a $E\r\r\n"  # 9
        + b"(2.6) a tab\there\n"  # 10 a control character in the payload
        + b"(2.7) d hex:\n"  # 11 empty hex
        + b"(2.8) d hex:7f7\n"  # 12 odd hex
        + b"(2.9) b $F\n"  # 13 unknown port
        + b"(1.0) a $G\n"  # 14 backwards
        + b"# a comment\n"  # 15
        + b"(3.0) a $H"  # 16 no terminator
    )
    reader = CaptureReader(path, errors="skip")
    received = list(reader.received())
    skipped = dict(reader.skipped), list(reader.skipped_lines)
    assert received == [(r.t, r.port, r.data, r.line) for r in reader]
    assert (dict(reader.skipped), list(reader.skipped_lines)) == skipped
    assert received == [
        (1.0, "a", b"$A\r\n", 4),
        (1.1, "d", b"\x7f\x7f\x00\xff", 5),
        (1.2, "a", b" $B with a leading blank\r\n", 6),
        (2.0, "a", b"$C\r\n", 7),
        (2.5, "a", b"$E\r\n", 9),
        (2.6, "a", b"tab\there\r\n", 10),
        (3.0, "a", b"$H\r\n", 16),
    ]
    assert reader.skipped == {"out_of_order": 2, "bad_hex": 2, "unknown_port": 1}
    assert sorted(n for n, _ in reader.skipped_lines) == [8, 11, 12, 13, 14]


T0 = 1748757600.0


def _timed_capture(path: Path, times: list[float]) -> None:
    """A capture whose record k is ``$Kk`` on port a or b (alternately) at ``times[k]``,
    written as the writer writes (six decimals), whatever the order of the times."""
    lines = [MAGIC, "# port a nmea0183", "# port b nmea0183"]
    lines += [f"({t:.6f}) {'ab'[k % 2]} $K{k}" for k, t in enumerate(times)]
    path.write_text("\n".join(lines) + "\n")


def _read(path: Path, **kw: object) -> tuple[list[int], CaptureReader]:
    reader = CaptureReader(path, errors="skip", **kw)  # type: ignore[arg-type]
    return [int(r.payload[2:]) for r in reader], reader


@pytest.mark.parametrize("digit", range(10))
@pytest.mark.parametrize("step", [1, -1])
def test_a_flipped_digit_in_one_time_loses_that_record_only(
    tmp_path: Path, digit: int, step: int
) -> None:
    """One record whose time has a digit of its whole seconds flipped (forward or backward, by
    1 s to 10^9 s; in the middle, near the start and as the first record) is the only record
    skipped, as out_of_order, and every other comes back in order (a first record set back in
    time contradicts nothing and is kept, first)."""
    times = [T0 + 0.1 * k for k in range(600)]
    for bad in (300, 1, 0):
        stamp = f"{times[bad]:.6f}"
        pos = 9 - digit  # the digit worth 10^digit seconds
        flipped = stamp[:pos] + str((int(stamp[pos]) + step) % 10) + stamp[pos + 1 :]
        wrong = list(times)
        wrong[bad] = float(flipped)
        path = tmp_path / f"flip{bad}.cap"
        _timed_capture(path, wrong)
        got, reader = _read(path)
        if bad == 0 and float(flipped) < times[0]:
            assert got == list(range(600)) and reader.n_skipped == 0
            continue
        assert got == [k for k in range(600) if k != bad], (bad, flipped)
        assert reader.skipped == {"out_of_order": 1}


def test_jitter_within_the_window_is_reordered_not_dropped(tmp_path: Path) -> None:
    """±50 ms of uniform jitter on 3000 records 20 ms apart loses nothing: every record comes back,
    sorted by time, and the reordered count says how many moved; with a window of 0 the same file
    skips records as out_of_order."""
    rng = __import__("random").Random(7)
    times = [T0 + 0.02 * k + rng.uniform(-0.05, 0.05) for k in range(3000)]
    path = tmp_path / "jitter.cap"
    _timed_capture(path, times)
    got, reader = _read(path)
    assert sorted(got) == list(range(3000)) and reader.n_skipped == 0
    assert [times[k] for k in got] == sorted(times)
    moved = sum(1 for i, k in enumerate(got) if k != i)
    assert reader.reordered > 0 and reader.skip_report()["reordered"] == reader.reordered
    assert moved >= reader.reordered
    got0, reader0 = _read(path, reorder_window_s=0.0)
    assert reader0.skipped["out_of_order"] > 0 and len(got0) == 3000 - reader0.n_skipped


def test_a_real_pause_is_not_an_outlier(tmp_path: Path) -> None:
    """A forward jump that the records after it follow (the capture paused 600 s) is kept: nothing
    is skipped. A record more than the window back is skipped alone."""
    times = [T0 + 0.1 * k for k in range(50)] + [T0 + 600 + 0.1 * k for k in range(50)]
    times[70] = times[69] - 0.5
    path = tmp_path / "pause.cap"
    _timed_capture(path, times)
    got, reader = _read(path)
    assert got == [k for k in range(100) if k != 70] and reader.skipped == {"out_of_order": 1}


def test_reorder_window_must_be_a_non_negative_number(tmp_path: Path) -> None:
    """A negative or non-finite window is refused."""
    path = tmp_path / "w.cap"
    _timed_capture(path, [T0])
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="reorder_window_s"):
            CaptureReader(path, reorder_window_s=bad)


@pytest.mark.parametrize(
    ("path", "name"),
    [
        ("runs/2-figure8.cap.gz", "2-figure8"),
        ("a.cap", "a"),
        ("b.gz", "b"),
        ("trial.v2.cap", "trial.v2"),
        ("plain", "plain"),
    ],
)
def test_capture_name_drops_the_capture_suffixes(path: str, name: str) -> None:
    """A capture's name is its file name without the folder, ``.cap`` and ``.gz``; other
    dots stay."""
    assert capture_name(path) == name


@pytest.mark.parametrize("where", ["header", "records"])
def test_a_line_of_many_megabytes_is_skipped_unheld(tmp_path: Path, where: str) -> None:
    """24 MiB of one line (a lost newline, a binary dump) among the header's comments or
    between records: skipped as ``too_long`` (a ``CaptureFormatError`` naming its line in
    raise mode), the records around it read, the line never held whole. It was read
    whole, 2.2 bytes of memory per byte of the line, by the header's scan and the reader."""
    path = tmp_path / "long.cap"
    long = b"#" + b"x" * (24 << 20) + b"\n"
    path.write_bytes(
        MAGIC.encode()
        + b"\n# port a nmea0183\n"
        + (long if where == "header" else b"")
        + b"(1.0) a $A\n"
        + (long if where == "records" else b"(1.5) a $B\n")
        + b"(2.0) a $C\n"
    )
    tracemalloc.start()
    try:
        reader = CaptureReader(path, errors="skip")
        got = [r.payload for r in reader]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert reader.ports == {"a": "nmea0183"}
    assert got == (["$A", "$C"] if where == "records" else ["$A", "$B", "$C"])
    assert reader.skipped == {"too_long": 1}
    assert peak < 8 * MAX_LINE_BYTES, peak  # the line: 24 MiB
    with pytest.raises(CaptureFormatError, match=r":[34]: a line longer than"):
        list(CaptureReader(path))


@pytest.mark.parametrize("step_s", [3600.0, 10.0])
def test_a_clock_set_back_shifts_the_records_after_it(tmp_path: Path, step_s: float) -> None:
    """The logger's clock set back an hour (or 10 s) half-way through, the records after
    the step following one another: every record kept, in file order, the ones from the
    step on shifted to follow the ones before it (0.1 s apart as written), the step
    reported with its line; in raise mode the step is an error naming its line. Each
    record after the step was skipped as out_of_order: half the capture."""
    times = [T0 + 0.1 * k for k in range(300)] + [T0 + 30.0 - step_s + 0.1 * k for k in range(300)]
    path = tmp_path / "stepped.cap"
    _timed_capture(path, times)
    got, reader = _read(path)
    assert got == list(range(600)) and reader.n_skipped == 0
    assert [r.t for r in CaptureReader(path, errors="skip")][300] == pytest.approx(times[299])
    [(line, step)] = reader.steps
    assert line == 304 and step == pytest.approx(step_s - 0.1)
    assert reader.skip_report()["steps"] == [{"line": 304, "step_s": step}]
    with pytest.raises(CaptureFormatError, match=r"stepped.cap:304: .* steps back"):
        list(CaptureReader(path))


def test_a_few_records_set_back_are_bad_times(tmp_path: Path) -> None:
    """One short of ``STEP_RECORDS`` records an hour back, then the time before them again:
    each is skipped as out_of_order, no step; so is a run that ends the file."""
    times = [T0 + 0.1 * k for k in range(100)]
    for k in range(50, 50 + STEP_RECORDS - 1):
        times[k] -= 3600.0
    path = tmp_path / "few.cap"
    _timed_capture(path, times)
    got, reader = _read(path)
    bad = set(range(50, 50 + STEP_RECORDS - 1))
    assert got == [k for k in range(100) if k not in bad] and not reader.steps
    assert reader.skipped == {"out_of_order": STEP_RECORDS - 1}
    _timed_capture(path, times[: 50 + STEP_RECORDS - 1])
    got, reader = _read(path)
    assert got == list(range(50)) and reader.skipped == {"out_of_order": STEP_RECORDS - 1}
