"""`buddybot run sim`: the simulated world's truth on `sim/world`.

The simulated sensors (radar bridge, camera) each render the world
themselves, from the same scenario, seed and start (see clock.py); this
service only says what is really there, so tools, tests and the dashboard
can compare what the robot perceives with the truth.
"""

from __future__ import annotations

import argparse
import math
import time

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge
from buddybot.runtime.service import ServiceContext
from buddybot.sim import views
from buddybot.sim.options import add_world_arguments, world_of
from buddybot.sim.settings import SimSettings
from buddybot.sim.world import Snapshot

DEFAULT_LENS = (640, 480, 600.0)
"""Width, height and fx of the camera when its tables say nothing (their defaults)."""


def lens_of(ctx: ServiceContext) -> views.Lens:
    """The camera's pinhole as the face detector measures with (`[camera]`,
    `[face_detector]`), read by name so this service needs no camera code."""
    width, height, fx = DEFAULT_LENS
    camera = getattr(ctx.config, "camera", None)
    detector = getattr(ctx.config, "face_detector", None)
    width = getattr(camera, "width", None) or width
    height = getattr(camera, "height", None) or height
    hfov = getattr(detector, "hfov_deg", None)
    fx = (width / 2) / math.tan(math.radians(hfov) / 2) if hfov else \
        (getattr(detector, "fx", None) or fx)
    fy = getattr(detector, "fy", None) or fx
    cx = getattr(detector, "cx", None)
    cy = getattr(detector, "cy", None)
    return views.Lens(fx, fy, width / 2 if cx is None else cx,
                      height / 2 if cy is None else cy, width, height)


def truth(snapshot: Snapshot, scenario: str, lens: views.Lens, stamp_ns: int) -> m.SimWorld:
    """The message for one moment of the world."""
    on_camera = {f.person.id for f in views.camera_view(snapshot, lens) if f.visible}
    people = [m.SimPerson(
        id=p.id, face=p.face, name=p.name or None, position=m.Point(x=p.x, y=p.y, z=p.z),
        vx_mps=p.vx, vy_mps=p.vy, facing_rad=p.facing, distance_m=p.distance,
        bearing_rad=p.bearing,
        in_radar=views.radar_sees(p.x, p.y, views.AT_CAMERA, views.LD2410_FIELD),
        in_camera=p.id in on_camera) for p in snapshot.people]
    clutter = [m.SimClutter(kind=c.kind, position=m.Point(x=c.x, y=c.y, z=0.0))  # type: ignore[arg-type]
               for c in snapshot.clutter]
    return m.SimWorld(stamp_ns=stamp_ns, scenario=scenario, t_s=snapshot.t, lap=snapshot.lap,
                      people=people, clutter=clutter)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_world_arguments(parser)


def settings_from(ctx: ServiceContext) -> SimSettings:
    """`[sim]` with the command line on top (ranges checked by `merge`)."""
    return merge(ctx.config.section(SimSettings), ctx.args)


def run(ctx: ServiceContext) -> int:
    world, clock, settings = world_of(settings_from(ctx))
    lens = lens_of(ctx)
    node: Node = ctx.node()
    try:
        pub = node.publisher(keys.SIM_WORLD)
        name = world.scenario.name
        node.diagnostics.values.update({"scenario": name, "seed": world.seed})

        def tick() -> None:
            now = time.time()
            pub.put(truth(world.at(clock.at(now)), name, lens, time.time_ns()))

        node.every(1.0 / settings.rate_hz, tick, name="sim-world")
        node.spin()
    finally:
        node.close()
    return 0
