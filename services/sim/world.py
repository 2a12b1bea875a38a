"""The simulated world at a moment: every person's position, velocity and facing (pure).

`World(scenario, seed).at(t)` is a function of the scenario time only, so
every simulated sensor (in whatever process, on whatever host) that knows
the scenario, the random seed and the start time sees the same people. People
walk straight lines between their waypoints; while they stand they sway
a little (a few centimetres, a smooth function of time and the random seed), as
real people do and as a radar's still-target energy needs.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from buddybot.sim.scenario import PersonSpec, Scenario, Waypoint

SWAY_M = 0.02
"""How far a standing person sways (m)."""
SWAY_PERIOD_S = 3.1


@dataclass(frozen=True, slots=True)
class PersonState:
    """One person now, in the robot's frame (m, m/s, rad); `z` is the eyes' height
    above the camera."""

    id: int
    name: str
    face: str
    x: float
    y: float
    z: float
    vx: float
    vy: float
    facing: float
    """Where their face points (rad about z, 0 = the robot's forward, + = its left)."""

    @property
    def distance(self) -> float:
        """Horizontal range from the camera (m)."""
        return math.hypot(self.x, self.y)

    @property
    def bearing(self) -> float:
        """Direction from the camera (rad, + = the robot's left)."""
        return math.atan2(self.y, self.x)

    @property
    def radial_speed(self) -> float:
        """Speed away from the robot (m/s, + = leaving)."""
        d = self.distance
        return 0.0 if d < 1e-9 else (self.x * self.vx + self.y * self.vy) / d

    @property
    def turned(self) -> float:
        """How far the face is turned from looking at the camera (rad, 0 = straight at it)."""
        toward = math.atan2(-self.y, -self.x)
        return abs(math.remainder(self.facing - toward, math.tau))


@dataclass(frozen=True, slots=True)
class ClutterState:
    kind: str
    x: float
    y: float

    @property
    def distance(self) -> float:
        return math.hypot(self.x, self.y)


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The world at scenario time `t` (after looping; `lap` counts the loops)."""

    t: float
    lap: int
    people: tuple[PersonState, ...]
    clutter: tuple[ClutterState, ...]
    camera_covered: bool


class World:
    """A scenario made into a function of time, for one seed."""

    def __init__(self, scenario: Scenario, seed: int = 0) -> None:
        self.scenario = scenario
        self.seed = seed
        rng = random.Random(seed)
        self._phases = [rng.uniform(0.0, math.tau) for _ in scenario.spec.person]

    def local_time(self, t: float) -> tuple[float, int]:
        """Scenario time `t` (s since start) -> (time within the run, lap)."""
        spec = self.scenario.spec
        t = max(t, 0.0)
        if spec.loop:
            lap = int(t // spec.length_s)
            return t - lap * spec.length_s, lap
        return min(t, spec.length_s), 0

    def at(self, t: float) -> Snapshot:
        spec = self.scenario.spec
        local, lap = self.local_time(t)
        people = []
        for index, person in enumerate(spec.person):
            state = self._person(index, person, local)
            if state is not None:
                people.append(state)
        clutter = tuple(ClutterState(c.kind, c.x, c.y) for c in spec.clutter
                        if c.until_s is None or local < c.until_s)
        return Snapshot(local, lap, tuple(people), clutter, spec.camera_covered)

    def _person(self, index: int, spec: PersonSpec, t: float) -> PersonState | None:
        path = spec.path
        end = self.scenario.spec.length_s if len(path) == 1 else path[-1].t
        if not path[0].t <= t <= end:
            return None
        # The segment t is on (at the last waypoint: the one arriving there).
        i = min(max(j for j in range(len(path)) if path[j].t <= t), max(len(path) - 2, 0))
        a = path[i]
        b = path[i + 1] if i + 1 < len(path) else a
        f = 0.0 if b.t <= a.t else min((t - a.t) / (b.t - a.t), 1.0)
        x, y = a.x + (b.x - a.x) * f, a.y + (b.y - a.y) * f
        vx, vy = ((b.x - a.x) / (b.t - a.t), (b.y - a.y) / (b.t - a.t)) if b.t > a.t \
            else (0.0, 0.0)
        if math.hypot(vx, vy) < 0.05:  # standing: sway
            phase = self._phases[index] + math.tau * t / SWAY_PERIOD_S
            x += SWAY_M * math.sin(phase)
            y += SWAY_M * math.cos(phase * 0.7)
        facing = _facing(_mode(path, i), x, y, a, b)
        z = spec.height_m - self.scenario.spec.camera_height_m
        return PersonState(index + 1, spec.name, spec.face, x, y, z, vx, vy, facing)


def _mode(path: list[Waypoint], i: int) -> str:
    """The facing in force at waypoint i: its own, else the last one given."""
    for waypoint in reversed(path[:i + 1]):
        if waypoint.facing is not None:
            return waypoint.facing
    return "robot"


def _facing(mode: str, x: float, y: float, a: Waypoint, b: Waypoint) -> float:
    toward = math.atan2(-y, -x)
    if mode == "away":
        return math.remainder(toward + math.pi, math.tau)
    if mode == "path" and (b.x, b.y) != (a.x, a.y):
        return math.atan2(b.y - a.y, b.x - a.x)
    return toward
