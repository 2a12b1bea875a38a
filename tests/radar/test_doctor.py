"""The radar bridge's doctor checks (its serial ports) on crafted files: no radar."""

from __future__ import annotations

import os
from pathlib import Path

from buddybot.radar.doctor import BRIDGE, check_serial
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
