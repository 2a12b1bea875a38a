"""The radar test rig: scripted scenes for simulated LD2410s, waits on what the
bridge publishes (frames per sensor, diagnostics values), and angle-radar targets
as the bridge would publish them."""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from typing import Any

import serial
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.radar import envelope, ld2410
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


def ack_of(data: bytes) -> envelope.Ack:
    """The one ACK in `data` (a simulator's answer; either model's envelope)."""
    [frame] = ld2410.Parser().feed(data)
    assert isinstance(frame, envelope.Ack)
    return frame


def cmd(frame: bytes) -> envelope.Command:
    """A command frame as a simulator receives it."""
    [command] = ld2410.Parser().feed(frame)
    assert isinstance(command, envelope.Command)
    return command


def check_any_chunking(make_parser: Callable[[], Any], stream: bytes,
                       frames: list[Any]) -> None:
    """A parser yields exactly `frames` from `stream` split at every byte boundary,
    and fed byte by byte (both models' parsers)."""
    for i in range(len(stream) + 1):
        parser = make_parser()
        got = parser.feed(stream[:i]) + parser.feed(stream[i:])
        assert got == frames, i
        assert parser.stats.bad_frames == 0
    parser = make_parser()
    assert [f for b in stream for f in parser.feed(bytes([b]))] == frames


MUTATIONS = ["intact", "intact", "truncate", "delete", "insert", "overwrite"]


def mutate(draw: Any, frame: bytes, noise: Any, structural: list[int]) -> tuple[bytes, str]:
    """One frame left intact or with exactly one mutation (for both models' fuzz tests):
    cut short, a byte deleted, noise inserted, or a structural byte (head, length,
    markers, tail: `structural` offsets) changed."""
    data = bytearray(frame)
    kind = draw(st.sampled_from(MUTATIONS))
    if kind == "truncate":
        data = data[: draw(st.integers(1, len(data) - 1))]
    elif kind == "delete":
        del data[draw(st.integers(0, len(data) - 1))]
    elif kind == "insert":
        at = draw(st.integers(1, len(data) - 1))
        data[at:at] = draw(noise)
    elif kind == "overwrite":
        at = draw(st.sampled_from(structural))
        data[at] = (data[at] + draw(st.integers(1, 255))) % 256
    return bytes(data), kind


def feed_in_cuts(parser: Any, data: bytes, cuts: list[int]) -> list[Any]:
    """Everything `parser` yields from `data` fed in pieces split at `cuts`."""
    got: list[Any] = []
    last = 0
    for cut in [*cuts, len(data)]:
        got += parser.feed(data[last:cut])
        last = cut
    return got
