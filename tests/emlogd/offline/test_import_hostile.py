"""Hostile files through both imports: a line far past any sentence or row (a binary dump,
a lost newline), a CSV quote left open. Each is counted and skipped with its reason; the
rows around it are imported, and the long line is never held whole."""

from __future__ import annotations

import gzip
import io
import re
import tracemalloc
from collections import Counter
from pathlib import Path

import pytest

from emlogd.cli import main
from emlogd.offline.importbase import MAX_LINE_CHARS, ImportFormatError, bounded_lines
from emlogd.offline.importer import import_csv, import_nmea
from tests.emlogd.offline.test_importnmea import IRENE

LONG = 8 * 1024 * 1024
"""The long line of these tests, characters (a gigabyte is the same, only slower)."""


def test_bounded_lines_skip_only_what_is_past_the_bound() -> None:
    """Lines up to the bound are given whole, the last one without its newline too; a
    longer one, ended or not, is counted ``too_long`` and the next line given."""
    n = MAX_LINE_CHARS
    text = "a\n" + "b" * (n - 1) + "\n" + "c" * n + "\n" + "d" * (n + 1) + "\nE\n" + "f" * n
    skipped: Counter[str] = Counter()
    got = [(x[0], len(x)) for x in bounded_lines(io.StringIO(text), skipped)]
    assert got == [("a", 2), ("b", n), ("c", n + 1), ("E", 2), ("f", n)]
    assert skipped == {"too_long": 1}
    skipped.clear()
    rest = [x for x in bounded_lines(io.StringIO("g" * 3 * n + "\nh\n" + "i" * 5 * n), skipped)]
    assert rest == ["h\n"] and skipped == {"too_long": 2}


def test_a_csv_with_a_long_line_and_an_open_quote(tmp_path: Path) -> None:
    """8 MiB of one line, then a quote left open over 200 KB of lines, between good rows:
    each skipped with its reason (``too_long``, ``csv_error``) and the good rows written,
    the command ending 0. The CSV reader's field limit ended ``emlogd import`` with an
    internal error, and the line was held whole (430 MB of memory for 200 MB)."""
    rows = [f"2020-01-01T00:00:{s:02d}Z,{5 + s / 100:.2f}\n" for s in range(6)]
    src = tmp_path / "hostile.csv"
    src.write_text(
        "time,stw\n"
        + "".join(rows[:2])
        + "9" * LONG
        + "\n"
        + "".join(rows[2:4])
        + '2020-01-01T00:00:10Z,"5\n'
        + ("x" * 1000 + "\n") * 200
        + "".join(rows[4:])
    )
    tracemalloc.start()
    try:
        rep = import_csv(src, tmp_path / "o.cap", {"time": "time", "stw": "stw"})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rep.skipped["too_long"] == 1 and rep.skipped["csv_error"] == 1, rep.skipped
    assert rep.sentences["VHW"] == 6, rep.sentences
    assert peak < LONG // 4, peak
    assert main(["import", "--format", "csv", "--map", "time=time,stw=stw", "--out",
                 str(tmp_path / "cli.cap"), str(src)]) == 0  # fmt: skip


def test_an_nmea_log_with_a_long_line(tmp_path: Path) -> None:
    """8 MiB of one line inside Irene's excerpt: counted ``too_long``, every sentence
    around it imported as without it."""
    src = tmp_path / "irene.nmea"
    cut = IRENE.index("$IIRMC,132221")
    src.write_text(IRENE[:cut] + "$" * LONG + "\n" + IRENE[cut:])
    rep = import_nmea([src], tmp_path / "o.cap")
    assert rep.skipped["too_long"] == 1, rep.skipped
    assert rep.written == 10 and rep.sentences["RMC"] == 3, rep.sentences


