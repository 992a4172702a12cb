"""The Decoder contract: error policies, counters, queued frames, options."""

from __future__ import annotations

from collections.abc import Iterable

import pytest

from drivers.base import Decoder, DecoderOptions
from drivers.errors import FieldError, FrameError
from drivers.framing import LineFramer
from drivers.records import Rejected


class _Digits(Decoder):
    """A toy line protocol: ``#<digits>`` lines decode to ints; anything else is bad."""

    protocol = "digits"
    binary = False

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._framer = LineFramer(b"#", 82)

    def _split(self, data: bytes) -> Iterable[bytes | FrameError]:
        return list(self._framer.feed(data))

    def _flush(self) -> Iterable[bytes | FrameError]:
        return list(self._framer.flush())

    def parse_frame(self, frame: bytes) -> object:
        if not frame[1:].isdigit():
            raise FieldError("not digits", frame)
        return int(frame[1:])


class TestErrorPolicies:
    """raise / yield / skip, and the counters under each."""

    STREAM = b"#1\n#x\n#2\ngarbage\n#3\n"

    def test_skip_counts_and_drops(self) -> None:
        """errors='skip' yields only good records and counts every reject by reason."""
        dec = _Digits("p", errors="skip")
        assert dec.decode_all(self.STREAM) == [1, 2, 3]
        assert dec.counters.records == 3
        assert dec.counters.rejects["bad_field"] == 1
        assert dec.counters.rejects["framing"] == 1

    def test_yield_reports_rejects_in_order(self) -> None:
        """errors='yield' yields a Rejected record in place of each bad frame."""
        out = _Digits("p", errors="yield").decode_all(self.STREAM)
        assert [type(o).__name__ for o in out] == ["int", "Rejected", "int", "Rejected", "int"]
        rej = out[1]
        assert isinstance(rej, Rejected)
        assert (rej.port, rej.reason, rej.raw) == ("p", "bad_field", b"#x")

    def test_raise_keeps_the_rest_of_the_chunk(self) -> None:
        """errors='raise' raises, and the frames after the bad one come out on the next call."""
        dec = _Digits("p")
        got: list[object] = []
        with pytest.raises(FieldError):
            got.extend(dec.feed(self.STREAM))
        with pytest.raises(FrameError):
            got.extend(dec.feed(b""))
        got.extend(dec.feed(b""))
        assert got == [1, 2, 3]
        assert dec.counters.rejected == 2

    def test_flush_reports_unterminated_line(self) -> None:
        """An unterminated line at end of stream is a counted framing reject."""
        dec = _Digits("p", errors="skip")
        assert dec.decode_all(b"#1\n#2") == [1]
        assert dec.counters.rejects["framing"] == 1

    def test_bad_policy_rejected(self) -> None:
        """An unknown error policy is a ValueError."""
        with pytest.raises(ValueError, match="errors"):
            _Digits("p", errors="ignore")  # type: ignore[arg-type]


class TestOptions:
    """DecoderOptions validation."""

    def test_defaults_are_strict_nmea(self) -> None:
        """Checksums are required and the NMEA length limit applies by default."""
        opts = DecoderOptions()
        assert (opts.checksum, opts.max_length) == ("required", 82)

    @pytest.mark.parametrize(
        "kwargs", [{"checksum": "maybe"}, {"max_length": 4}, {"max_length": 100_000}]
    )
    def test_bad_values_raise(self, kwargs: dict[str, object]) -> None:
        """Out-of-range options raise ValueError naming the option."""
        with pytest.raises(ValueError, match=next(iter(kwargs))):
            DecoderOptions(**kwargs)  # type: ignore[arg-type]
