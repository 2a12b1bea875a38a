"""The top-down map's geometry: the camera's frame (metres) to the map canvas (pixels).

The map is drawn looking down on the robot: the camera's frame (ROS axes,
x forward, y left, the frame radar targets and faces share) with x drawn
up and y drawn to the left, so a person on the robot's left appears on the
left of the screen, as a person standing behind the robot would see them.
The robot sits at the bottom centre, or at the centre when something is
behind it. One scale for both axes (a circle stays a circle), chosen so the
farthest thing shown fits, in whole metres up to `MAX_EXTENT_M` (the
LD2450's range).

Pure functions only: `radar_map.py` decides what is drawn, this module
where, and the page paints what it is sent.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

MIN_EXTENT_M = 3.0
"""The map never shows less than this ahead (a near target is not drawn huge)..."""
MIN_SIDE_M = 2.0
"""...nor less than this to each side."""
MAX_EXTENT_M = 8.0
"""Nor more: the LD2450 sees 8 m; a farther (absurd) point is drawn off the canvas."""
EDGE_PX = 20.0
"""Free pixels between the extent and the canvas' sides."""
ROBOT_PX = 60.0
"""Pixels below the robot when it sits at the bottom (its own drawing and a label)."""
BEHIND_M = 0.3
"""A point farther than this behind the camera moves the robot to the centre."""
LIMIT_PX = 100_000.0
"""Canvas coordinates are clamped to +-this (an absurd point stays a finite, small number)."""


@dataclass(frozen=True)
class MapView:
    """Where the robot is on the canvas and how many pixels a metre is."""

    width: float
    height: float
    origin_u: float
    origin_v: float
    scale: float
    """Pixels per metre, both axes."""

    def to_canvas(self, x: float, y: float) -> tuple[float, float]:
        """A point of the camera's frame (x forward, y left) -> canvas (u right, v down)."""
        u = self.origin_u - y * self.scale
        v = self.origin_v - x * self.scale
        return (max(-LIMIT_PX, min(LIMIT_PX, u)), max(-LIMIT_PX, min(LIMIT_PX, v)))

    def to_world(self, u: float, v: float) -> tuple[float, float]:
        """The inverse of `to_canvas` (inside the clamp)."""
        return ((self.origin_v - v) / self.scale, (self.origin_u - u) / self.scale)

    def reach_m(self) -> float:
        """Metres from the robot to the farthest canvas corner: a ray this long
        leaves the canvas whatever its direction."""
        du = max(self.origin_u, self.width - self.origin_u)
        dv = max(self.origin_v, self.height - self.origin_v)
        return math.hypot(du, dv) / self.scale

    def contains(self, u: float, v: float) -> bool:
        return 0.0 <= u <= self.width and 0.0 <= v <= self.height


def extent_for(values: Iterable[float], minimum: float) -> float:
    """Metres the map must show along one axis: the largest value, rounded up to a
    whole metre, within `minimum`..MAX_EXTENT_M."""
    far = max(values, default=0.0)
    return min(MAX_EXTENT_M, max(minimum, float(math.ceil(far + 0.25))))


def fit_view(width: float, height: float, points: Iterable[tuple[float, float]]) -> MapView:
    """The view showing `points` (camera frame, metres) on a `width` x `height` canvas.

    The robot at the bottom centre when nothing is more than `BEHIND_M`
    behind it, else at the centre. The scale is the largest that fits both
    the sideways extent (the farthest |y|, at least MIN_SIDE_M) and the one
    ahead (the farthest x, at least MIN_EXTENT_M; behind too when the robot
    is centred), so the people fill the canvas and one metre is the same
    length both ways.
    """
    pts = list(points)
    behind = any(x < -BEHIND_M for x, _y in pts)
    side = extent_for((abs(y) for _x, y in pts), MIN_SIDE_M)
    ahead = extent_for((abs(x) if behind else x for x, _y in pts), MIN_EXTENT_M)
    origin_u = width / 2.0
    origin_v = height / 2.0 if behind else height - ROBOT_PX
    up = origin_v - EDGE_PX
    if behind:
        up = min(up, height - origin_v - EDGE_PX)
    scale = min(max(1.0, width / 2.0 - EDGE_PX) / side, max(1.0, up) / ahead)
    return MapView(width, height, origin_u, origin_v, scale)


def bearing_point(bearing_rad: float, distance_m: float) -> tuple[float, float]:
    """The camera-frame point at `distance_m` along `bearing_rad` (+ = the robot's left)."""
    return (distance_m * math.cos(bearing_rad), distance_m * math.sin(bearing_rad))


def wedge(view: MapView, left_rad: float, right_rad: float,
          steps: int = 24) -> list[tuple[float, float]]:
    """Canvas polygon of the directions between `right_rad` and `left_rad` (a field
    of view): the robot, then an arc reaching past the canvas' corners."""
    reach = view.reach_m()
    poly = [view.to_canvas(0.0, 0.0)]
    for i in range(steps + 1):
        b = right_rad + (left_rad - right_rad) * i / steps
        poly.append(view.to_canvas(*bearing_point(b, reach)))
    return poly


def rectangle(view: MapView, x_min: float, x_max: float, y_min: float,
              y_max: float) -> list[tuple[float, float]]:
    """Canvas polygon of a camera-frame rectangle (a presence zone)."""
    return [view.to_canvas(x, y) for x, y in
            ((x_min, y_min), (x_max, y_min), (x_max, y_max), (x_min, y_max))]


def rings(view: MapView) -> list[float]:
    """Distance rings every metre (every 2 m past 6 m of extent) up to the canvas' edge."""
    visible = view.reach_m()
    step = 1.0 if (view.width / 2.0) / view.scale <= 6.0 else 2.0
    out, r = [], step
    while r < visible:
        out.append(r)
        r += step
    return out


def camera_fov(width_px: int | None, fx: float | None, cx: float | None,
               hfov_deg: float | None) -> tuple[float, float] | None:
    """The camera's horizontal view as (left, right) bearings in radians (+ = left).

    From the face detector's intrinsics, as it resolves them: `hfov_deg`,
    when set, defines fx from the frame width (and is symmetric when the
    principal point `cx` is the centre); otherwise fx. Column 0 is the
    robot's left: its bearing is atan(cx / fx), the last column's
    -atan((width - cx) / fx). None when not enough is known (no width and
    no hfov_deg) or the numbers are absurd.
    """
    if hfov_deg is not None:
        if not 0.0 < hfov_deg < 180.0:
            return None
        half = math.radians(hfov_deg) / 2.0
        if width_px is None or width_px <= 0 or cx is None:
            return (half, -half)
        fx = (width_px / 2.0) / math.tan(half)
    if width_px is None or width_px <= 0 or fx is None or not fx > 0 or not math.isfinite(fx):
        return None
    centre = width_px / 2.0 if cx is None else cx
    if not math.isfinite(centre):
        return None
    return (math.atan2(centre, fx), -math.atan2(width_px - centre, fx))
