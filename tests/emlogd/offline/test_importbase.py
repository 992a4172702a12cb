"""What both imports share: the years a time may name, the capture written under a
temporary name and moved into place only on success, gzip input, the report's plain form."""

from __future__ import annotations

import gzip
import os
import stat
import threading
from datetime import UTC, datetime
from pathlib import Path

import pytest

from emlogd.offline.importbase import (
    SNIFF_BYTES,
    CaptureSink,
    ImportReport,
    open_text,
    sentence_kind,
    within_years,
)


def _t(year: int) -> float:
    return datetime(year, 1, 1, tzinfo=UTC).timestamp()


def test_years() -> None:
    """1980 up to (not including) 2100 are GPS-era times; anything else is a misread time."""
    assert within_years(_t(1980)) and within_years(_t(2099))
    assert not within_years(_t(1979)) and not within_years(_t(2100))


def test_the_capture_appears_only_on_commit(tmp_path: Path) -> None:
    """The sink writes next to the capture's name and moves it there on commit; an abort
    leaves nothing; the report counts what was written, by sentence type, and its span."""
    report = ImportReport(["in"], str(tmp_path / "o.cap"), "nmea")
    sink = CaptureSink(tmp_path / "o.cap", "nmea", "test", report)
    sink.write(100.0, "$IIVHW,,T,,M,1.0,N,,K*00")
    sink.write(101.5, "$PRTI01,1*00")
    assert not (tmp_path / "o.cap").exists()
    sink.commit()
    assert (tmp_path / "o.cap").exists() and list(tmp_path.iterdir()) == [tmp_path / "o.cap"]
    d = report.to_dict()
    assert (d["written"], d["sentences"], d["span_s"]) == (2, {"PRTI01": 1, "VHW": 1}, 1.5)
    aborted = CaptureSink(tmp_path / "p.cap", "nmea", "test", ImportReport([], "", "nmea"))
    aborted.write(1.0, "$IIVHW,,T,,M,1.0,N,,K*00")
    aborted.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.cap"]


def test_gzip_input_is_told_by_its_magic(tmp_path: Path) -> None:
    """A file starting with gzip's magic is read through gzip whatever its name."""
    (tmp_path / "a.log").write_bytes(gzip.compress(b"$GPRMC\n"))
    (tmp_path / "b.log").write_bytes(b"$GPVTG\n")
    with open_text(tmp_path / "a.log") as a, open_text(tmp_path / "b.log") as b:
        assert (a.read(), b.read()) == ("$GPRMC\n", "$GPVTG\n")


def test_utf16_and_a_utf8_bom_are_read_as_text(tmp_path: Path) -> None:
    """A spreadsheet's "Unicode text" (UTF-16 with its byte-order mark, either endian)
    and UTF-8 with a byte-order mark read as the plain text."""
    text = "Utc\tBsp\n38516.4\t3.1\n"
    (tmp_path / "le.txt").write_bytes(text.encode("utf-16"))
    (tmp_path / "be.txt").write_bytes(b"\xfe\xff" + text.encode("utf-16-be"))
    (tmp_path / "u8.txt").write_bytes(text.encode("utf-8-sig"))
    for name in ("le.txt", "be.txt", "u8.txt"):
        with open_text(tmp_path / name) as f:
            assert f.read() == text, name


def test_an_export_written_on_windows_is_read_in_its_code_page(tmp_path: Path) -> None:
    """A file whose first bytes are not UTF-8 (``°`` and ``ö`` as single bytes) is read
    in Windows' Western code page; UTF-8 stays UTF-8, even with a character cut at the
    end of the bytes the encoding is told by; a gzip cut short still opens."""
    text = "Utc,Bsp (kt),Hdg (°T),Geschwindigkeit über Grund\n38516.4,3.1,147,3.4\n"
    (tmp_path / "cp.csv").write_bytes(text.encode("cp1252"))
    (tmp_path / "u8.csv").write_bytes(text.encode("utf-8"))
    cut = ("x" * (SNIFF_BYTES - 1) + "°\n").encode("utf-8")  # '°' across the boundary
    (tmp_path / "cut.csv").write_bytes(cut)
    (tmp_path / "gz.csv").write_bytes(gzip.compress(text.encode("cp1252")))
    (tmp_path / "gz-cut.csv").write_bytes(gzip.compress(text.encode("cp1252"))[:-12])
    for name in ("cp.csv", "u8.csv", "gz.csv"):
        with open_text(tmp_path / name) as f:
            assert f.read() == text, name
    with open_text(tmp_path / "cut.csv") as f:
        assert f.read().endswith("°\n")
    with open_text(tmp_path / "gz-cut.csv") as f, pytest.raises(EOFError):
        f.read()  # bounded_lines counts it ``truncated``


def test_sentence_kind() -> None:
    """A sentence's type without its talker; a proprietary one by its address."""
    assert sentence_kind("$IIVHW,1") == "VHW" and sentence_kind("$PRTI01,1") == "PRTI01"


def test_a_fifo_out_is_written_into_never_replaced(tmp_path: Path) -> None:
    """``import --out`` naming a FIFO (as a device, ``/dev/stdout``): the capture is written
    into it, the FIFO stays, no part file is left. The part file was renamed over it."""
    fifo = tmp_path / "o.cap"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    sink = CaptureSink(fifo, "nmea", "test", ImportReport(["in"], str(fifo), "nmea"))
    sink.write(100.0, "$IIVHW,,T,,M,1.0,N,,K*00")
    sink.commit()
    reader.join(5.0)
    assert got and got[0].startswith(b"# emlogd capture v1") and b"$IIVHW" in got[0]
    assert stat.S_ISFIFO(fifo.lstat().st_mode) and list(tmp_path.iterdir()) == [fifo]
