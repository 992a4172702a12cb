"""The daemon's outputs: opened from the config, kept across a sync when their settings
are equal, and each sentence routed to its log's own outputs or the shared ones."""

from __future__ import annotations

import dataclasses
import os
import selectors
import socket
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from emlogd.config import Config, parse_config
from emlogd.daemon.outputs import OUTPUT_RETRY_S, Outputs
from emlogd.daemon.sinks import PtySink, TcpServerSink
from emlogd.pipeline.core import Emit
from tests.emlogd.daemon.harness import free_port


class _Log:
    def info(self, event: str, **kw: object) -> None:
        pass

    warning = info


def _receiver() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    return s


def _config(shared: int, own: int | None) -> Config:
    own_key = f", udp: '127.0.0.1:{own}'" if own is not None else ""
    return parse_config(
        "ports:\n"
        "  - {name: emlog1, url: 'loop://', protocol: nmea0183, role: uut}\n"
        "  - {name: emlog2, url: 'loop://', protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: 'loop://', protocol: pd6, role: reference}\n"
        "calibration:\n"
        "  - {uut: emlog1, reference: dvl}\n"
        f"  - {{uut: emlog2, reference: dvl, talker: VM{own_key}}}\n"
        f"outputs: {{pty: null, udp: '127.0.0.1:{shared}'}}\n"
    )


@pytest.fixture
def receivers() -> Iterator[tuple[socket.socket, socket.socket]]:
    shared, own = _receiver(), _receiver()
    yield shared, own
    shared.close()
    own.close()


def test_a_log_with_its_own_output_writes_there_only(
    receivers: tuple[socket.socket, socket.socket],
) -> None:
    """emlog2's sentences go to its own UDP destination alone; emlog1's to the shared one."""
    shared, own = receivers
    outputs = Outputs(selectors.DefaultSelector(), _Log(), lambda: 0.0)
    cfg = _config(shared.getsockname()[1], own.getsockname()[1])
    try:
        closed, opened = outputs.sync(cfg)
        assert closed == [] and len(opened) == 2
        outputs.deliver([Emit(1.0, "emlog1", "$VWVHW,a"), Emit(1.0, "emlog2", "$VMVHW,b")])
        assert shared.recv(4096) == b"$VWVHW,a\r\n"
        assert own.recv(4096) == b"$VMVHW,b\r\n"
        shared.settimeout(0.1)
        with pytest.raises(TimeoutError):
            shared.recv(4096)  # emlog2's sentence did not reach the shared output
        assert set(outputs.status()) == set(opened)
        assert all(doc["state"] == "open" for doc in outputs.status().values())
    finally:
        outputs.close()


def test_a_sync_keeps_equal_outputs_and_closes_the_others(
    receivers: tuple[socket.socket, socket.socket],
) -> None:
    """Syncing to a config without emlog2's own output closes that one, keeps the shared
    output as the same object, and sends emlog2's sentences to the shared one again."""
    shared, own = receivers
    outputs = Outputs(selectors.DefaultSelector(), _Log(), lambda: 0.0)
    port = shared.getsockname()[1]
    try:
        outputs.sync(_config(port, own.getsockname()[1]))
        kept = outputs.shared[0]
        closed, opened = outputs.sync(_config(port, None))
        assert closed == [f"udp:127.0.0.1:{own.getsockname()[1]}"] and opened == []
        assert outputs.shared == [kept] and outputs.routes == {}
        outputs.deliver([Emit(1.0, "emlog2", "$VMVHW,b")])
        assert shared.recv(4096) == b"$VMVHW,b\r\n"
    finally:
        outputs.close()
    assert outputs.sinks == {}


class _Events(_Log):
    def __init__(self) -> None:
        self.seen: list[tuple[str, dict[str, object]]] = []

    def info(self, event: str, **kw: object) -> None:
        self.seen.append((event, kw))

    warning = info


