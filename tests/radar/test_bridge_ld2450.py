"""The radar bridge with LD2450s: per-sensor models and mounts from `[radar_bridge]`
(pure), and, marked `integration`, simulated LD2410s and LD2450s on real ptys mixed
on one bridge through a real router: `radar/{device}/targets`, bearings, a sensor
that changes model, garbage, targets at the limits, silence."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import bridge
from buddybot.radar.mounting import IDENTITY, Mount
from buddybot.radar.settings import RadarBridgeSettings, RadarMount
from buddybot.radar.sim import PtySensor
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process
from tests.radar.rig import diag_value

Spawn = Callable[..., Process]


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    bridge.add_arguments(parser)
    return parser.parse_args(argv)


def test_models_and_mounts_by_sensor_index() -> None:
    cfg = RadarBridgeSettings(
        sensors=["/dev/ttyUSB0", "socket://esp32:8881"], models={"1": "LD2450"},
        mount=[RadarMount(sensor=1, y=0.05, z=-0.1, yaw=0.3, mirror_x=True)])
    opts = bridge.resolve_options(parse(), cfg)
    assert opts.models == ["auto", "LD2450"]
    assert opts.mounts == [IDENTITY, Mount(0.0, 0.05, -0.1, 0.3, True)]


def test_the_simulated_ld2450_is_the_last_sensor() -> None:
    opts = bridge.resolve_options(
        parse("--sensor", "/dev/ttyUSB0", "--sim", "--sim-model", "LD2450"),
        RadarBridgeSettings())
    assert opts.urls == ["/dev/ttyUSB0"] and opts.sim_model == "LD2450"
    assert opts.models == ["auto", "LD2450"] and len(opts.mounts) == 2


@pytest.mark.parametrize(("cfg", "says"), [
    (RadarBridgeSettings(sensors=["a"], models={"1": "LD2450"}), "radar_bridge.models: '1'"),
    (RadarBridgeSettings(sensors=["a"], models={"x": "LD2450"}), "radar_bridge.models: 'x'"),
    (RadarBridgeSettings(sensors=["a"], models={"0": "LD2420"}), "radar_bridge.models.0"),
    (RadarBridgeSettings(sensors=["a"], mount=[RadarMount(sensor=2)]),
     "radar_bridge.mount[0].sensor: 2"),
    (RadarBridgeSettings(sensors=["a"], mount=[RadarMount(sensor=0), RadarMount(sensor=0)]),
     "radar_bridge.mount[1].sensor: sensor 0 has two mounts"),
    (RadarBridgeSettings(sim=True, sim_model="LD2460"), "radar_bridge.sim_model"),
])
def test_bad_per_sensor_settings_are_refused_naming_the_key(cfg: RadarBridgeSettings,
                                                             says: str) -> None:
    with pytest.raises(ConfigError, match=says.replace("[", r"\[").replace("]", r"\]")):
        bridge.resolve_options(parse(), cfg)


def _targets(collector: Collector[m.RadarTargets], radar_id: int) -> list[m.RadarTargets]:
    return [msg for msg in collector.messages if msg.radar_id == radar_id]


@pytest.mark.integration
def test_ld2410_and_ld2450_on_one_bridge_each_on_its_key(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node, tmp_path: Path) -> None:
    ld2410 = sensors("visit", name="tty0", engineering=False)
    ld2450 = sensors("crossing", name="tty1", model="LD2450")
    config = tmp_path / "buddybot.toml"
    config.write_text(f'[radar_bridge]\nsensors = ["{ld2410.path}", "{ld2450.path}"]\n'
                      "[[radar_bridge.mount]]\nsensor = 1\nz = -0.1\n")
    frames = Collector(probe, keys.RADAR_FRAMES)
    targets = Collector(probe, keys.RADAR_TARGETS)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    proc = spawn("radar-bridge", "--config", str(config))
    diag.wait_for(lambda d: diag_value(d, "radar0.model") == "LD2410 basic"
                  and diag_value(d, "radar1.model") == "LD2450", 30, "both models recognised")
    targets.wait_for(lambda msg: len(msg.targets) == 1, 20, "a target")
    assert all(f.radar_id == 0 for msg in frames.messages for f in msg.sensors)
    assert _targets(targets, 0) == []
    msg = next(msg for msg in _targets(targets, 1) if msg.targets)
    [t] = msg.targets
    # The robot's left is x < 0 in the sensor and + y, + bearing in the camera (where
    # the crossing is when the bridge is up depends on how busy the machine is).
    assert msg.model == "LD2450" and msg.device_id == 0 and msg.stamp_ns > 0
    assert t.x_m != 0 and (t.x_m < 0) == (t.position.y > 0) == (t.bearing_rad > 0)
    assert t.position.z == pytest.approx(-0.1)
    assert t.bearing_rad == pytest.approx(math.atan2(t.position.y, t.position.x))
    assert t.resolution_m == pytest.approx(0.32)
    assert proc.alive()


@pytest.mark.integration
def test_a_sensor_that_changes_model_is_recognised_again(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    first = sensors("visit", name="ttyX")
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    targets = Collector(probe, keys.RADAR_TARGETS)
    proc = spawn("radar-bridge", "--sensor", first.path, "--no-sim")
    diag.wait_for(lambda d: str(diag_value(d, "radar0.model")).startswith("LD2410"), 30,
                  "LD2410 recognised")
    first.stop()
    sensors("standing", name="ttyX", model="LD2450")
    d = diag.wait_for(lambda d: diag_value(d, "radar0.model") == "LD2450", 40,
                      "LD2450 recognised on the same line")
    assert int(diag_value(d, "radar0.model_changes")) == 1  # type: ignore[arg-type]
    targets.wait_for(lambda msg: len(msg.targets) == 1, 20, "targets of the new sensor")
    assert proc.alive()


@pytest.mark.integration
def test_garbage_limits_and_silence_are_diagnosed_and_survived(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    noisy = sensors("noisy", name="ttyN", model="LD2450", seed=3)
    limits = sensors("limits", name="ttyL", model="LD2450")
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    targets = Collector(probe, keys.RADAR_TARGETS)
    proc = spawn("radar-bridge", "--sensor", noisy.path, "--sensor", limits.path)
    edge = targets.wait_for(lambda msg: msg.radar_id == 1 and len(msg.targets) == 3, 30,
                            "the targets at the limits")
    assert sorted((round(t.x_m, 3), round(t.y_m, 3)) for t in edge.targets) == [
        (-4.0, 0.1), (0.0, 8.0), (4.0, 0.1)]
    assert {round(t.bearing_rad, 2) for t in edge.targets} == {
        round(math.atan2(4.0, 0.1), 2), 0.0, round(math.atan2(-4.0, 0.1), 2)}
    d = diag.wait_for(lambda d: int(diag_value(d, "radar0.bad_frames") or 0) > 0, 40,  # type: ignore[arg-type]
                      "the noisy line's bad frames counted")
    assert diag_value(d, "implausible_targets") == 0
    limits.sim._silent_until = float("inf")  # the sensor goes quiet
    d = diag.wait_for(lambda d: "no valid frame" in str(diag_value(d, "radar1.error")), 30,
                      "silence reported")
    assert d.level in ("WARN", "ERROR") and proc.alive()
