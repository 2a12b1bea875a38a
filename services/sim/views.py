"""What each simulated sensor should see of a `Snapshot` (pure geometry, no drawing).

One place answers "is this person in that sensor's field", so the sensors
(radar and camera, each in its own process) and the truth published on
`sim/world` never disagree. A sensor's pose is the radar mount's
convention (`radar/mounting.py`): position in the robot's frame and a yaw,
+ = turned to the robot's left; the camera sits at the origin facing +x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from buddybot.sim.world import PersonState, Snapshot

FACE_WIDTH_M = 0.15
"""Width of the face box on an average adult: the detector's default `face_width_m`."""
MAX_TURN_RAD = math.radians(75)
"""A face turned further than this from the camera is not drawn (the back of a head)."""
MIN_DEPTH_M = 0.25
# A person's silhouette in face-box widths, from the face centre: the head and the
# shoulders below it. The camera draws it; a face inside a nearer one is hidden.
HEAD_HALF_W, HEAD_HALF_H = 0.65, 0.85
BODY_TOP, BODY_HALF_W = 0.8, 1.5


@dataclass(frozen=True, slots=True)
class Pose:
    """A sensor on the robot: position (m) and yaw (rad, + = toward the robot's left)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


AT_CAMERA = Pose()


@dataclass(frozen=True, slots=True)
class RadarField:
    """A radar's field: half the opening angle (rad) and its range (m)."""

    half_angle: float
    range_m: float


LD2410_FIELD = RadarField(math.radians(60), 6.0)
"""8 gates of 0.75 m; +-60 degrees (HLK-LD2410 data sheet)."""
LD2450_FIELD = RadarField(math.radians(60), 8.0)


def in_sensor(x: float, y: float, pose: Pose) -> tuple[float, float]:
    """A point of the robot's frame in the sensor's own (forward, left), m."""
    dx, dy = x - pose.x, y - pose.y
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return c * dx + s * dy, -s * dx + c * dy


def radar_sees(x: float, y: float, pose: Pose, field: RadarField) -> bool:
    forward, left = in_sensor(x, y, pose)
    return forward > 0.05 and math.hypot(forward, left) <= field.range_m and \
        abs(math.atan2(left, forward)) <= field.half_angle


@dataclass(frozen=True, slots=True)
class Lens:
    """The camera's pinhole: focal lengths and principal point (px), image size (px)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


@dataclass(frozen=True, slots=True)
class FaceView:
    """One person's face as the camera should see it: centre and box width (px)."""

    person: PersonState
    u: float
    v: float
    box_px: float
    depth_m: float
    visible: bool
    """Wholly in the image, facing the camera and not hidden behind a nearer person."""


def project(person: PersonState, lens: Lens) -> tuple[float, float, float] | None:
    """The face centre in pixels and its box width, or None behind the camera."""
    depth = person.x
    if depth < MIN_DEPTH_M:
        return None
    u = lens.cx - lens.fx * person.y / depth
    v = lens.cy - lens.fy * person.z / depth
    return u, v, lens.fx * FACE_WIDTH_M / depth


def camera_view(snapshot: Snapshot, lens: Lens) -> list[FaceView]:
    """Every person in front of the camera, nearest last (the order to draw them in)."""
    views: list[FaceView] = []
    for person in snapshot.people:
        found = project(person, lens)
        if found is None:
            continue
        u, v, box = found
        half = box / 2  # the whole face box in the image: a cut face is not a face
        inside = half <= u <= lens.width - half and half <= v <= lens.height - half
        views.append(FaceView(person, u, v, box, person.x,
                              inside and person.turned <= MAX_TURN_RAD
                              and not snapshot.camera_covered))
    views.sort(key=lambda f: -f.depth_m)
    out = []
    for i, face in enumerate(views):
        hidden = any(_covers(nearer, face, lens) for nearer in views[i + 1:])
        out.append(face if not hidden else _hidden(face))
    return out


def _covers(nearer: FaceView, face: FaceView, lens: Lens) -> bool:
    """Whether the nearer person's silhouette (head and shoulders) hides the face's centre."""
    b = nearer.box_px
    dx, dy = abs(face.u - nearer.u), face.v - nearer.v
    in_head = (dx / (HEAD_HALF_W * b)) ** 2 + (dy / (HEAD_HALF_H * b)) ** 2 <= 1.0
    in_body = dy >= BODY_TOP * b and dx <= BODY_HALF_W * b
    return in_head or in_body


def _hidden(face: FaceView) -> FaceView:
    return FaceView(face.person, face.u, face.v, face.box_px, face.depth_m, False)
