"""The simulated LD2450: its protocol state (pure), and the sensor on a real pty."""

from __future__ import annotations

import time

from buddybot.radar import envelope as e
from buddybot.radar import ld2450 as p
from buddybot.radar.ld2450_sim import SimulatedLD2450
from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import Person, Scene
from tests.radar.rig import ack_of, check_noisy_stream, cmd, open_port
from tests.radar.scripts import LD2450_SCRIPTS


def three(t: float, rng: object) -> Scene:
    return Scene((Person(-1000, 1000, 10), Person(0, 2000), Person(1000, 3000, -20)))


def reported(sim: SimulatedLD2450, now: float = 100.0) -> list[tuple[int, int]]:
    [frame] = p.Parser().feed(sim.report(0.0, now))
    assert isinstance(frame, p.Report)
    return [(t.x_mm, t.y_mm) for _, t in frame.targets()]


def test_reports_every_person_in_sensor_axes() -> None:
    sim = SimulatedLD2450(three)
    assert reported(sim) == [(-1000, 1000), (0, 2000), (1000, 3000)]


def test_commands_need_configuration_mode_and_change_what_is_reported() -> None:
    sim = SimulatedLD2450(three)
    assert not ack_of(sim.handle(cmd(p.single_target()), 0.0)).ok
    enable = ack_of(sim.handle(cmd(e.enable_config()), 0.0))
    assert enable.ok and e.decode_enable(enable.data).buffer_size == 0x40
    assert sim.report(0.0, 0.0) == b""  # silent while configuring
    assert ack_of(sim.handle(cmd(p.single_target()), 0.0)).ok
    mode = ack_of(sim.handle(cmd(p.query_tracking_mode()), 0.0))
    assert p.decode_tracking_mode(mode.data) == "single"
    zf = p.ZoneFilter(p.ZONE_IGNORE, (p.Zone(-1500, 0, -500, 1500), p.EMPTY_ZONE, p.EMPTY_ZONE))
    assert ack_of(sim.handle(cmd(p.set_zone_filter(zf)), 0.0)).ok
    assert p.decode_zone_filter(ack_of(sim.handle(cmd(p.query_zone_filter()), 0.0)).data) == zf
    assert ack_of(sim.handle(cmd(e.end_config()), 0.0)).ok
    assert reported(sim) == [(0, 2000)]  # the first is ignored, single mode keeps one
    sim.handle(cmd(e.enable_config()), 0.0)
    sim.handle(cmd(p.multi_target()), 0.0)
    only = p.ZoneFilter(p.ZONE_DETECT_ONLY, (p.Zone(500, 2500, 1500, 3500),) + (p.EMPTY_ZONE,) * 2)
    sim.handle(cmd(p.set_zone_filter(only)), 0.0)
    sim.handle(cmd(e.end_config()), 0.0)
    assert reported(sim) == [(1000, 3000)]


def test_firmware_mac_bluetooth_baud_restart_and_factory_reset() -> None:
    sim = SimulatedLD2450(three)
    sim.handle(cmd(e.enable_config()), 0.0)
    firmware = ack_of(sim.handle(cmd(e.read_firmware()), 0.0))
    assert e.decode_firmware(firmware.data) == "V2.02.23090617"
    assert e.decode_mac(ack_of(sim.handle(cmd(e.read_mac()), 0.0)).data) == "c4:f2:a1:b0:5e:77"
    sim.handle(cmd(e.bluetooth(False)), 0.0)
    assert e.decode_mac(ack_of(sim.handle(cmd(e.read_mac()), 0.0)).data) == p.BLUETOOTH_OFF_MAC
    assert ack_of(sim.handle(cmd(e.set_baud_rate(115200)), 0.0)).ok and sim.baud_index == 5
    assert not ack_of(sim.handle(cmd(e.encode_command(e.CMD_SET_BAUD_RATE, b"\x09\x00")),
                                 0.0)).ok
    assert not ack_of(sim.handle(cmd(e.encode_command(p.CMD_SET_ZONE_FILTER, b"\x01")), 0.0)).ok
    assert not ack_of(sim.handle(cmd(e.encode_command(0x0077)), 0.0)).ok
    assert ack_of(sim.handle(cmd(e.factory_reset()), 0.0)).ok
    assert sim.baud_index == 7 and sim.tracking_mode == 2 and sim.factory_resets == 1
    assert ack_of(sim.handle(cmd(e.restart()), 10.0)).ok
    assert not sim.config_mode and sim.report(0.0, 10.1) == b""
    assert reported(sim, 11.0)


def test_silent_sensor_never_answers() -> None:
    sim = SimulatedLD2450(three, answer_commands=False)
    assert sim.handle(cmd(e.enable_config()), 0.0) == b""


def test_noisy_scenario_stream_is_survivable() -> None:
    check_noisy_stream(SimulatedLD2450(LD2450_SCRIPTS["noisy"], seed=5), p.Parser())


def test_ld2450_on_a_real_pty_answers_commands_and_reports() -> None:
    with PtySensor(LD2450_SCRIPTS["three-people"], model="LD2450", speed=1.0) as sensor:
        port = open_port(sensor.path)
        try:
            parser = p.Parser()
            frames: list[p.Frame] = []
            end = time.monotonic() + 10
            while not any(isinstance(f, p.Report) for f in frames) and time.monotonic() < end:
                frames += parser.feed(port.read(64))
            report = next(f for f in frames if isinstance(f, p.Report))
            assert len(report.targets()) == 3
            port.write(e.enable_config())
            acks: list[p.Ack] = []
            end = time.monotonic() + 10
            while not acks and time.monotonic() < end:
                acks = [f for f in parser.feed(port.read(64)) if isinstance(f, p.Ack)]
            assert acks[0].command == e.CMD_ENABLE_CONFIG and acks[0].ok
            port.write(e.end_config())
        finally:
            port.close()