def test_a_gzip_file_cut_short(tmp_path: Path) -> None:
    """A gzip CSV export and a gzip NMEA log cut short: the rows and sentences before the
    cut imported, the cut counted ``truncated``; a file of gzip's magic and garbage is
    one error line naming why. Each ended with ``internal error: EOFError``."""
    rows = "".join(
        f"2020-01-01T00:{s // 60:02d}:{s % 60:02d}Z,{5 + s % 7 / 10:.1f}\n" for s in range(3000)
    )
    whole = gzip.compress(("time,stw\n" + rows).encode())
    csv_gz = tmp_path / "cut.csv.gz"
    csv_gz.write_bytes(whole[: len(whole) // 2])
    rep = import_csv(csv_gz, tmp_path / "c.cap", {"time": "time", "stw": "stw"})
    assert rep.skipped["truncated"] == 1 and 0 < rep.sentences["VHW"] < 3000, rep.skipped
    log = gzip.compress((IRENE * 200).encode())
    nmea_gz = tmp_path / "cut.nmea.gz"
    nmea_gz.write_bytes(log[: len(log) * 3 // 4])
    rep = import_nmea([nmea_gz], tmp_path / "n.cap")
    assert rep.skipped["truncated"] == 1 and rep.written >= 10, rep.skipped
    bad = tmp_path / "bad.nmea.gz"
    bad.write_bytes(b"\x1f\x8b\x08\x00garbage")
    with pytest.raises(ImportFormatError, match="gzip stream cut short or corrupt before its"):
        import_nmea([bad], tmp_path / "b.cap")
    with pytest.raises(ImportFormatError, match=r"empty file \(a gzip stream cut short"):
        import_csv(bad, tmp_path / "b.cap")


@pytest.mark.parametrize(
    ("first", "looks"),
    [
        ("(1436509053.650713) can0 09F80115#A0D4F4C19C400A24", "NMEA 2000 CAN dump"),
        ("  can0  09F80115   [8]  A0 D4 F4 C1 9C 40 0A 24", "NMEA 2000 CAN dump"),
        ("2016-04-09T16:41:39.628Z,2,127250,7,255,8,00,fc,69,ff", "Actisense/canboat"),
        ("1460220099628;A;2016-04-09T16:41:39.628Z,2,127250,7,255,8,00", "--format n2k"),
        ('{"context":"vessels.self","updates":[]}', "Signal K JSON (import it with --format json"),
        (
            '{"timestamp":"2013-08-22-19:11:05.607","prio":"2","pgn":"130306","fields":{}}',
            "canboat analyzer JSON (import it with --format json",
        ),
        ("\x89\x01\x02\x03\xff\xfe\x00\x10binary", "binary data"),
        ("Utc,Bsp,Hdg,Sog", "--format csv"),
    ],
)
def test_a_file_of_another_format_is_named(first: str, looks: str, tmp_path: Path) -> None:
    """An NMEA import of a file none of whose lines is a sentence quotes its first line
    and names what it looks like (NMEA 2000 dumps, Signal K, binary, a table); a CSV
    import of such a file (or of an NMEA log) names it too; an empty file is said so."""
    src = tmp_path / "log.txt"
    src.write_bytes(((first + "\n") * 3).encode("latin-1"))
    with pytest.raises(ImportFormatError, match="no line is an NMEA 0183 sentence") as exc:
        import_nmea([src], tmp_path / "o.cap")
    assert looks in str(exc.value)
    if looks != "--format csv":
        with pytest.raises(
            ImportFormatError, match=rf"no header: the file looks like .*{re.escape(looks)}"
        ):
            import_csv(src, tmp_path / "o.cap")
    src.write_text("$IIVHW,,,263,M,01.0,N,,*62\n")
    with pytest.raises(ImportFormatError, match=r"an NMEA 0183 log .*--format nmea"):
        import_csv(src, tmp_path / "o.cap")
    src.write_bytes(b"")
    with pytest.raises(ImportFormatError, match="empty"):
        import_nmea([src], tmp_path / "o.cap")


def test_a_csv_of_one_huge_line_is_not_called_empty(tmp_path: Path) -> None:
    """A file whose only line is past :data:`MAX_LINE_CHARS` (a lost line ending): the CSV
    import says its line is too long for a row, not that the file is empty."""
    src = tmp_path / "one.csv"
    src.write_text("Utc,Bsp," + "1" * (2 * MAX_LINE_CHARS) + "\n")
    with pytest.raises(
        ImportFormatError, match=rf"no header: its 1 line\(s\) each over {MAX_LINE_CHARS}"
    ):
        import_csv(src, tmp_path / "o.cap")
