"""Teledyne-RDI PD6 and PD13 ASCII output (which Rowe SeaPILOT emulates).

An ensemble is a block of ``:XX,...`` lines (docs/PROTOCOLS.md §5.1–5.2) in this order:
``:SA :TS [:RA] [:WI :WS :WE :WD] :BI :BS :BE :BD [:HM]``. PD6 has no checksum, so
every line is validated instead: its type, its field count, numeric syntax (spaces
and a leading ``+`` allowed, PD13 pads with spaces), and the ``A``/``V`` status.

Assembly: a block starts at ``:SA`` and is emitted as one :class:`Pd6Ensemble` when
its ``:BD`` line arrives (the last line PD6/PD13 send; a Pathfinder's trailing
``:HM`` comes out as its own :class:`PdHealth` record). A block is never spliced:
a line out of order, a repeated line, or a rejected line inside the block discards
the whole block, counted once as ``framing`` (the rejected line itself is counted
under its own reason). Lines before the first ``:SA`` are discarded the same way.

Invalid data: velocity −32768 (mm/s) or status ``V`` → the vector is None.

Sign convention: PD6/PD13 give the **vessel's** motion (``:BS`` T + = moving to
starboard, L + = moving forward, N + = moving away from the bottom; ``:BE`` + =
moving east/north/up), so the speed record is ``:BS`` as is (PD0 is the opposite).
``:RA`` beam ranges are in decimetres (the manual's example pairs 71.31 dm with
``:BD`` 7.13 m); they are converted to metres.

The package: :mod:`.records` (the ensemble's records and line order), :mod:`.parse`
(each line's checks and readers), :mod:`.decoder` (:class:`PdAsciiDecoder`, the block
assembly), :mod:`.encode` (:func:`encode_pd6`).

Must not import: serial, os, time, threading (pure modules).
"""

from drivers.rdi_ascii.decoder import PdAsciiDecoder
from drivers.rdi_ascii.encode import encode_pd6
from drivers.rdi_ascii.records import (
    ORDER,
    RECORD_PARTS,
    RECORDS,
    DistanceMadeGood,
    Pd6Ensemble,
    Pd6Record,
    PdHealth,
    Velocity,
)

__all__ = [
    "ORDER",
    "RECORDS",
    "RECORD_PARTS",
    "DistanceMadeGood",
    "Pd6Ensemble",
    "Pd6Record",
    "PdAsciiDecoder",
    "PdHealth",
    "Velocity",
    "encode_pd6",
]
