"""The offline commands' shared arguments and the UUT settings they give."""

from __future__ import annotations

import pytest

from emlogd.cli import build_parser
from emlogd.cli.offline.args import uut_settings
from emlogd.pipeline.settings import UutSettings


@pytest.mark.parametrize("command", ["calibrate", "evaluate", "crossval"])
def test_an_offline_job_takes_the_declared_defaults(command: str) -> None:
    """Options left out give exactly the pipeline's declared UUT settings (no second copy)."""
    argv = [command, "x.cap", "--uut", "log", "--ref", "dvl"]
    if command == "evaluate":
        argv += ["--params", "p.json"]
    args = build_parser().parse_args(argv)
    assert uut_settings(args) == UutSettings(port="log", reference_port="dvl")
