"""The `buddybot radar` tool, as a user runs it, against a simulated sensor on a pty."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from buddybot.radar import ld2410 as p
from buddybot.radar.sim import PtySensor, default_parameters
from tests.radar.scripts import LD2410_SCRIPTS, LD2450_SCRIPTS


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
    with PtySensor(LD2410_SCRIPTS["nobody"], link=tmp_path / "mute", answer_commands=False) as mute:
        out = radar("info", "--port", mute.path, "--timeout", "0.3")
    assert out.returncode == 1
    assert "no ACK for 'enable configuration'" in out.stderr


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


# --- LD2450 ------------------------------------------------------------------------------


@pytest.fixture
def angle_sensor(tmp_path: Path):  # type: ignore[no-untyped-def]
    with PtySensor(LD2450_SCRIPTS["three-people"], link=tmp_path / "ttyLD2450",
                   model="LD2450") as sim:
        yield sim


@pytest.mark.integration
def test_tool_ld2450_commands(angle_sensor: PtySensor) -> None:
    from buddybot.radar import ld2450

    sim = angle_sensor.sim
    port = angle_sensor.path
    out = radar("firmware", "--port", port, "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["firmware"] == "V2.02.23090617"
    out = radar("tracking-mode", "single", "--port", port, "--json")
    assert json.loads(out.stdout) == {"tracking_mode": "single"} and sim.tracking_mode == 1
    assert "tracking_mode: single" in radar("tracking-mode", "query", "--port", port).stdout
    assert radar("tracking-mode", "multi", "--port", port).returncode == 0
    assert sim.tracking_mode == 2
    out = radar("set-zones", "--mode", "ignore-inside", "--zone=-500,0,500,1500",
                "--zone", "1000,1000,2000,3000", "--port", port, "--json")
    assert out.returncode == 0, out.stderr
    zones = {"mode": "ignore-inside", "zones": [[-500, 0, 500, 1500], [1000, 1000, 2000, 3000]]}
    assert json.loads(out.stdout) == zones
    assert sim.zone_filter.mode == ld2450.ZONE_IGNORE
    assert json.loads(radar("zones", "--port", port, "--json").stdout) == zones
    assert json.loads(radar("mac", "--port", port, "--json").stdout)["mac"] == "c4:f2:a1:b0:5e:77"
    assert radar("bluetooth", "off", "--port", port).returncode == 0 and not sim.bluetooth
    assert radar("baud-rate", "115200", "--port", port).returncode == 0
    assert sim.baud_index == 5
    assert radar("factory-reset", "--port", port).returncode == 0
    assert sim.factory_resets == 1 and sim.zone_filter.mode == ld2450.ZONE_OFF
    assert radar("restart", "--port", port).returncode == 0 and sim.restarts == 1


@pytest.mark.parametrize("zones", [
    ["1,2,3"], ["a,b,c,d"], ["0,0,40000,1"], ["0,0,1,1"] * 4,
])
def test_bad_zones_are_refused_before_the_port_is_opened(zones: list[str]) -> None:
    from buddybot.radar import tool

    with pytest.raises(p.ProtocolError):
        tool.zone_filter("detect-only-inside", zones)


def test_zones_from_the_command_line() -> None:
    from buddybot.radar import ld2450, tool

    zf = tool.zone_filter("ignore-inside", ["-500,0,500,1500"])
    assert zf.mode == ld2450.ZONE_IGNORE
    assert zf.zones == (ld2450.Zone(-500, 0, 500, 1500), ld2450.EMPTY_ZONE, ld2450.EMPTY_ZONE)
