"""Camera -> eyes-centre rigid transform and gaze angles (pure, no ROS/TF2).

A ROS 2 robot uses a TF2 static transform from the camera frame to the
middle between the eyes; the robot's geometry never changes at run time, so one
3x3 rotation and a translation computed once are all that is needed.

Conventions (ROS REP 103/105): x forward, y left, z up; the orientation
is roll (about x), pitch (about y), yaw (about z) applied in that order
about the *fixed* axes, i.e. R = Rz(yaw) @ Ry(pitch) @ Rx(roll). The
transform maps a point given in the camera frame into the eyes frame:
`p_eyes = R @ p_cam + t`, with `t` the camera origin in the eyes frame.

Gaze, as docs/design.md section 4.4 defines it: `yaw = atan2(y, x)`
(+ = the robot's left), `pitch = atan2(z, hypot(x, y))` (+ = up), and the
Euclidean distance in centimetres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

Vector = tuple[float, float, float]
Matrix = tuple[Vector, Vector, Vector]


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> Matrix:
    """R = Rz(yaw) Ry(pitch) Rx(roll): the ROS fixed-axis roll-pitch-yaw rotation."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        (-sp, cp * sr, cp * cr),
    )


@dataclass(frozen=True)
class RigidTransform:
    """A rotation then a translation: maps points of one frame into another."""

    rotation: Matrix = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    translation: Vector = (0.0, 0.0, 0.0)

    @classmethod
    def from_rpy(cls, translation_m: Vector, rpy_rad: Vector) -> RigidTransform:
        """From the config's `translation_m` and `rpy_rad`; refuses non-finite values."""
        values = (*translation_m, *rpy_rad)
        if len(translation_m) != 3 or len(rpy_rad) != 3:
            raise ValueError("translation_m and rpy_rad need three values each")
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"camera_to_eyes has a non-finite value: {values}")
        return cls(rotation_from_rpy(*rpy_rad), tuple(float(v) for v in translation_m))  # type: ignore[arg-type]

    def apply(self, point: Vector) -> Vector:
        """`R @ point + t`."""
        x, y, z = point
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = self.rotation
        tx, ty, tz = self.translation
        return (
            r00 * x + r01 * y + r02 * z + tx,
            r10 * x + r11 * y + r12 * z + ty,
            r20 * x + r21 * y + r22 * z + tz,
        )


@dataclass(frozen=True)
class Gaze:
    """Where the eyes should look: radians (+yaw left, +pitch up) and cm."""

    yaw: float
    pitch: float
    distance_cm: float


def gaze_angles(point: Vector) -> Gaze:
    """Yaw, pitch and distance of a point in the eyes frame (x forward, y left, z up).

    A point at the origin gives (0, 0, 0): atan2(0, 0) is 0 in Python, so a
    degenerate input centres the eyes instead of raising.
    """
    x, y, z = point
    horizontal = math.hypot(x, y)
    return Gaze(
        yaw=math.atan2(y, x),
        pitch=math.atan2(z, horizontal),
        distance_cm=math.sqrt(x * x + y * y + z * z) * 100.0,
    )


def face_gaze(transform: RigidTransform, point: Vector) -> Gaze:
    """Gaze toward a face point given in the camera frame (metres).

    Raises ValueError for a non-finite point (a detector bug must not send
    NaN angles to the eyes).
    """
    if not all(math.isfinite(v) for v in point):
        raise ValueError(f"face point is not finite: {point}")
    return gaze_angles(transform.apply(point))
