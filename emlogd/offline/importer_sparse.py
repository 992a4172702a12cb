"""Expedition's own sparse log, read as the rows of a CSV export.

Expedition (race navigation software) writes its log as channel numbers and values
rather than one cell per column::

    !Boat,Utc,BSP,AWA,...,Set,Drift,HDG,...,Lat,Lon,COG,SOG
    !boat,0,1,2,...,11,12,13,...,48,49,50,51
    !v12.5.1
    0,45859.15310,1,6.81,2,31.35,13,245.1,48,44.3431296,...

The first line names the channels, the second gives each name's channel number (in
the same places after the leading ``!Boat``/``!boat``), further ``!`` lines carry the
version and the like; a data row is the boat's number (0: this boat), the time (the
channel 0 cell) and ``channel,value`` pairs of the channels written then. A header
pair may come again in the file with other channels.

:class:`SparseLog` turns each row into a dense comma-separated line laid out as the
first header's names, so the CSV import reads it with its presets and its rule that
only written cells become samples: a channel absent from a row is an empty cell.
Rows of another boat (``other_boat``) and rows whose pairs cannot be read
(``bad_row``) are counted in the report's ``skipped`` and give no line.
"""

from __future__ import annotations

from collections.abc import Iterator

from emlogd.offline.importbase import ImportReport

NAMES_TAG = "!boat,"
"""A header line's lead, in any case (``!Boat`` names, ``!boat`` numbers)."""

OWN_BOAT = "0"
"""The boat number of the logging boat's own rows."""


def _header_pair(lines: list[str], i: int) -> tuple[list[str], list[int]] | None:
    """(names, channel numbers) of the header pair at ``lines[i]``, or None."""
    if i + 1 >= len(lines):
        return None
    a, b = lines[i].strip(), lines[i + 1].strip()
    if not (a.casefold().startswith(NAMES_TAG) and b.casefold().startswith(NAMES_TAG)):
        return None
    names = [x.strip() for x in a.split(",")[1:]]
    try:
        numbers = [int(x) for x in b.split(",")[1:] if x.strip()]
    except ValueError:
        return None
    if len(numbers) != len(names) or 0 not in numbers:
        return None
    return names, numbers


class SparseLog:
    """One sparse log being read: the dense layout and the channels' places in it.

    Attributes:
        names: the dense header (the first header's names).
        first_row: the index, in the lines it was found in, after its header lines.
    """

    def __init__(self, names: list[str], numbers: list[int], first_row: int) -> None:
        self.names = names
        self.first_row = first_row
        self.place: dict[int, int] = {}
        self._layout(names, numbers)

    def _layout(self, names: list[str], numbers: list[int]) -> None:
        """Each channel's place in the dense layout, from a header pair (a name the
        first header lacks has none)."""
        where = {n.casefold(): i for i, n in enumerate(self.names)}
        self.place = {
            ch: where[n.casefold()]
            for n, ch in zip(names, numbers, strict=True)
            if n.casefold() in where
        }

    @classmethod
    def detect(cls, head: list[str]) -> SparseLog | None:
        """The sparse log whose header pair is among ``head``'s lines, or None."""
        for i in range(len(head)):
            pair = _header_pair(head, i)
            if pair is not None:
                return cls(pair[0], pair[1], i + 2)
        return None

    @property
    def header(self) -> str:
        """The dense header line."""
        return ",".join(self.names)

    def dense(self, lines: Iterator[str], report: ImportReport) -> Iterator[str]:
        """Each data row as a dense comma-separated line (module docstring)."""
        pending: str | None = None
        for line in lines:
            text = line.strip()
            if not text:
                continue
            if text.startswith("!"):
                if pending is not None:
                    pair = _header_pair([pending, text], 0)
                    if pair is not None:
                        self._layout(*pair)
                    pending = None
                elif text.casefold().startswith(NAMES_TAG):
                    pending = text
                continue
            pending = None
            row, why = self._row(text.split(","))
            if row is None:
                report.lines += 1
                report.skipped[why] += 1
                continue
            yield row

    def _row(self, tokens: list[str]) -> tuple[str | None, str]:
        """A data row's dense line, or None and why: ``other_boat``, ``bad_row``."""
        at = self.place.get(0)
        if len(tokens) < 2 or len(tokens) % 2 or at is None:
            return None, "bad_row"
        if tokens[0].strip() != OWN_BOAT:
            return None, "other_boat"
        cells = [""] * len(self.names)
        cells[at] = tokens[1].strip()
        for ch, value in zip(tokens[2::2], tokens[3::2], strict=True):
            try:
                place = self.place.get(int(ch))
            except ValueError:
                return None, "bad_row"
            if place is not None:
                cells[place] = value.strip()
        return ",".join(cells), ""
