"""The daemon's outputs: opened from the config, kept across a sync when their settings
are equal, and each sentence routed to its log's own outputs or the shared ones."""

from __future__ import annotations

import dataclasses
import selectors
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from drivers.errors import DeviceError
from emlogd.config import Config, parse_config
from emlogd.daemon.outputs import OUTPUT_RETRY_S, Outputs
from emlogd.pipeline.core import Emit


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
