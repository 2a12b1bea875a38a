"""`buddybot param set radar-presence range_m ...` moves the IN/OUT decision while it runs.

A simulated LD2410 on a real pty sees one person standing 1.00 m away; the
real radar-bridge reads it, the real radar-presence decides, and the
`buddybot param` verb changes `range_m` twice: no restart in between
(the same process, checked by its pid and its node instance).
"""

from __future__ import annotations

import random
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.scenarios import Target
from buddybot.radar.sim import PtySensor
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv

pytestmark = pytest.mark.integration

IN, OUT = m.PresenceState.IN_RANGE, m.PresenceState.OUT_OF_RANGE


def standing_1m(_t: float, _rng: random.Random) -> Target:
    return Target(2, 100, 5, 100, 70, 100)  # STATIONARY at 100 cm


@pytest.fixture
def sensor(tmp_path: Path) -> Iterator[PtySensor]:
    made = PtySensor(standing_1m, link=tmp_path / "ttyLD").start()
    yield made
    made.stop()


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_range_m_set_live_moves_the_decision(sensor: PtySensor, spawn: Callable[..., Process],
                                             probe: Node, endpoint: str) -> None:
    presence = Collector[m.PresenceDetection](probe, keys.PRESENCE)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="radar-presence")
    spawn("radar-bridge", "--sensor", sensor.path)
    service = spawn("radar-presence", "--range-m", "0.5", "--absence-hold-s", "0.3")
    pid = service.pid
    # 1.00 m is beyond 0.5 m: nobody in range.
    assert presence.wait_for(timeout=30, what="first verdict").presence_state == OUT

    result = param(endpoint, "set", "radar-presence", "range_m", "1.5")
    assert result.returncode == 0, result.stderr
    assert "radar_presence.range_m = 1.5 (applied)" in result.stdout
    entered = presence.wait_for(lambda v: v.presence_state == IN, 15, "IN_RANGE after the set")
    assert entered.distance_m == pytest.approx(1.0, abs=0.01)

    presence.clear()
    result = param(endpoint, "set", "radar-presence", "range_m", "0.5")
    assert result.returncode == 0, result.stderr
    presence.wait_for(lambda v: v.presence_state == OUT, 15, "OUT_OF_RANGE after the set")

    # One process all along, which says what changed, in its log and its diagnostics.
    assert service.alive() and service.pid == pid
    service.wait_for_output("parameters changed: range_m=0.5")
    changed = diag.wait_for(lambda d: d.values.get("params_changed") == 2, 15,
                            "params_changed in diagnostics")
    assert changed.values["last_param_change"] == "range_m=0.5"
