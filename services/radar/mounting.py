"""Where an angle radar sits on the robot: sensor x/y -> the camera's frame (pure geometry).

The LD2450 reports a target in its own axes: y away from its face, x
across it. Which way +x points is not drawn unambiguously in the
datasheet's text; ESPHome computes the angle as atan2(-x, y), i.e. it takes
+x as the sensor's RIGHT seen from behind the sensor (looking where it
looks), and so do we: a person to the robot's left has x < 0 on a sensor
mounted upright and facing forward. A module mounted upside down mirrors x
(`mirror_x`), and so does a module whose firmware turns out to use the
other convention: one setting fixes either, nothing else changes.

The camera's frame uses ROS axes (x forward, y left, z up), the frame of
`FacePosition.point`. A mount places the sensor in it: its position (m)
and yaw (rad about z, + = turned toward the robot's left). The default is
the identity: at the camera, facing forward. Bearing = atan2(y, x) of the
placed point (+ = the robot's left); distance = its horizontal range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Mount:
    """The sensor's pose relative to the camera (m, m, m, rad) and its x sense."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    mirror_x: bool = False


IDENTITY = Mount()


@dataclass(frozen=True, slots=True)
class Placed:
    """A target in the camera's frame: position (m), bearing (rad), horizontal range (m)."""

    x: float
    y: float
    z: float
    bearing_rad: float
    distance_m: float


def place(x_m: float, y_m: float, mount: Mount = IDENTITY) -> Placed:
    """Sensor x/y (m, the datasheet's axes) -> the camera's frame.

    In the sensor's own ROS-style frame the target is `forward = y`,
    `left = -x` (or `+x` when mirrored); the mount's yaw rotates that and
    its position shifts it.
    """
    forward = y_m
    left = x_m if mount.mirror_x else -x_m
    c, s = math.cos(mount.yaw), math.sin(mount.yaw)
    px = mount.x + c * forward - s * left
    py = mount.y + s * forward + c * left
    return Placed(px, py, mount.z, math.atan2(py, px), math.hypot(px, py))
