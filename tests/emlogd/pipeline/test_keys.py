"""The declaration of config keys: fields, groups, and the value checks."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import pytest

from emlogd.pipeline.keys import (
    InvalidValueError,
    build,
    entries,
    get,
    group,
    hostport,
    ipv4_port,
    key,
    lag,
    number,
    param_std,
    string,
)
from emlogd.pipeline.settings import UutSettings


@dataclass(frozen=True, slots=True)
class _Inner:
    depth_m: float = key(2.0, check=number(0.0, 10.0), unit="m", doc="Depth.")
    note: str = "not a key"


@dataclass(frozen=True, slots=True)
class _Outer:
    name: str = key(check=string(), doc="Name.")
    inner: _Inner = group(_Inner)
    count: int = key(3, check=number(0, 9, integer=True), name="n", doc="Count.")


def test_entries_flatten_groups_in_field_order() -> None:
    """A group's keys sit in the parent's section where the group is declared; fields that
    are not keys are not listed; a key may have a config name of its own."""
    es = list(entries(_Outer))
    assert [(e.name, e.attrs) for e in es] == [
        ("name", ("name",)),
        ("depth_m", ("inner", "depth_m")),
        ("n", ("count",)),
    ]
    assert [e.required for e in es] == [True, False, False]
    assert es[1].default == 2.0 and es[1].key.unit == "m"


def test_build_fills_groups_and_defaults() -> None:
    """build() makes the nested group from its values and leaves the rest to defaults."""
    o = build(_Outer, {("name",): "a", ("inner", "depth_m"): 5.0})
    assert o == _Outer(name="a", inner=_Inner(depth_m=5.0), count=3)
    assert get(o, ("inner", "depth_m")) == 5.0
    assert build(_Outer, {("name",): "b"}).inner == _Inner()


def test_a_key_without_a_default_is_required() -> None:
    """A key declared without default is a required field of the dataclass too."""
    with pytest.raises(TypeError):
        _Outer()


def test_the_pipelines_settings_declare_their_keys() -> None:
    """UutSettings' keys include the envelope's speed range through its group, and its
    defaults are the fields' own."""
    by_name = {e.name: e for e in entries(UutSettings)}
    assert by_name["max_speed_mps"].attrs == ("envelope", "max_speed_mps")
    assert by_name["lag"].attrs == ("lag_s",)
    default = UutSettings(port="a", reference_port="b")
    for e in by_name.values():
        if not e.required:
            assert get(default, e.attrs) == e.default, e.name
    assert {f.name for f in dataclasses.fields(UutSettings)} >= {"ref_stale_s", "maker"}
    assert "ref_stale_s" not in by_name and "maker" not in by_name


@pytest.mark.parametrize(
    ("check", "value", "message"),
    [
        (number(0.0, 1.0), 2, "2 is out of range [0.0, 1.0]"),
        (number(0.0, 1.0, lo_open=True), 0.0, "0.0 is out of range (0.0, 1.0]"),
        (number(0, 9, integer=True), 1.5, "expected an integer, got 1.5"),
        (number(0.0, 1.0), True, "expected a number, got True"),
        (number(0.0, 1.0), None, "expected a number, got None"),
        (string(r"[A-Z]{2}", "two uppercase letters"), "vw", "'vw' is not two uppercase letters"),
        (lag, "soon", "expected auto or seconds in [0, 30], got 'soon'"),
        (hostport, "nowhere", "'nowhere' is not HOST:PORT (port 1..65535)"),
        (ipv4_port, "nowhere", "'nowhere' is not HOST:PORT (port 1..65535)"),
        (
            ipv4_port,
            "display.local:10110",
            "'display.local:10110': needs an IPv4 address, not a host name (resolving it "
            "would hold the daemon's one thread, every output with it, at every retry)",
        ),
    ],
)
def test_checks_refuse_with_the_problem(check: object, value: object, message: str) -> None:
    """Each check refuses a bad value with the problem in words (the loader adds where)."""
    with pytest.raises(InvalidValueError) as exc:
        check(value)  # type: ignore[operator]
    assert str(exc.value) == message


def test_checks_convert_and_pass() -> None:
    """lag: auto is None, seconds are floats; null passes an optional number."""
    assert lag("auto") is None and lag(3) == 3.0 and isinstance(lag(3), float)
    assert number(0.0, 1.0, optional=True)(None) is None
    assert hostport(":10110") == ":10110"
    assert ipv4_port(":10110") == ":10110" and ipv4_port(None) is None
    assert ipv4_port("192.168.1.255:10110") == "192.168.1.255:10110"


def test_param_std_names_the_parameter_at_fault() -> None:
    """A mapping check says which of its keys is wrong."""
    check = param_std(("a", "m", "b"), 0.0, 10.0)
    assert check({"m": 0.1}) == {"m": 0.1}
    with pytest.raises(InvalidValueError) as exc:
        check({"z": 1.0})
    assert exc.value.sub == "z" and str(exc.value) == "unknown parameter (a, m or b)"
    with pytest.raises(InvalidValueError) as exc:
        check({"b": 0.0})
    assert exc.value.sub == "b"
    assert check.mapping and "a, m, b" in check.text


def test_number_text_for_the_table() -> None:
    """The words the README's table gives a number check show its range."""
    assert number(0.0, 4_000_000, integer=True).text == "integer in [0, 4000000]"
    assert number(0.0, 1.0, lo_open=True, optional=True).text == "number in (0, 1] or null"
