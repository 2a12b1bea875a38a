"""The radar bridge's command line merged over `[radar_bridge]` (pure, no process)."""

from __future__ import annotations

import argparse

import pytest

from buddybot.radar import bridge
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.runtime.errors import ConfigError


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    bridge.add_arguments(parser)
    return parser.parse_args(argv)


def test_flags_not_given_take_the_config() -> None:
    cfg = RadarBridgeSettings(sensors=["/dev/ttyUSB1"], device_id=3, baudrate=115200,
                              sim_speed=2.5)
    opts = bridge.resolve_options(parse(), cfg)
    assert (opts.urls, opts.device_id, opts.baudrate, opts.sim_scenario) == (
        ["/dev/ttyUSB1"], 3, 115200, None)


def test_given_flags_win_over_the_config() -> None:
    cfg = RadarBridgeSettings(device_id=3, baudrate=115200, sim_speed=2.5)
    opts = bridge.resolve_options(
        parse("--sim", "--sim-speed", "0.5", "--device-id", "0", "--baudrate", "9600"), cfg)
    # device_id 0 is a real id: it must not fall back to the config's 3.
    assert (opts.device_id, opts.baudrate, opts.sim_scenario, opts.sim_speed) == (
        0, 9600, "visit", 0.5)


@pytest.mark.parametrize(("argv", "flag"), [
    (("--sim", "--sim-speed", "0"), "--sim-speed"),   # would freeze the scenario
    (("--sim", "--sim-speed", "-1"), "--sim-speed"),
    (("--sensor", "/dev/ttyUSB0", "--baudrate", "0"), "--baudrate"),
    (("--sensor", "/dev/ttyUSB0", "--device-id", "-1"), "--device-id"),
])
def test_zero_or_negative_is_refused_naming_the_flag_not_replaced(
        argv: tuple[str, ...], flag: str) -> None:
    # Not `args.x or cfg.x`, which silently turns 0 into the config value.
    with pytest.raises(ConfigError, match=flag):
        bridge.resolve_options(parse(*argv), RadarBridgeSettings())
