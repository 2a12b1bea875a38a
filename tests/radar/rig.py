"""The radar test rig: scripted scenes for simulated LD2410s, waits on what the
bridge publishes (frames per sensor, diagnostics values), and angle-radar targets
as the bridge would publish them."""

from __future__ import annotations

import math
import random

import serial

from buddybot.contract import messages as m
from buddybot.radar.scenarios import NOBODY, Scenario, Target
from buddybot.radar.sim import PtySensor
from buddybot.tools.testing import Collector, retry_until


class Gated:
    """A scenario that shows nobody until `go()`, then plays `inner` from its start."""

    def __init__(self, inner: Scenario) -> None:
        self.inner = inner
        self.started: float | None = None
        self.sensor: PtySensor | None = None

    def __call__(self, t: float, rng: random.Random) -> Target:
        if self.started is None:
            return NOBODY
        return self.inner(t - self.started, rng)

    def go(self) -> None:
        assert self.sensor is not None
        self.started = self.sensor.scenario_time()


def standing(t: float, rng: random.Random) -> Target:
    """A person standing still 1.00 m away (STATIONARY at 100 cm)."""
    return Target(2, 100, 5, 100, 70, 100)


def frames_of(collector: Collector[m.LD2410TargetDataFrameArray], radar_id: int) -> int:
    return sum(1 for msg in collector.messages for f in msg.sensors if f.radar_id == radar_id)


def wait_more_frames(collector: Collector[m.LD2410TargetDataFrameArray], radar_id: int, n: int,
                     timeout: float = 20.0) -> None:
    start = frames_of(collector, radar_id)
    retry_until(lambda: frames_of(collector, radar_id) >= start + n, timeout,
                what=f"{n} more frames from radar {radar_id}")


def diag_value(msg: m.DiagnosticStatus, name: str) -> object:
    return msg.values.get(name)


def open_port(path: str) -> serial.Serial:
    """The serial port of a simulated sensor, as the bridge opens a real one."""
    return serial.serial_for_url(path, baudrate=256000, timeout=0.05)


def radar_target(x: float, y: float, speed: float = 0.0, slot: int = 0) -> m.RadarTarget:
    """An LD2450 target at (x forward, y left) metres in the camera's frame, the
    sensor mounted at the camera facing forward (its y axis = forward)."""
    return m.RadarTarget(slot=slot, x_m=-y, y_m=x, speed_mps=speed, resolution_m=0.36,
                         position=m.Point(x=x, y=y, z=0.0), bearing_rad=math.atan2(y, x),
                         distance_m=math.hypot(x, y))
