"""PD6/PD13 line parsing: the pattern path reads every line as the field-by-field checks do."""

from __future__ import annotations

import pytest

from drivers.errors import FrameError
from drivers.rdi_ascii import parse as rdi_ascii

# Every line type, as a good line and with each field in turn replaced by each value
# of a list of good ones (some out of range), bad ones and other types' ones, and with a
# field too many or too few.
_GOOD_LINES = {
    "SA": "+00.00,+00.00,219.27",
    "TS": "25061210100009,35.0,+15.0,0000.0,1500.0,000",
    "TS7": "25061210100009,35.0,+15.0,0000.0,1500.0,000,O",
    "RA": "+0020.5,0712,0713,0714,0715",
    "WI": "+00172,+00958,+00000,+00000,A",
    "BI": "+00172,+00958,+00000,-32768,A",
    "WS": "+00172,+00958,+00000,A",
    "WE": "-00740,-00633,+00000,A",
    "BS": "+00172,+00958,+00000,A",
    "BE": "-00740,-00633,+00000,A",
    "WD": "+0000000.00,+0000000.00,+0000000.00,0033.66,000.00",
    "BD": "+0000012.50,-0000003.25,+0000000.00,0033.66,000.00",
}
_VALUES = [
    *("+00.00", "219.27", " 35.0", "-12.5", "0", ".5", "5.", "1500.0", "95.0", "-200.0"),
    *("+00172", "-00740", "-32768", "32767", "  12", "000", "-32769", "32768"),
    *("25061210100009", " 25061210100009 ", "A", "V", " A", "V ", "O", "W", " X "),
    *("", " ", "1e3", "1_0", "nan", "1 ", "+", "-", "X", "2506121010000", "A1"),
]


def _variants() -> list[bytes]:
    lines = []
    for name, good in _GOOD_LINES.items():
        base = good.split(",")
        shapes = [base, base[:-1], [*base, base[-1]]]
        for i in range(len(base)):
            shapes += [[*base[:i], v, *base[i + 1 :]] for v in _VALUES]
        lines += [f":{name[:2]},{','.join(fields)}".encode("ascii") for fields in shapes]
    return lines


def test_pattern_path_reads_every_line_as_the_field_checks_do() -> None:
    """A line read by its type's pattern gives the value, or the error, that the
    field-by-field checks give for it."""

    def outcome(parse: object, frame: bytes) -> object:
        assert callable(parse)
        try:
            return parse(frame)
        except FrameError as exc:
            return type(exc), str(exc)

    for name, good in _GOOD_LINES.items():  # the lines the variants are made from are good
        rdi_ascii._parse_fields(f":{name[:2]},{good}".encode("ascii"))
    lines = _variants()
    assert len(lines) > 1500
    for frame in lines:
        assert outcome(rdi_ascii._parse_line, frame) == outcome(rdi_ascii._parse_fields, frame), (
            frame
        )


def test_the_pattern_path_reads_the_good_lines() -> None:
    """Each line type's good line is read by its pattern, not by the field checks."""

    read = {name[:2] for name, good in _GOOD_LINES.items() if rdi_ascii._LINES[name[:2]][0](good)}
    assert read == set(rdi_ascii._LINES)


def test_the_pattern_path_takes_only_a_real_date_and_time() -> None:
    """A :TS time naming no real month, day, hour, minute or second is refused as out of range
    on the pattern path as by the field checks; each real one is read alike by both."""
    from drivers.errors import OutOfRangeError

    impossible = ["25001208000008", "25131208000008", "25060008000008", "25063208000008"]
    impossible += ["25061224000008", "25061208600008", "25061208006008"]
    real = ["25010100000000", "25123123595999", "99063019303099", "00091505050505"]
    for stamp in impossible + real:
        frame = f":TS,{stamp},35.0,+15.0,0000.0,1500.0,000".encode("ascii")
        if stamp in impossible:
            with pytest.raises(OutOfRangeError, match="no date and time"):
                rdi_ascii._parse_line(frame)
        else:
            assert rdi_ascii._parse_line(frame) == rdi_ascii._parse_fields(frame)
