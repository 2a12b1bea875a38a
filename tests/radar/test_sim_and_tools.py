"""The simulated sensor (pure and on a real pty), conversion, and `buddybot radar` tools."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import msgspec
import pytest
import serial

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import ld2410 as p
from buddybot.radar.client import LD2410Client, RadarError
from buddybot.radar.convert import report_to_frame
from buddybot.radar.scenarios import SCENARIOS, Target
from buddybot.radar.sim import PtySensor, SimulatedLD2410, default_parameters

# --- the simulator's protocol state (pure) ----------------------------------------------


def ack_of(data: bytes) -> p.Ack:
    [frame] = p.Parser().feed(data)
    assert isinstance(frame, p.Ack)
    return frame


def cmd(frame: bytes) -> p.Command:
    [command] = p.Parser().feed(frame)
    assert isinstance(command, p.Command)
    return command


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
    sim = SimulatedLD2410(SCENARIOS["noisy"], seed=5)
    parser = p.Parser()
    reports = [f for i in range(500) for f in parser.feed(sim.report(i * 0.1, i * 0.1))]
    assert 400 < len(reports) < 500
    assert parser.stats.bad_frames > 0


# --- conversion to the contract ---------------------------------------------------------


def test_energies_above_100_are_clamped_and_counted() -> None:
    report = p.Report(3, 120, 130, 140, 255, 125, engineering=True, max_moving_gate=8,
                      max_still_gate=8, moving_gate_energy=(101, *range(8)),
                      still_gate_energy=(*range(8), 200), light_level=80, out_pin=1)
    frame, clamped, _ = report_to_frame(report, 2)
    assert clamped == 4
    assert frame.movement_energy == 100 and frame.stationary_energy == 100
    assert frame.moving_gate_energy is not None and frame.moving_gate_energy[0] == 100
    assert frame.stationary_gate_energy is not None and frame.stationary_gate_energy[8] == 100
    assert (frame.radar_id, frame.movement_distance, frame.stationary_distance) == (2, 120, 140)
    msg = m.LD2410TargetDataFrameArray(stamp_ns=1, device_id=0, sensors=[frame])
    codec = keys.RADAR_FRAMES.codec
    assert codec.decode(codec.encode(msg), m.LD2410TargetDataFrameArray) == msg


def test_basic_report_has_no_engineering_fields() -> None:
    frame, clamped, _ = report_to_frame(p.Report(2, 0, 0, 300, 60, 300), 0)
    assert clamped == 0 and frame.target_state == m.TargetState.STATIONARY
    assert frame.moving_gate_energy is None and frame.light_level is None


def _engineering(light: int, out: int, state: int = 1) -> p.Report:
    return p.Report(state, 120, 50, 0, 0, 120, engineering=True, max_moving_gate=8,
                    max_still_gate=8, moving_gate_energy=(1,) * 9, still_gate_energy=(2,) * 9,
                    light_level=light, out_pin=out)


def test_light_and_out_only_from_firmware_that_has_them() -> None:
    """V1.07 sends two bytes there that are not light/OUT (a real module: OUT 33)."""
    v1 = report_to_frame(_engineering(120, 33), 0, light_and_out=False)
    assert (v1.frame.light_level, v1.frame.out_pin, v1.bad_out_pin) == (None, None, False)
    v2 = report_to_frame(_engineering(120, 1), 0, light_and_out=True)
    assert (v2.frame.light_level, v2.frame.out_pin, v2.bad_out_pin) == (120, 1, False)
    odd = report_to_frame(_engineering(120, 33), 0, light_and_out=True)
    assert (odd.frame.light_level, odd.frame.out_pin, odd.bad_out_pin) == (120, None, True)


@pytest.mark.parametrize("state", [4, 5, 6])
def test_noise_detection_states_convert_to_the_contract(state: int) -> None:
    frame = report_to_frame(p.Report(state, 0, 0, 0, 0, 0), 0).frame
    assert frame.target_state == m.TargetState(state)
    codec = keys.RADAR_FRAMES.codec
    msg = m.LD2410TargetDataFrameArray(stamp_ns=1, device_id=0, sensors=[frame])
    assert codec.decode(codec.encode(msg), m.LD2410TargetDataFrameArray) == msg


def test_out_of_contract_message_is_refused_at_decode() -> None:
    """Why we clamp: a subscriber would drop this message."""
    raw = b'{"stamp_ns":1,"device_id":0,"sensors":[{"radar_id":0,"target_state":1,' \
          b'"movement_distance":1,"movement_energy":101,"stationary_distance":0,' \
          b'"stationary_energy":0,"detection_distance":1}]}'
    with pytest.raises(msgspec.ValidationError):
        keys.RADAR_FRAMES.codec.decode(raw, m.LD2410TargetDataFrameArray)


# --- on a real pseudo-terminal ----------------------------------------------------------


@pytest.fixture
def sensor(tmp_path: Path):  # type: ignore[no-untyped-def]
    with PtySensor("walk-in", link=tmp_path / "ttyLD2410") as sim:
        yield sim


def _open(path: str) -> serial.Serial:
    return serial.serial_for_url(path, baudrate=256000, timeout=0.05)


def test_client_over_a_pty(sensor: PtySensor) -> None:
    port = _open(sensor.path)
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
    port = _open(sensor.path)
    try:
        client = LD2410Client(port)
        with pytest.raises(RadarError), client.configuring():
            client.command(p.encode_command(0x0077), 0x0077)
        assert sensor.sim.commands[-1] == p.CMD_END_CONFIG
        assert not sensor.sim.config_mode
    finally:
        port.close()


def test_unplug_and_replug_behind_the_same_path(sensor: PtySensor) -> None:
    port = _open(sensor.path)
    sensor.unplug()
    with pytest.raises(serial.SerialException):
        end = time.monotonic() + 10
        while time.monotonic() < end:
            port.read(64)
    port.close()
    assert not Path(sensor.path).exists()
    sensor.replug()
    port = _open(sensor.path)
    try:
        parser = p.Parser()
        end = time.monotonic() + 10
        got: list[p.Frame] = []
        while not got and time.monotonic() < end:
            got = parser.feed(port.read(64))
        assert got
    finally:
        port.close()


# --- the `buddybot radar` tool, as a user runs it ---------------------------------------


def radar(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "buddybot", "radar", *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.integration
def test_tool_info(sensor: PtySensor) -> None:
    out = radar("info", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert info["firmware"] == "V1.07.22091615"
    assert info["parameters"]["max_moving_gate"] == 8
    assert info["parameters"]["moving_sensitivity"] == [50, 50, 40, 30, 20, 15, 15, 15, 15]
    assert info["resolution_m"] == 0.75
    words = sensor.sim.commands
    assert words[0] == p.CMD_ENABLE_CONFIG and words[-1] == p.CMD_END_CONFIG
    text = radar("info", "--port", sensor.path)
    assert "firmware: V1.07.22091615" in text.stdout


@pytest.mark.integration
def test_tool_settings_change_the_sensor(sensor: PtySensor) -> None:
    sim = sensor.sim
    assert radar("engineering", "off", "--port", sensor.path).returncode == 0
    assert not sim.engineering
    assert radar("engineering", "on", "--port", sensor.path).returncode == 0
    assert sim.engineering
    out = radar("set-gates", "--moving", "6", "--duration", "30", "--json", "--port",
                sensor.path)
    assert out.returncode == 0, out.stderr
    params = json.loads(out.stdout)["parameters"]
    assert (params["max_moving_gate"], params["max_still_gate"],
            params["no_one_duration_s"]) == (6, 8, 30)
    assert radar("set-sensitivity", "--port", sensor.path, "--gate", "3", "--moving", "70",
                 "--still", "60").returncode == 0
    assert sim.params.moving_sensitivity[3] == 70 and sim.params.still_sensitivity[3] == 60
    assert radar("set-sensitivity", "--port", sensor.path, "--gate", "all", "--moving", "33",
                 "--still", "22").returncode == 0
    assert set(sim.params.moving_sensitivity) == {33}
    assert set(sim.params.still_sensitivity) == {22}
    assert radar("set-resolution", "0.2", "--port", sensor.path).returncode == 0
    assert sim.resolution_index == 1
    assert radar("factory-reset", "--port", sensor.path).returncode == 0
    assert sim.factory_resets == 1 and sim.params == default_parameters()
    assert radar("restart", "--port", sensor.path).returncode == 0
    assert sim.restarts == 1


@pytest.mark.integration
def test_tool_errors_are_clear(sensor: PtySensor, tmp_path: Path) -> None:
    out = radar("set-gates", "--moving", "9", "--port", sensor.path)
    assert out.returncode == 2 and "max gates must be 2..8" in out.stderr
    assert not sensor.sim.config_mode  # configuration was ended
    out = radar("set-sensitivity", "--port", sensor.path, "--gate", "x", "--moving", "1",
                "--still", "1")
    assert out.returncode == 2 and "--gate" in out.stderr
    out = radar("info", "--port", str(tmp_path / "nothing-here"))
    assert out.returncode == 1 and "cannot open" in out.stderr
    out = radar("info")
    assert out.returncode == 2 and "--port" in out.stderr
    # 0 is no serial speed: refused, not silently replaced by the config's 256000
    # (a pty ignores the speed, so only this check can tell).
    out = radar("info", "--port", sensor.path, "--baudrate", "0")
    assert out.returncode == 2 and "--baudrate" in out.stderr


@pytest.mark.integration
def test_tool_reports_a_sensor_that_does_not_ack(tmp_path: Path) -> None:
    with PtySensor("nobody", link=tmp_path / "mute", answer_commands=False) as mute:
        out = radar("info", "--port", mute.path, "--timeout", "0.3")
    assert out.returncode == 1
    assert "no ACK for 'enable configuration'" in out.stderr


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


@pytest.mark.integration
def test_tool_baud_rate_bluetooth_and_mac(sensor: PtySensor) -> None:
    sim = sensor.sim
    out = radar("baud-rate", "115200", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    assert sim.baud_index == p.BAUD_RATES[115200]
    assert "--baudrate 115200" in json.loads(out.stdout)["note"]
    assert radar("bluetooth", "off", "--port", sensor.path).returncode == 0
    assert sim.bluetooth is False
    assert radar("bluetooth", "on", "--port", sensor.path).returncode == 0
    assert sim.bluetooth is True
    out = radar("mac", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == {"mac": "8f:27:c6:d9:1a:3b"}
    assert p.CMD_SET_BAUD_RATE in sim.commands and p.CMD_BLUETOOTH in sim.commands
    assert sim.commands[-1] == p.CMD_END_CONFIG and not sim.config_mode
    out = radar("baud-rate", "12345", "--port", sensor.path)
    assert out.returncode == 2 and "invalid choice" in out.stderr


@pytest.mark.integration
def test_tool_background_noise_detection(sensor: PtySensor) -> None:
    sim = sensor.sim
    out = radar("noise-status", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == {"noise_detection": "not started"}
    out = radar("auto-thresholds", "--duration", "1", "--wait", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == {"noise_detection": "completed"}
    assert p.CMD_AUTO_THRESHOLDS in sim.commands and p.CMD_AUTO_THRESHOLDS_STATUS in sim.commands
    assert sim.commands[-1] == p.CMD_END_CONFIG and not sim.config_mode
    out = radar("noise-status", "--port", sensor.path)
    assert out.returncode == 0 and "noise_detection: completed" in out.stdout
    before = len(sim.commands)
    out = radar("auto-thresholds", "--duration", "0", "--port", sensor.path)
    assert out.returncode == 2 and "1..65535" in out.stderr
    assert len(sim.commands) == before  # refused before the port was touched


@pytest.mark.integration
def test_tool_bluetooth_password_and_permissions(sensor: PtySensor) -> None:
    sim = sensor.sim
    assert radar("bluetooth-auth", "--password", "HiLink", "--port", sensor.path).returncode == 0
    assert sim.bluetooth_authorised
    out = radar("bluetooth-auth", "--password", "wrong!", "--port", sensor.path)
    assert out.returncode == 1 and "refused 'bluetooth authentication" in out.stderr
    assert not sim.config_mode  # ended even though the command was refused
    out = radar("bluetooth-password", "abc123", "--port", sensor.path, "--json")
    assert out.returncode == 0, out.stderr
    assert sim.bluetooth_password == "abc123"
    assert radar("bluetooth-auth", "--password", "abc123", "--port", sensor.path).returncode == 0
    for bad in ("short", "toolong7", "tab\tx12"):
        out = radar("bluetooth-password", bad, "--port", sensor.path)
        assert out.returncode == 2 and "6 printable ASCII" in out.stderr, bad
    assert sim.bluetooth_password == "abc123"
