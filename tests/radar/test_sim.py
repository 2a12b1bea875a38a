"""The simulated LD2410: its protocol state (pure), and the sensor on a real pty."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import serial

from buddybot.radar import ld2410 as p
from buddybot.radar.sim import PtySensor, SimulatedLD2410
from buddybot.radar.sim_scene import Target
from tests.radar.rig import ack_of, check_noisy_stream, cmd, open_port
from tests.radar.scripts import LD2410_SCRIPTS as SCENARIOS


def test_sim_needs_configuration_mode_and_answers_like_the_protocol() -> None:
    sim = SimulatedLD2410(SCENARIOS["nobody"])
    assert not ack_of(sim.handle(cmd(p.read_parameters()), 0.0)).ok
    enable = ack_of(sim.handle(cmd(p.enable_config()), 0.0))
    assert enable.ok and p.decode_enable(enable.data).protocol_version == 1
    assert sim.report(0.0, 0.0) == b""  # no reports while configuring
    assert ack_of(sim.handle(cmd(p.set_max_gates(5, 6, 20)), 0.0)).ok
    params = p.decode_parameters(ack_of(sim.handle(cmd(p.read_parameters()), 0.0)).data)
    assert (params.max_moving_gate, params.max_still_gate, params.no_one_duration_s) == (5, 6, 20)
    bad = p.encode_command(p.CMD_SET_MAX_GATES, bytes(5))
    assert not ack_of(sim.handle(cmd(bad), 0.0)).ok
    assert not ack_of(sim.handle(cmd(p.encode_command(0x0077)), 0.0)).ok
    assert ack_of(sim.handle(cmd(p.end_config()), 0.0)).ok
    assert sim.report(0.0, 0.0) != b""


def test_sim_restart_goes_quiet_and_leaves_engineering_mode() -> None:
    sim = SimulatedLD2410(SCENARIOS["nobody"], engineering=True)
    sim.handle(cmd(p.enable_config()), 0.0)
    assert ack_of(sim.handle(cmd(p.restart()), 10.0)).ok
    assert sim.report(0.0, 10.1) == b""
    [frame] = p.Parser().feed(sim.report(0.0, 11.0))
    assert isinstance(frame, p.Report) and not frame.engineering


def test_sim_engineering_frames_put_energy_in_the_right_gate() -> None:
    sim = SimulatedLD2410(lambda t, rng: Target(3, 160, 77, 300, 88, 160))
    [frame] = p.Parser().feed(sim.report(0.0, 0.0))
    assert isinstance(frame, p.Report) and frame.engineering
    assert frame.moving_gate_energy is not None and frame.still_gate_energy is not None
    assert frame.moving_gate_energy[160 // 75] == 77
    assert frame.still_gate_energy[300 // 75] == 88


def test_noisy_scenario_stream_is_survivable() -> None:
    check_noisy_stream(SimulatedLD2410(SCENARIOS["noisy"], seed=5), p.Parser())


def test_sim_background_noise_detection_reports_states_4_to_6() -> None:
    sim = SimulatedLD2410(SCENARIOS["walk-in"], engineering=False)
    sim.handle(cmd(p.enable_config()), 0.0)
    status = ack_of(sim.handle(cmd(p.query_auto_thresholds()), 0.0))
    assert p.decode_auto_thresholds_status(status.data) == "not started"
    assert ack_of(sim.handle(cmd(p.start_auto_thresholds(2)), 0.0)).ok
    sim.handle(cmd(p.end_config()), 0.0)
    states = []
    for now in (0.5, 1.9, 2.1, 2.9):
        [frame] = p.Parser().feed(sim.report(5.0, now))
        assert isinstance(frame, p.Report)
        states.append(frame.target_state)
    assert states == [4, 4, 5, 5]
    [after] = p.Parser().feed(sim.report(5.0, 3.5))
    assert isinstance(after, p.Report) and after.target_state in (1, 2, 3)  # the person again
    sim.handle(cmd(p.enable_config()), 4.0)
    status = ack_of(sim.handle(cmd(p.query_auto_thresholds()), 4.0))
    assert p.decode_auto_thresholds_status(status.data) == "completed"


# --- on a real pseudo-terminal ---------------------------------------------------------


def test_unplug_and_replug_behind_the_same_path(sensor: PtySensor) -> None:
    port = open_port(sensor.path)
    sensor.unplug()
    with pytest.raises(serial.SerialException):
        end = time.monotonic() + 10
        while time.monotonic() < end:
            port.read(64)
    port.close()
    assert not Path(sensor.path).exists()
    sensor.replug()
    port = open_port(sensor.path)
    try:
        parser = p.Parser()
        end = time.monotonic() + 10
        got: list[p.Frame] = []
        while not got and time.monotonic() < end:
            got = parser.feed(port.read(64))
        assert got
    finally:
        port.close()
