"""Scripted people for the simulated LD2410: time (s) -> what the sensor would see.

Pure: a scenario is a function of the scenario time and a random source,
returning a `Target` (or a NO_TARGET one). The simulator turns targets
into report frames; the same scenarios drive unit tests of the presence
rule and the end-to-end tests through a pty.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass

NO_TARGET, MOVING, STILL, BOTH = 0, 1, 2, 3


@dataclass(frozen=True)
class Target:
    """What the sensor reports about the scene (distances cm, energies 0..100+)."""

    state: int = NO_TARGET
    moving_cm: int = 0
    moving_energy: int = 0
    still_cm: int = 0
    still_energy: int = 0
    detection_cm: int = 0
    garbage: bytes = b""  # bytes the noisy line adds before this frame
    corrupt: bool = False  # send this frame with a broken tail


Scenario = Callable[[float, random.Random], Target]

NOBODY = Target()


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


SCENARIOS: dict[str, Scenario] = {
    "visit": visit,
    "walk-in": walk_in,
    "passer-by": passer_by,
    "noisy": noisy,
    "nobody": nobody,
}
