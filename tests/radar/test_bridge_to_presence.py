"""The radar chain end to end: simulated LD2410s on real ptys, the real radar-bridge
and radar-presence processes, a real router: what a visit and a noisy sensor give on
`presence`, and how both services refuse a bad command line or config."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.sim import PtySensor
from buddybot.runtime.node import Node
from buddybot.tools.testing import LOOPBACK, Collector, Process
from tests.radar.rig import Gated, diag_value, wait_more_frames
from tests.radar.scripts import LD2410_SCRIPTS

pytestmark = pytest.mark.integration

IN, OUT = m.PresenceState.IN_RANGE, m.PresenceState.OUT_OF_RANGE
Spawn = Callable[..., Process]


def test_approach_and_leave_gives_one_visit(sensors: Callable[..., PtySensor], spawn: Spawn,
                                            probe: Node,
                                            node_factory: Callable[..., Node]) -> None:
    script = Gated(LD2410_SCRIPTS["walk-in"])
    sensor = sensors(script, speed=2.0)
    presence = Collector(probe, keys.PRESENCE)
    frames = Collector(probe, keys.RADAR_FRAMES)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    bridge = spawn("radar-bridge", "--sensor", sensor.path)
    service = spawn("radar-presence", "--absence-hold-s", "1.0")
    pdiag.wait_for(lambda d: d.level == "OK", 30, "presence seeing the sensor")
    # The first verdict of a fresh service: nobody, once the absence hold has passed.
    assert presence.wait_for(timeout=30).presence_state == OUT
    presence.clear()
    script.go()
    entered = presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")
    left = presence.wait_for(lambda v: v.presence_state == OUT, 30, "OUT_OF_RANGE")
    # The scenario is over (nobody, for good): let 2 s of frames more pass.
    wait_more_frames(frames, 0, 20)
    states = [v.presence_state for v in presence.messages]
    edges = [s for i, s in enumerate(states) if i == 0 or states[i - 1] != s]
    assert edges == [IN, OUT], presence.messages
    assert states.count(OUT) == 1
    assert 1.5 <= entered.distance_m <= 2.0
    # IN_RANGE carries the arrival stamp of the frame that caused it.
    stamps = {msg.stamp_ns for msg in frames.messages}
    assert entered.stamp_ns in stamps and left.stamp_ns >= entered.stamp_ns
    # A late joiner gets the latched verdict at once.
    late = Collector(node_factory("late"), keys.PRESENCE)
    assert late.wait_for(timeout=10).presence_state == OUT
    assert bridge.alive() and service.alive()


def test_flickering_noisy_sensor_does_not_flap_presence(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    sensor = sensors("noisy", seed=7)
    presence = Collector(probe, keys.PRESENCE)
    frames = Collector(probe, keys.RADAR_FRAMES)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    spawn("radar-bridge", "--sensor", sensor.path)
    service = spawn("radar-presence")  # default holds
    presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")
    wait_more_frames(frames, 0, 80, 40)
    assert [v.presence_state for v in presence.messages].count(OUT) == 0, presence.messages
    diag.wait_for(lambda d: int(diag_value(d, "bad_frames") or 0) > 0
                  and int(diag_value(d, "clamped_energies") or 0) > 0
                  and int(diag_value(d, "frames") or 0) > 50, 20,
                  "bad frames and clamped energies counted")
    assert service.alive()


def test_bad_command_line_values_are_clear_errors() -> None:
    for service, args, needle in (
        ("radar-presence", ["--range-m", "-1"], "range_m"),
        ("radar-presence", ["--max-sensors", "0"], "max_sensors"),
        ("radar-presence", ["--max-sensors", "5000"], "max_sensors"),
        ("radar-bridge", ["--sim", "--sim-speed", "-2"], "--sim-speed"),
        ("radar-bridge", ["--sim", "--sim-speed", "0"], "--sim-speed"),
        ("radar-bridge", ["--sim", "--baudrate", "0"], "--baudrate"),
        ("radar-bridge", [], "no sensor"),
    ):
        out = subprocess.run(
            [sys.executable, "-m", "buddybot", "run", service, *args,
             "--connect", f"tcp/{LOOPBACK}:1"], capture_output=True, text=True, timeout=60)
        assert out.returncode == 2, (service, args, out.stderr)
        assert needle in out.stdout + out.stderr


@pytest.mark.parametrize(("toml", "needle"), [
    ("[radar_presence]\nrange_m = -1.0\n", "range_m"),
    ("[radar_presence]\nrange = 2.0\n", "range"),
    ("[radar_presence]\nmax_sensors = 0\n", "max_sensors"),
    ("[radar_bridge]\nquery_firmware = 'maybe'\n", "query_firmware"),
    ("[sim]\nscenario = 'party'\n[radar_bridge]\nsim = true\n", "party"),
])
def test_bad_config_is_a_clear_error(tmp_path: Path, toml: str, needle: str) -> None:
    config = tmp_path / "bad.toml"
    config.write_text(toml)
    service = "radar-bridge" if "radar_bridge" in toml else "radar-presence"
    out = subprocess.run(
        [sys.executable, "-m", "buddybot", "run", service, "--config", str(config),
         "--connect", f"tcp/{LOOPBACK}:1"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    assert needle in out.stderr