def test_a_logs_own_tcp_output_without_a_shared_one_opens() -> None:
    """A log with its own TCP output and no shared TCP output (a valid config): the
    output opens, a client connecting is logged, and emlog2's sentences reach it.
    Building the outputs raised ``UnboundLocalError`` (the client events were bound to
    the shared output's address, unset): the daemon ended at its start, or at the
    reload into such a config, with ``internal error``."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    cfg = parse_config(
        "ports:\n"
        "  - {name: emlog2, url: 'loop://', protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: 'loop://', protocol: pd6, role: reference}\n"
        "calibration:\n"
        f"  - {{uut: emlog2, reference: dvl, tcp: '127.0.0.1:{port}'}}\n"
        "outputs: {pty: null}\n"
    )
    log = _Events()
    sel = selectors.DefaultSelector()
    outputs = Outputs(sel, log, lambda: 0.0)
    try:
        _, opened = outputs.sync(cfg)
        assert opened == [f"tcp:127.0.0.1:{port}"]
        with socket.create_connection(("127.0.0.1", port), 2.0) as client:
            for key, _ in sel.select(1.0):
                key.data()
            assert any(e == "client_connected" for e, _ in log.seen), log.seen
            outputs.deliver([Emit(1.0, "emlog2", "$VMVHW,b")])
            assert client.recv(4096) == b"$VMVHW,b\r\n"
    finally:
        outputs.close()
        sel.close()


def test_an_output_that_cannot_be_opened_is_tried_again(tmp_path: Path) -> None:
    """A log's own pty whose path holds a regular file: the sync raises, the shared UDP
    output is open all the same, the status says why the pty is not; tried again at
    housekeeping once OUTPUT_RETRY_S has passed, it opens when the file is gone (and a
    reload without it forgets it)."""
    clock = [0.0]
    outputs = Outputs(selectors.DefaultSelector(), _Log(), lambda: clock[0])
    link = tmp_path / "e2"
    link.write_text("kept")
    with _receiver() as shared:
        base = _config(shared.getsockname()[1], None)
        uut = base.calibration[1]
        own = dataclasses.replace(uut, outputs=dataclasses.replace(uut.outputs, pty=str(link)))
        cfg = dataclasses.replace(base, calibration=(base.calibration[0], own))
        try:
            with pytest.raises(DeviceError, match="not a symlink"):
                outputs.sync(cfg)
            assert [s.name for s in outputs.shared] == [f"udp:127.0.0.1:{shared.getsockname()[1]}"]
            assert "not a symlink" in str(outputs.status()[f"pty:{link}"]["state"])
            link.unlink()
            outputs.housekeep()  # not yet due
            assert not link.exists()
            clock[0] += OUTPUT_RETRY_S
            outputs.housekeep()
            assert link.is_symlink() and outputs.status()[f"pty:{link}"]["state"] == "open"
            assert [s.name for s in outputs.routes["emlog2"]] == [f"pty:{link}"]
            assert not outputs.failed
            link.unlink()
            link.write_text("again")
            outputs.sync(base)  # without it: closed (its file left), nothing to retry
            assert not outputs.failed and f"pty:{link}" not in outputs.status()
        finally:
            outputs.close()


def test_a_reload_changing_mode_or_limits_keeps_the_pty_and_the_clients(tmp_path: Path) -> None:
    """A sync into new ``pty_mode`` and TCP limits keeps the pty (same slave, its reader
    reads on, the new mode on it) and the TCP output (same sink, its client stays, the
    new limits in force); an unknown ``pty_group`` is raised, the pty kept as it was. A
    new mode made a new pty (its reader hung up) and new limits a new TCP output (every
    client dropped)."""
    port = free_port()
    text = (
        "ports:\n  - {name: emlog1, url: 'loop://', protocol: nmea0183, role: uut}\n"
        "  - {name: dvl, url: 'loop://', protocol: pd6, role: reference}\n"
        "calibration:\n  - {uut: emlog1, reference: dvl}\n"
        f"outputs: {{pty: {tmp_path / 'e0'}, tcp: '127.0.0.1:{port}', pty_mode: 0660}}\n"
    )
    sel = selectors.DefaultSelector()
    outputs = Outputs(sel, _Log(), lambda: 0.0)
    try:
        outputs.sync(parse_config(text))
        pty, tcp = outputs.shared
        reader = os.open(tmp_path / "e0", os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
        client = socket.create_connection(("127.0.0.1", port), timeout=5)
        try:
            for key, _ in sel.select(timeout=1.0):
                key.data()  # the client accepted
            changed = text.replace("pty_mode: 0660}", "pty_mode: 0640, tcp_stall_s: 3}")
            assert outputs.sync(parse_config(changed)) == ([], [])
            assert outputs.shared == [pty, tcp]
            assert isinstance(tcp, TcpServerSink) and tcp.limits.stall_s == 3.0
            assert isinstance(pty, PtySink)
            assert stat.S_IMODE(Path(pty.port.slave_path).stat().st_mode) == 0o640
            outputs.deliver([Emit(0.0, "emlog1", "$VWVHW,,T,,M,5.00,N,9.26,K*5C")])
            assert os.read(reader, 100) == b"$VWVHW,,T,,M,5.00,N,9.26,K*5C\r\n"
            assert client.recv(100) == b"$VWVHW,,T,,M,5.00,N,9.26,K*5C\r\n"
            with pytest.raises(DeviceError, match="cannot configure"):
                outputs.sync(parse_config(changed.replace("tcp_stall_s: 3", "pty_group: nogrp_x")))
            assert outputs.shared == [pty, tcp]
        finally:
            client.close()
            os.close(reader)
    finally:
        outputs.close()
        sel.close()
