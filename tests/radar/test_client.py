"""The LD2410 client over a real pty to the simulated sensor: configuration mode
entered and always ended, answers read, refusals raised."""

from __future__ import annotations

import time

import pytest

from buddybot.radar import ld2410 as p
from buddybot.radar.client import LD2410Client, RadarError
from buddybot.radar.sim import PtySensor
from tests.radar.rig import open_port


def test_client_over_a_pty(sensor: PtySensor) -> None:
    port = open_port(sensor.path)
    try:
        client = LD2410Client(port)
        with client.configuring() as info:
            assert info.protocol_version == 1
            assert client.read_firmware() == "V1.07.22091615"
            assert client.read_parameters().no_one_duration_s == 5
            client.set_resolution(0.2)
            assert client.read_resolution() == 0.2
            assert client.read_mac() == "8f:27:c6:d9:1a:3b"
            with pytest.raises(RadarError, match="refused 'set max gates"):
                client.command(p.encode_command(p.CMD_SET_MAX_GATES, bytes(3)),
                               p.CMD_SET_MAX_GATES)
        assert not sensor.sim.config_mode
        # Reports flow again after end configuration.
        parser = p.Parser()
        end = time.monotonic() + 10
        got: list[p.Frame] = []
        while not got and time.monotonic() < end:
            got = [f for f in parser.feed(port.read(64)) if isinstance(f, p.Report)]
        assert got
    finally:
        port.close()


def test_client_ends_configuration_even_when_a_command_fails(sensor: PtySensor) -> None:
    port = open_port(sensor.path)
    try:
        client = LD2410Client(port)
        with pytest.raises(RadarError), client.configuring():
            client.command(p.encode_command(0x0077), 0x0077)
        assert sensor.sim.commands[-1] == p.CMD_END_CONFIG
        assert not sensor.sim.config_mode
    finally:
        port.close()
