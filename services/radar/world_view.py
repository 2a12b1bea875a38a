"""The simulated world as each radar model reports it (pure): the simulators' input.

An LD2410 reports one moving and one still target: the nearest of each in
its field, with energies that fall with distance. An LD2450 reports up to
three targets in its own axes (mm) with their radial speed (cm/s), from
its mounting. A fan is a moving target and a ghost a still one: clutter
a radar cannot tell from a person.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from buddybot.radar.mounting import Mount
from buddybot.radar.sim_scene import (
    BOTH,
    MOVING,
    NO_TARGET,
    STILL,
    AngleScript,
    Person,
    Scene,
    Script,
    Target,
)
from buddybot.sim import views
from buddybot.sim.world import Snapshot, World

WALKING_MS = 0.15
"""Faster than this a person is a moving target; slower (standing, swaying), a still one."""
FAN_SPEED_CMS = 40
MAX_TARGETS = 3  # LD2450


@dataclass(frozen=True, slots=True)
class Echo:
    """One thing a radar sees, in its own (forward, left) metres."""

    forward: float
    left: float
    radial_ms: float
    moving: bool
    energy_scale: float  # a person 1.0, clutter less

    @property
    def distance(self) -> float:
        return math.hypot(self.forward, self.left)


def pose_of(mount: Mount) -> views.Pose:
    return views.Pose(mount.x, mount.y, mount.yaw)


def echoes(snapshot: Snapshot, pose: views.Pose, field: views.RadarField) -> list[Echo]:
    """Everything in the radar's field, nearest first."""
    found: list[Echo] = []
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    for p in snapshot.people:
        if not views.radar_sees(p.x, p.y, pose, field):
            continue
        forward, left = views.in_sensor(p.x, p.y, pose)
        vf, vl = c * p.vx + s * p.vy, -s * p.vx + c * p.vy
        r = math.hypot(forward, left)
        radial = (forward * vf + left * vl) / r
        found.append(Echo(forward, left, radial, math.hypot(p.vx, p.vy) > WALKING_MS, 1.0))
    for thing in snapshot.clutter:
        if not views.radar_sees(thing.x, thing.y, pose, field):
            continue
        forward, left = views.in_sensor(thing.x, thing.y, pose)
        fan = thing.kind == "fan"
        radial = FAN_SPEED_CMS / 100.0 * math.sin(math.tau * snapshot.t / 0.7) if fan else 0.0
        found.append(Echo(forward, left, radial, fan, 0.6 if fan else 0.4))
    found.sort(key=lambda e: e.distance)
    return found


def _energy(echo: Echo, base: float) -> int:
    """Energy 0..100 falling with distance (a person at 1 m: about `base`)."""
    return max(5, min(100, round(base * echo.energy_scale * (1.3 - 0.12 * echo.distance))))


def ld2410_target(snapshot: Snapshot, pose: views.Pose = views.AT_CAMERA) -> Target:
    """The LD2410's report: nearest moving and nearest still target."""
    seen = echoes(snapshot, pose, views.LD2410_FIELD)
    moving = next((e for e in seen if e.moving), None)
    still = next((e for e in seen if not e.moving), None)
    if moving is None and still is None:
        return Target(NO_TARGET)
    state = BOTH if moving and still else MOVING if moving else STILL
    m = moving or still
    s = still or moving
    assert m is not None and s is not None
    m_cm, s_cm = round(m.distance * 100), round(s.distance * 100)
    return Target(state, m_cm, _energy(m, 60) if moving else 5,
                  s_cm, _energy(s, 65) if still else 20, min(m_cm, s_cm))


def ld2450_scene(snapshot: Snapshot, mount: Mount) -> Scene:
    """The LD2450's report: the nearest three targets in its axes (mm, cm/s)."""
    out = []
    for e in echoes(snapshot, pose_of(mount), views.LD2450_FIELD)[:MAX_TARGETS]:
        across = e.left if mount.mirror_x else -e.left
        out.append(Person(round(across * 1000), round(e.forward * 1000),
                          round(e.radial_ms * 100)))
    return Scene(tuple(out))


def world_script(world: World, model: str, mount: Mount) -> Script | AngleScript:
    """What a simulated sensor of `model`, mounted at `mount`, reports at scenario time t."""
    if model == "LD2450":
        return lambda t, _rng: ld2450_scene(world.at(t), mount)
    pose = pose_of(mount)
    return lambda t, _rng: ld2410_target(world.at(t), pose)
