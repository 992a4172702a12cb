"""Red-team cases of the live daemon's reloads and state (round five): a UUT the config
leaves out for a while keeps its calibration."""

from __future__ import annotations

import dataclasses
import signal
from pathlib import Path

from emlogd.calfile import loads_state
from emlogd.daemon.statefile import StateStore
from tests.emlogd.daemon.harness import OUTPUTS, Daemon, make_work, saved_calibration, wait

TWO_LOGS = f"""\
ports:
  - {{name: emlog1, url: links/emlog1, protocol: nmea0183, role: uut}}
  - {{name: emlog2, url: links/emlog2, protocol: nmea0183, role: uut}}
  - {{name: dvl, url: links/dvl, protocol: pd6, role: reference}}
calibration:
  - {{uut: emlog1, reference: dvl, lag: 0.165}}
  - {{uut: emlog2, reference: dvl, lag: 0.165, talker: VD}}
{OUTPUTS}"""
"""Two EMlogs and a DVL; no sensor needs to be there."""


def _without_emlog2(config: str) -> str:
    """The same config with emlog2 taken out (its log away for service, say)."""
    lines = config.splitlines(keepends=True)
    return "".join(x for x in lines if "emlog2" not in x)


def _saved(store: StateStore) -> dict[str, float]:
    """The scale ``m`` of every UUT's calibration the state file holds."""
    cals, others = loads_state(store.path.read_text())
    found = {c.uut: c.params.m for c in others}
    found.update({u: c.params.m for u, c in cals.items() if not c.reset})
    return found


def test_a_uut_left_out_of_a_reload_keeps_its_calibration(tmp_path: Path) -> None:
    """SIGHUP into a config without emlog2, a save (a ``freeze``), then SIGHUP with it
    back: emlog2's calibration is still in the state file after the save, and emlog2
    starts from it again. The calibration of a UUT the config did not have was dropped at
    the reload and at the next save: the log's frozen calibration lost for good."""
    work = make_work(tmp_path, TWO_LOGS)
    cfg = work / "emlogd.yaml"
    both = cfg.read_text()
    store = StateStore(work / "state" / "state.yaml")
    one = saved_calibration(0.1, lag_s=0.165)
    store.save(
        {
            "emlog1": one,
            "emlog2": dataclasses.replace(
                one, uut="emlog2", estimate=saved_calibration(0.2).estimate
            ),
        }
    )
    d = Daemon(work)
    try:
        cfg.write_text(_without_emlog2(both))
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 1, "the reload without emlog2", 10.0)
        assert d.ask(cmd="reset", port="emlog1").get("ok") is True, d.tail()
        assert _saved(store).get("emlog2") == 0.2, _saved(store)
        cfg.write_text(both)
        d.send_signal(signal.SIGHUP)
        wait(lambda: d.events("reloaded") >= 2, "the reload with emlog2 back", 10.0)
        assert d.ask(cmd="freeze", port="emlog2").get("ok") is True, d.tail()
        assert _saved(store).get("emlog2") == 0.2, _saved(store)
        assert d.stop() == 0
    finally:
        d.kill()
