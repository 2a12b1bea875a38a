"""The radar bridge's part of `buddybot doctor`: its serial ports, its frame rate."""

from __future__ import annotations

import os
from collections.abc import Sequence

from buddybot.contract import keys
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.runtime.health import FAIL, OK, Check, DoctorHooks, Rate

RADAR_HZ = 10.0
"""An LD2410 reports about 10 times a second (the simulator too)."""


def check_serial(sensors: Sequence[str], sim: bool) -> list[Check]:
    """Each configured radar's serial port present and usable."""
    if sim or not sensors:
        return [Check("radar serial", OK, "simulated (no serial port needed)")]
    checks = []
    for i, url in enumerate(sensors):
        name = f"radar serial {i}"
        if "://" in url:
            checks.append(Check(name, OK, f"{url}: network serial, not opened here"))
        elif not os.path.exists(url):
            checks.append(Check(name, FAIL, f"{url} does not exist (unplugged? wrong name?)"))
        elif not os.access(url, os.R_OK | os.W_OK):
            checks.append(Check(name, FAIL, f"{url}: no read/write permission "
                                "(add the user to the dialout group)"))
        else:
            checks.append(Check(name, OK, f"{url} present"))
    return checks


def _devices(settings: RadarBridgeSettings, sim: bool, _in_use: bool) -> list[Check]:
    return check_serial(list(settings.sensors), sim or settings.sim)


def _rate(_settings: RadarBridgeSettings | None) -> Rate:
    return Rate("radar frames", keys.RADAR_FRAMES.wildcard(), RADAR_HZ)


BRIDGE = DoctorHooks(devices=_devices, rate=_rate)
