"""What two parts of a config may not share: a TCP output's port, one path for two of
the sockets, the state file and the ptys."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from emlogd.config import parse_config
from emlogd.configclash import path_clash, same_listener, tcp_clash

CONFIG = """\
ports:
  - {name: emlog1, url: /dev/emlog1, protocol: nmea0183, role: uut}
  - {name: dvl, url: /dev/dvl, protocol: pd6, role: reference}
calibration:
  - {uut: emlog1, reference: dvl}
outputs: {pty: /run/emlogd/emlog0, tcp: ":10110"}
control_socket: /run/emlogd/control.sock
status_socket: /run/emlogd/status.sock
state_file: /var/lib/emlogd/state.yaml
"""


def test_tcp_outputs_on_one_port_clash_only_where_both_cannot_bind() -> None:
    """Two TCP outputs clash on one port with one host or a wildcard; on two hosts, or two
    ports, they do not (both bind)."""
    assert same_listener("127.0.0.1:10110", "127.0.0.1:10110")
    assert same_listener(":10110", "127.0.0.1:10110")
    assert same_listener("[::]:10110", "10.0.0.1:10110")
    assert not same_listener("127.0.0.1:10110", "10.0.0.1:10110")
    assert not same_listener("127.0.0.1:10110", "127.0.0.1:10111")
    assert tcp_clash(["127.0.0.1:1", "127.0.0.1:2", "10.0.0.1:2"]) == ""
    assert "127.0.0.1:2 and :2 clash" in tcp_clash(["127.0.0.1:1", "127.0.0.1:2", ":2"])


def test_every_path_its_own_passes_and_the_second_of_one_is_named() -> None:
    """A config whose sockets, state file and pty each have their own path passes; two at
    one path (the same after normalisation) name the second and its section."""
    good = parse_config(CONFIG)
    assert path_clash(good) == ("", "", "")
    cfg = dataclasses.replace(good, status_socket="/run/emlogd/./control.sock")
    why, key, section = path_clash(cfg)
    assert (key, section) == ("status_socket", "status_socket")
    assert why.startswith("the same path as control_socket")
    outputs = dataclasses.replace(good.outputs, pty="/var/lib/emlogd/state.yaml")
    why, key, section = path_clash(dataclasses.replace(good, outputs=outputs))
    assert (key, section) == ("outputs.pty", "outputs") and "as state_file" in why


def test_two_ptys_through_a_symlinked_directory_clash(tmp_path: Path) -> None:
    """Two UUTs' ptys at ``run/x`` and ``alias/x``, ``alias`` a symlink to ``run``: the
    second named; ``run/x`` and ``run/y`` pass, and so does a pty link that is itself a
    symlink (to the pty of the day) beside another path."""
    (tmp_path / "run").mkdir()
    (tmp_path / "alias").symlink_to(tmp_path / "run")
    good = parse_config(CONFIG)
    uut = good.calibration[0]

    def with_ptys(a: Path, b: Path) -> tuple[str, str, str]:
        cals = tuple(
            dataclasses.replace(uut, outputs=dataclasses.replace(uut.outputs, pty=str(p)))
            for p in (a, b)
        )
        return path_clash(dataclasses.replace(good, calibration=cals))

    why, key, section = with_ptys(tmp_path / "run" / "x", tmp_path / "alias" / "x")
    assert (key, section) == ("calibration[1].pty", "calibration")
    assert why.startswith("the same path as calibration[0].pty")
    for name in ("x", "y"):
        (tmp_path / "run" / name).symlink_to("/dev/null")
    assert with_ptys(tmp_path / "run" / "x", tmp_path / "run" / "y") == ("", "", "")


def test_a_port_reading_an_output_pty_is_named(tmp_path: Path) -> None:
    """A port whose device is the output pty's link, a link to that link, or the control
    socket is refused naming the port (the daemon read its own corrected VHW as a second
    log's readings and sent them on as that log's); two ports on one device and a port
    beside the outputs pass."""
    good = parse_config(CONFIG)
    (tmp_path / "links").mkdir()
    (tmp_path / "links" / "relay").symlink_to("../out/emlog0")
    (tmp_path / "links" / "relay2").symlink_to(tmp_path / "links" / "relay")
    outputs = dataclasses.replace(good.outputs, pty=str(tmp_path / "out" / "emlog0"))

    def with_url(url: str, port: int = 1) -> tuple[str, str, str]:
        ports = list(good.ports)
        ports[port] = dataclasses.replace(ports[port], url=url)
        return path_clash(dataclasses.replace(good, ports=tuple(ports), outputs=outputs))

    for url in ("out/emlog0", "out/./emlog0", "links/relay", "links/relay2"):
        why, key, section = with_url(str(tmp_path / url))
        assert (key, section) == ("ports[1].url", "ports"), url
        assert why.startswith("the same place as outputs.pty"), why
    why, key, _ = with_url("/run/emlogd/control.sock", 0)
    assert key == "ports[0].url" and "as control_socket" in why
    assert with_url("/dev/emlog1") == ("", "", "")
    assert with_url(str(tmp_path / "links" / "other")) == ("", "", "")
    assert with_url("socket://127.0.0.1:10112") == ("", "", "")


def test_a_socket_input_on_a_tcp_output_of_this_host_is_named() -> None:
    """A ``socket://`` input on the port of a TCP output, by a loopback address or the
    output's own (also IPv6-mapped, and the unspecified address a connect takes for this
    host), is refused naming the input and the output (the daemon read its own
    sentences back as a sensor's); another address on that port (a multiplexer on the
    usual 10110) and a loopback address on another port pass."""
    good = parse_config(CONFIG)  # outputs.tcp ":10110"
    uut = good.calibration[0]
    own = dataclasses.replace(uut, outputs=dataclasses.replace(uut.outputs, tcp="10.1.1.1:10111"))

    def with_url(url: str) -> tuple[str, str, str]:
        ports = (good.ports[0], dataclasses.replace(good.ports[1], url=url))
        return path_clash(dataclasses.replace(good, ports=ports, calibration=(own,)))

    for url, output in (
        ("socket://127.0.0.1:10110", "outputs.tcp"),
        ("SOCKET://127.0.0.2:10110", "outputs.tcp"),
        ("socket://[::1]:10110", "outputs.tcp"),
        ("socket://10.1.1.1:10111", "calibration[0].tcp"),
        ("socket://0.0.0.0:10110", "outputs.tcp"),  # a connect to it reaches this host
        ("socket://[::]:10110", "outputs.tcp"),
        ("socket://[::ffff:127.0.0.1]:10110", "outputs.tcp"),  # 127.0.0.1, IPv6-mapped
        ("socket://[::ffff:10.1.1.1]:10111", "calibration[0].tcp"),
    ):
        why, key, section = with_url(url)
        assert (key, section) == ("ports[1].url", "ports"), url
        assert why.startswith(f"the same place as {output}"), why
    for url in (
        "socket://192.168.1.10:10110",
        "socket://[::ffff:192.168.1.10]:10110",
        "socket://127.0.0.1:10112",
        "/dev/dvl",
    ):
        assert with_url(url) == ("", "", ""), url
