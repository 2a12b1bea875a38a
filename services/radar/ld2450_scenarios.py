"""Scripted people for the simulated LD2450: time (s) -> what the sensor would see.

Pure: a scenario is a function of the scenario time and a random source
returning a `Scene`: up to three people in the SENSOR's axes (mm: x across
its face, + = the sensor's right seen from behind it; y away from its
face), with their radial speed (cm/s, + = moving away). The simulator
turns scenes into report frames; the same scenarios drive unit tests and
the end-to-end tests through a pty. With the default mounting pose (the
sensor at the camera, facing forward) the robot's left is -x.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass

Position = tuple[float, float]  # (x_mm, y_mm)


@dataclass(frozen=True)
class Person:
    """One person as the sensor sees them: mm, mm, cm/s (+ = moving away)."""

    x_mm: int
    y_mm: int
    speed_cms: int = 0


@dataclass(frozen=True)
class Scene:
    """What the sensor reports now; `garbage`/`corrupt` model a noisy line."""

    people: tuple[Person, ...] = ()
    garbage: bytes = b""  # bytes the line adds before this frame
    corrupt: bool = False  # send this frame with a broken end
    truncate: bool = False  # send only the first half of this frame


AngleScenario = Callable[[float, random.Random], Scene]
EMPTY = Scene()
_DT = 0.05  # s, for the radial speed by finite difference


def _person(path: Callable[[float], Position], t: float) -> Person:
    """A person on `path` at time t, with the radial speed the sensor measures."""
    x, y = path(t)
    x2, y2 = path(t + _DT)
    speed = (math.hypot(x2, y2) - math.hypot(x, y)) / _DT / 10.0  # mm/s -> cm/s
    return Person(round(x), round(y), round(speed))


def _line(a: Position, b: Position, duration: float) -> Callable[[float], Position]:
    def at(t: float) -> Position:
        f = min(max(t / duration, 0.0), 1.0)
        return a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f
    return at


def crossing(t: float, rng: random.Random) -> Scene:
    """Loop of 10 s: someone walks from the robot's left to its right 1.5 m in
    front (x -3500 -> +3500 mm in 7 s, 1 m/s), then nobody for 3 s."""
    t %= 10.0
    if t >= 7.0:
        return EMPTY
    return Scene((_person(_line((-3500, 1500), (3500, 1500), 7.0), t),))


def walking(t: float, rng: random.Random) -> Scene:
    """Loop of 16 s: walks in from 5 m slightly to the right, stops at 1 m for 6 s
    (still: speed 0), walks back out."""
    t %= 16.0
    if t < 5.0:
        return Scene((_person(_line((800, 5000), (200, 1000), 5.0), t),))
    if t < 11.0:
        return Scene((Person(200 + rng.randint(-20, 20), 1000 + rng.randint(-20, 20)),))
    return Scene((_person(_line((200, 1000), (800, 5000), 5.0), t - 11.0),))


def standing(t: float, rng: random.Random) -> Scene:
    """One person standing still 1.5 m away, a little to the robot's left."""
    return Scene((Person(-600 + rng.randint(-30, 30), 1500 + rng.randint(-30, 30)),))


def two_people(t: float, rng: random.Random) -> Scene:
    """One stands to the robot's right at 2 m; another walks across (loop of 10 s)."""
    still = Person(1200 + rng.randint(-20, 20), 2000 + rng.randint(-20, 20))
    walker = crossing(t, rng).people
    return Scene((still, *walker))


def three_people(t: float, rng: random.Random) -> Scene:
    """Three at once: one crossing from left to right, one walking toward the robot
    and back, one standing; their slots stay in this order (the tracker's job is
    to keep identities when a real sensor swaps them)."""
    t %= 10.0
    cross = _person(_line((-3000, 2500), (3000, 2500), 10.0), t)
    toward = _person(lambda s: (-1500.0, 4000 - 2500 * abs(math.sin(math.pi * s / 10.0))), t)
    still = Person(1500 + rng.randint(-20, 20), 1200 + rng.randint(-20, 20))
    return Scene((cross, toward, still))


def limits(t: float, rng: random.Random) -> Scene:
    """Targets at the edges of the documented field: x -4000/+4000 mm, y 8000 mm."""
    return Scene((Person(-4000, 100), Person(4000, 100), Person(0, 8000)))


def noisy(t: float, rng: random.Random) -> Scene:
    """Someone crossing, on a bad line: garbage, stray heads, broken and cut frames."""
    scene = crossing(t, rng)
    garbage = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8))) \
        if rng.random() < 0.1 else b""
    if rng.random() < 0.05:
        garbage += b"\xaa\xff\x03\x00"  # a stray head in the noise
    return Scene(scene.people, garbage, corrupt=rng.random() < 0.05,
                 truncate=rng.random() < 0.05)


def nobody(t: float, rng: random.Random) -> Scene:
    return EMPTY


ANGLE_SCENARIOS: dict[str, AngleScenario] = {
    "crossing": crossing,
    "walking": walking,
    "standing": standing,
    "two-people": two_people,
    "three-people": three_people,
    "limits": limits,
    "noisy": noisy,
    "nobody": nobody,
}
