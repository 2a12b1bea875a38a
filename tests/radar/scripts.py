"""Scripted sensor inputs for the radar tests: time -> what an LD2410 or LD2450 reports.

The product's simulated radars render the simulated world (`buddybot.sim`);
these scripts are the tests' own inputs where a test needs exact frames: a
person at a known distance at a known moment, line noise, edge-of-field
targets. Pure: each is a function of the scenario time and a random source.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable

from buddybot.radar.sim_scene import (
    BOTH,
    EMPTY,
    MOVING,
    NOBODY,
    STILL,
    AngleScript,
    Person,
    Scene,
    Script,
    Target,
)

Position = tuple[float, float]  # (x_mm, y_mm)
_DT = 0.05  # s, for the radial speed by finite difference


# -- LD2410: one target, distances and energies --

def _walking(cm: float) -> Target:
    d = round(cm)
    return Target(MOVING, d, 60, d, 20, d)


def _standing(cm: float) -> Target:
    d = round(cm)
    return Target(STILL, d, 5, d, 70, d)


def _lerp(a: float, b: float, t: float, duration: float) -> float:
    return a + (b - a) * min(max(t / duration, 0.0), 1.0)


def visit(t: float, rng: random.Random) -> Target:
    """Loop of 38 s: walks in from 4 m (4 s), stands at 1 m (20 s), leaves (4 s), away 10 s.

    About 23 s within 2 m per loop: the whole-robot demo greets, follows and
    says goodbye once per loop."""
    t %= 38.0
    if t < 4.0:
        return _walking(_lerp(400, 100, t, 4.0))
    if t < 24.0:
        return _standing(100 + rng.randint(-5, 5))
    if t < 28.0:
        return _walking(_lerp(100, 400, t - 24.0, 4.0))
    return NOBODY


def walk_in(t: float, rng: random.Random) -> Target:
    """Once: nobody 0.5 s, walks in from 4 m (3 s), stands at 1 m (4 s), leaves (3 s), nobody.

    Within 2 m from t = 2.5 s: before a freshly started presence service's
    first "nobody" verdict (after its 3 s absence hold), so a visit that
    starts with the sensor reads as exactly one arrival and one departure."""
    if t < 0.5:
        return NOBODY
    t -= 0.5
    if t < 3.0:
        return _walking(_lerp(400, 100, t, 3.0))
    if t < 7.0:
        return _standing(100)
    if t < 10.0:
        return _walking(_lerp(100, 400, t - 7.0, 3.0))
    return NOBODY


def passer_by(t: float, rng: random.Random) -> Target:
    """Loop of 12 s: someone walks past at 2.6-3.2 m (never within 2 m), then nobody."""
    t %= 12.0
    if 3.0 <= t < 9.0:
        return _walking(260 + abs(t - 6.0) * 20)
    return NOBODY


def noisy(t: float, rng: random.Random) -> Target:
    """A person at ~1.5 m on a bad sensor: distance jitter, NO_TARGET blips,
    MOVING/STILL flicker, energies above 100, garbage and corrupted frames."""
    if rng.random() < 0.2:
        target = NOBODY
    else:
        d = 150 + rng.randint(-40, 40)
        state = rng.choice((STILL, STILL, BOTH, MOVING))
        energy = rng.choice((70, 90, 130))  # real modules send >100 now and then
        target = Target(state, d, 40, d, energy, d)
    garbage = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8))) \
        if rng.random() < 0.1 else b""
    if rng.random() < 0.05:
        garbage += b"\xf4\xf3\xf2\xf1"  # a stray header in the noise
    return Target(**{**target.__dict__, "garbage": garbage, "corrupt": rng.random() < 0.05})


def nobody(t: float, rng: random.Random) -> Target:
    return NOBODY


LD2410_SCRIPTS: dict[str, Script] = {
    "visit": visit,
    "walk-in": walk_in,
    "passer-by": passer_by,
    "noisy": noisy,
    "nobody": nobody,
}


# -- LD2450: up to three people in the sensor's axes --

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


def angle_two_people(t: float, rng: random.Random) -> Scene:
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


def angle_noisy(t: float, rng: random.Random) -> Scene:
    """Someone crossing, on a bad line: garbage, stray heads, broken and cut frames."""
    scene = crossing(t, rng)
    garbage = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8))) \
        if rng.random() < 0.1 else b""
    if rng.random() < 0.05:
        garbage += b"\xaa\xff\x03\x00"  # a stray head in the noise
    return Scene(scene.people, garbage, corrupt=rng.random() < 0.05,
                 truncate=rng.random() < 0.05)


def angle_nobody(t: float, rng: random.Random) -> Scene:
    return EMPTY


LD2450_SCRIPTS: dict[str, AngleScript] = {
    "crossing": crossing,
    "walking": walking,
    "standing": standing,
    "two-people": angle_two_people,
    "three-people": three_people,
    "limits": limits,
    "noisy": angle_noisy,
    "nobody": angle_nobody,
}
