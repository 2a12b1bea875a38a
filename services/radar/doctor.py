"""The radar bridge's part of `buddybot doctor`: its serial ports, its report rate.

What the bridge publishes depends on the model of each sensor: an LD2410
sends `frames`, an LD2450 `targets`. So the rate doctor counts follows the
configured models (the simulated sensor's `sim_model` when simulated); a
sensor left to be recognised at connect may send either, and both count.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from buddybot.contract import keys
from buddybot.radar.models import AUTO, LD2410, LD2450
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.runtime.health import FAIL, OK, Check, DoctorHooks, Rate

RADAR_HZ = 10.0
"""An LD2410 or an LD2450 reports about 10 times a second (the simulator too)."""


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


def sensor_models(settings: RadarBridgeSettings, sim: bool) -> list[str]:
    """Each sensor's configured model (`AUTO`: recognised at connect), as the bridge
    will run: simulated (`--sim`, `sim`, or no sensor configured), only the
    simulated sensor, of `sim_model`."""
    if sim or settings.sim or not settings.sensors:
        return [settings.sim_model]
    return [settings.models.get(str(i), AUTO) for i in range(len(settings.sensors))]


def expected_rates(models: Sequence[str]) -> list[Rate]:
    """The streams a bridge with sensors of these models publishes (pure)."""
    frames, targets = keys.RADAR_FRAMES.wildcard(), keys.RADAR_TARGETS.wildcard()
    rates = []
    if LD2410 in models:
        rates.append(Rate("radar frames", frames, RADAR_HZ))
    if LD2450 in models:
        rates.append(Rate("radar targets", targets, RADAR_HZ))
    if AUTO in models and not rates:
        rates.append(Rate("radar reports", frames, RADAR_HZ, also=(targets,)))
    return rates


def _rates(settings: RadarBridgeSettings | None, sim: bool) -> list[Rate]:
    return expected_rates(sensor_models(settings or RadarBridgeSettings(), sim))


BRIDGE = DoctorHooks(devices=_devices, rates=_rates)
