"""The radar bridge's doctor checks (its serial ports) on crafted files: no radar."""

from __future__ import annotations

import os
from pathlib import Path

from buddybot.radar.doctor import BRIDGE, check_serial, sensor_models
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.runtime.health import FAIL, OK


def test_serial_ports(tmp_path: Path) -> None:
    present = tmp_path / "ttyUSB0"
    present.write_bytes(b"")
    locked = tmp_path / "ttyUSB1"
    locked.write_bytes(b"")
    locked.chmod(0o000)
    checks = check_serial([str(present), str(tmp_path / "gone"), str(locked),
                           "socket://radar.local:4001"], sim=False)
    assert [c.name for c in checks] == [f"radar serial {i}" for i in range(4)]
    assert [c.level for c in checks[:2]] == [OK, FAIL]
    assert "does not exist" in checks[1].detail
    if os.geteuid() != 0:  # root reads anything
        assert checks[2].level == FAIL and "dialout" in checks[2].detail
    assert checks[3].level == OK and "network" in checks[3].detail
    assert check_serial(["/dev/nothing"], sim=True)[0].level == OK


def test_the_settings_sim_flag_needs_no_port() -> None:
    assert BRIDGE.devices is not None
    gone = RadarBridgeSettings(sensors=["/dev/nothing"])
    assert [c.level for c in BRIDGE.devices(gone, False, False)] == [FAIL]
    simulated = RadarBridgeSettings(sensors=["/dev/nothing"], sim=True)
    assert [c.level for c in BRIDGE.devices(simulated, False, False)] == [OK]
    assert [c.level for c in BRIDGE.devices(gone, True, False)] == [OK]


def rate_names(settings: RadarBridgeSettings, sim: bool = False) -> list[str]:
    assert BRIDGE.rates is not None
    return [r.name for r in BRIDGE.rates(settings, sim)]


def test_an_ld2450_robot_is_counted_on_targets_not_frames() -> None:
    """An LD2450 publishes `targets`: counting `frames` would report it silent."""
    angle = RadarBridgeSettings(sensors=["/dev/ttyUSB0"], models={"0": "LD2450"})
    assert rate_names(angle) == ["radar targets"]
    assert BRIDGE.rates is not None
    [rate] = BRIDGE.rates(angle, False)
    assert rate.key.endswith("/targets") and rate.also == ()
    assert rate_names(RadarBridgeSettings(sim_model="LD2450")) == ["radar targets"]
    assert rate_names(RadarBridgeSettings(sensors=["/dev/x"], sim_model="LD2450"),
                      sim=True) == ["radar targets"]


def test_each_configured_model_has_its_stream() -> None:
    assert rate_names(RadarBridgeSettings()) == ["radar frames"]  # the simulated LD2410
    mixed = RadarBridgeSettings(sensors=["/dev/a", "/dev/b"],
                                models={"0": "LD2410", "1": "LD2450"})
    assert rate_names(mixed) == ["radar frames", "radar targets"]
    assert sensor_models(mixed, sim=False) == ["LD2410", "LD2450"]
    assert sensor_models(mixed, sim=True) == ["LD2410"]  # only the simulated sensor


def test_a_model_recognised_at_connect_counts_either_stream() -> None:
    auto = RadarBridgeSettings(sensors=["/dev/a"])
    assert BRIDGE.rates is not None
    [rate] = BRIDGE.rates(auto, False)
    assert rate.name == "radar reports"
    assert {rate.key.rsplit("/", 1)[1], *(k.rsplit("/", 1)[1] for k in rate.also)} == {
        "frames", "targets"}
