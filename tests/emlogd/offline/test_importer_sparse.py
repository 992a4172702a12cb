"""Expedition's own sparse log (``!Boat`` header, channel numbers, ``channel,value``
pairs) read by ``emlogd import`` as the rows of its flat export. Synthetic."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183 import Rmc, Vdr, Vhw
from drivers.records import KNOT_MPS
from emlogd.offline.csvmaps import FILETIME_EPOCH_S, guess_time_format, parse_time
from emlogd.offline.importer import import_csv


def _decoded(cap: Path) -> list[object]:
    dec = make_decoder("nmea0183", "nmea")
    return [x for r in CaptureReader(cap) for x in dec.feed(r.data)]


OLE_T = 46148.5  # 2026-05-06 12:00 UTC
OLE_STEP = 1.0 / 86400.0

SPARSE_HEAD = "!Boat,Utc,BSP,AWA,Set,Drift,HDG,Lat,Lon,COG,SOG\r\n!boat,0,1,2,11,12,13,48,49,50,51\r\n!v12.5.1\r\n"


class TestExpeditionSparseLog:
    def test_channel_value_rows_become_samples(self, tmp_path: Path) -> None:
        """Expedition's own log: a row holds only the channels written; the import reads
        them by channel number, whatever their order, as the flat export's cells."""
        rows = [
            f"0,{OLE_T},1,5.10,13,90.0,50,95.0,51,5.3,48,43.1,49,5.6,11,200,12,0.4",
            f"0,{OLE_T + OLE_STEP},51,5.5,50,96.0,1,5.20",
            f"0,{OLE_T + 2 * OLE_STEP},2,-40.0",
        ]
        src = tmp_path / "log.csv"
        src.write_text(SPARSE_HEAD + "\r\n".join(rows) + "\r\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.preset == "expedition" and rep.notes["expedition_sparse_log"] == 1
        assert rep.sentences == {"RMC": 2, "VHW": 2, "VDR": 1}
        assert rep.skipped == {"no_new_value": 1}  # the wind-only row
        recs = _decoded(tmp_path / "o.cap")
        vhw = [x for x in recs if isinstance(x, Vhw)]
        assert [v.stw_knots for v in vhw] == [5.10, 5.20]
        assert all(v.heading_true_deg == 90.0 for v in vhw)  # carried within carry_s
        (vdr,) = [x for x in recs if isinstance(x, Vdr)]
        assert vdr.set_true_deg == 200.0
        rmc = [x for x in recs if isinstance(x, Rmc)]
        assert rmc[1].sog_mps == pytest.approx(5.5 * KNOT_MPS) and rmc[0].lat_deg == pytest.approx(
            43.1
        )
        assert rep.t_start == pytest.approx(datetime(2026, 5, 6, 12, tzinfo=UTC).timestamp())

    def test_other_boats_bad_rows_and_a_new_header(self, tmp_path: Path) -> None:
        """Another boat's rows and unreadable pairs are counted; a header pair later in
        the file renumbers the channels."""
        rows = [
            f"0,{OLE_T},1,5.0,13,90.0",
            f"3,{OLE_T},1,9.0,13,10.0",
            f"0,{OLE_T + OLE_STEP},1",
            "!Boat,Utc,HDG,BSP",
            "!boat,0,7,8",
            f"0,{OLE_T + 2 * OLE_STEP},8,6.0,7,180.0",
        ]
        src = tmp_path / "log.csv"
        src.write_text(SPARSE_HEAD + "\n".join(rows) + "\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.skipped == {"other_boat": 1, "bad_row": 1}
        vhw = [x for x in _decoded(tmp_path / "o.cap") if isinstance(x, Vhw)]
        assert [(v.stw_knots, v.heading_true_deg) for v in vhw] == [(5.0, 90.0), (6.0, 180.0)]

    def test_filetime_times(self, tmp_path: Path) -> None:
        """``!log=v3`` logs keep time as Windows FILETIME ticks (100 ns since 1601)."""
        t = datetime(2026, 9, 2, 12, 0, tzinfo=UTC).timestamp()
        ticks = round((t - FILETIME_EPOCH_S) * 1e7)
        assert guess_time_format(str(ticks)) == "filetime"
        assert parse_time(str(ticks), "filetime") == pytest.approx(t)
        rows = [f"0,{ticks + k * 10_000_000},1,5.{k},13,90.0,51,5.0,50,92.0" for k in range(3)]
        src = tmp_path / "log.csv"
        src.write_text(SPARSE_HEAD + "!log=v3\n" + "\n".join(rows) + "\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert rep.t_start == pytest.approx(t) and rep.t_end == pytest.approx(t + 2.0)
        assert rep.sentences["VHW"] == 3

    def test_a_flat_export_is_not_taken_for_a_sparse_log(self, tmp_path: Path) -> None:
        """A flat export whose first cell is named like the boat column stays flat."""
        src = tmp_path / "log.csv"
        src.write_text(f"Utc,Bsp,Hdg\n{OLE_T},5.0,90.0\n")
        rep = import_csv(src, tmp_path / "o.cap")
        assert "expedition_sparse_log" not in rep.notes and rep.sentences == {"VHW": 1}
