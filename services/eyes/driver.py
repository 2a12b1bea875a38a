"""The eyes driver's logic (docs/design.md section 4.5), pure: no Zenoh, no I/O.

* gaze: `EyeControl` radians -> `EyesDirection` degrees, same signs
  (+yaw = the robot's left, +pitch = up), clamped to the message's range;
* pupil: target distance -> dilation percentage through a piecewise-linear
  curve (near -> large, far -> small, like a real eye accommodating and the
  "cute" big-pupil look when someone is close), clamped to 0..100;
* lids: an expression -> top/bottom lid positions per eye (0/0 open,
  50/50 closed). Shapes a lid position cannot express (a sad slant, a
  happy crescent, hearts, stars) are drawn by the renderer, which also
  receives the expression.

Everything here is a function of its inputs so it is unit-tested without
processes; the service (`driver_service.py`) only wires it to keys.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from buddybot.contract import messages as m

# --- gaze --------------------------------------------------------------------------

MAX_YAW_DEG = 180.0
MAX_PITCH_DEG = 90.0


def _clamp(value: float, low: float, high: float) -> float:
    return min(high, max(low, value))


def direction_from_control(control: m.EyeControl) -> m.EyesDirection:
    """Radians -> degrees with the same signs; `stamp_ns` is the face's, kept.

    `EyeControl` allows +-3.15 rad (a hair over pi), so the degrees are
    clamped into `EyesDirection`'s +-180 / +-90 range instead of producing
    a message the renderer would refuse. The target distance is passed on
    (the pages converge the eyes on a near face); 0, "unknown" in
    `EyeControl`, becomes None.
    """
    return m.EyesDirection(
        stamp_ns=control.stamp_ns,
        yaw=_clamp(math.degrees(control.yaw), -MAX_YAW_DEG, MAX_YAW_DEG),
        pitch=_clamp(math.degrees(control.pitch), -MAX_PITCH_DEG, MAX_PITCH_DEG),
        target_distance_cm=control.target_distance_cm or None,
    )


# --- pupil -------------------------------------------------------------------------


@dataclass(frozen=True)
class PupilCurve:
    """A monotonic (non-increasing) piecewise-linear distance -> dilation map."""

    points: tuple[tuple[float, float], ...]

    @classmethod
    def from_points(cls, points: Iterable[Sequence[float]]) -> PupilCurve:
        """Validate user points; ValueError says what is wrong.

        Rules: at least one point, each `[distance_cm, percent]`, distances
        finite, >= 0 and strictly increasing, percentages within 0..100 and
        never increasing with distance (near -> large, far -> small).
        """
        pts: list[tuple[float, float]] = []
        for i, point in enumerate(points):
            if len(point) != 2:
                raise ValueError(f"point {i} must be [distance_cm, percent], got {list(point)}")
            dist, pct = float(point[0]), float(point[1])
            if not (math.isfinite(dist) and dist >= 0):
                raise ValueError(f"point {i}: distance {dist} must be a finite number >= 0")
            if not (math.isfinite(pct) and 0.0 <= pct <= 100.0):
                raise ValueError(f"point {i}: percent {pct} must be within 0..100")
            if pts and dist <= pts[-1][0]:
                raise ValueError(f"point {i}: distances must increase ({dist} after {pts[-1][0]})")
            if pts and pct > pts[-1][1]:
                raise ValueError(
                    f"point {i}: dilation must not grow with distance ({pct} after {pts[-1][1]})"
                )
            pts.append((dist, pct))
        if not pts:
            raise ValueError("the curve needs at least one point")
        return cls(tuple(pts))

    def __call__(self, distance_cm: float) -> float:
        """Dilation % for a distance; flat outside the points, always 0..100."""
        pts = self.points
        if not math.isfinite(distance_cm) or distance_cm <= pts[0][0]:
            # NaN cannot come through msgspec validation; +inf is "very far".
            value = pts[-1][1] if distance_cm == math.inf else pts[0][1]
            return _clamp(value, 0.0, 100.0)
        for (d0, p0), (d1, p1) in itertools.pairwise(pts):
            if distance_cm <= d1:
                t = (distance_cm - d0) / (d1 - d0)
                return _clamp(p0 + t * (p1 - p0), 0.0, 100.0)
        return _clamp(pts[-1][1], 0.0, 100.0)


def pupil_from_control(
    control: m.EyeControl, curve: PupilCurve, unknown_percent: float
) -> m.PupilControl:
    """Dilation for the control's distance; 0 cm means "distance unknown"
    (the ROS 2 message's field is optional) and gives `unknown_percent`."""
    if control.target_distance_cm <= 0:
        pct = _clamp(unknown_percent, 0.0, 100.0)
    else:
        pct = curve(control.target_distance_cm)
    return m.PupilControl(stamp_ns=control.stamp_ns, dilation_percentage=pct)


# --- lids --------------------------------------------------------------------------


@dataclass(frozen=True)
class Lids:
    """Top and bottom lid positions of one eye, 0..100 (0/0 open, 50/50 closed)."""

    top: float
    bottom: float


@dataclass(frozen=True)
class EyePair:
    """Lids of the robot's left and right eye."""

    left: Lids
    right: Lids

    @classmethod
    def same(cls, top: float, bottom: float) -> EyePair:
        lids = Lids(top, bottom)
        return cls(lids, lids)


A = m.ExpressionAction
DEFAULT_LIDS: Mapping[m.ExpressionAction, EyePair] = {
    A.EYE_AWAKE: EyePair.same(0.0, 0.0),        # fully open (the ROS 2 design's)
    A.EYE_SLEEP: EyePair.same(50.0, 50.0),      # lids meet in the middle (ROS 2 design's)
    A.EYE_SLEEPY: EyePair.same(34.0, 8.0),      # heavy top lid, a third of the eye
    A.EYE_GRIN: EyePair.same(0.0, 28.0),        # cheeks push the bottom lid up: crescent
    A.EYE_SAD: EyePair.same(22.0, 4.0),         # top lid lowered; the renderer slants it
    A.EYE_LOOK_RANDOM: EyePair.same(4.0, 0.0),  # open, a little curious
    A.ANIMATE_LOVE: EyePair.same(6.0, 10.0),    # soft, relaxed around the hearts
    A.ANIMATE_STAR: EyePair.same(0.0, 0.0),     # wide open, star-struck
    A.EYE_ALERT: EyePair.same(0.0, 0.0),        # wide open: someone is coming
}
"""Every expression's lids. Designed symmetric so one `eye_id` BOTH message
carries them, which the latched key's one-sample cache replays whole to a
late renderer (two per-eye messages would leave it only the last)."""


def lid_table(overrides: Mapping[str, Sequence[float]]) -> dict[m.ExpressionAction, EyePair]:
    """The default table with config overrides `{"EYE_SAD": [top, bottom]}`
    (both eyes) or `[left_top, left_bottom, right_top, right_bottom]`."""
    table = dict(DEFAULT_LIDS)
    for name, values in overrides.items():
        try:
            action = m.ExpressionAction[name]
        except KeyError:
            known = ", ".join(a.name for a in m.ExpressionAction)
            raise ValueError(f"unknown expression {name!r} (known: {known})") from None
        vals = [float(v) for v in values]
        if len(vals) not in (2, 4):
            raise ValueError(f"{name}: give [top, bottom] or [lt, lb, rt, rb], got {vals}")
        if not all(0.0 <= v <= 100.0 for v in vals):
            raise ValueError(f"{name}: lid positions must be within 0..100, got {vals}")
        if len(vals) == 2:
            table[action] = EyePair.same(vals[0], vals[1])
        else:
            table[action] = EyePair(Lids(vals[0], vals[1]), Lids(vals[2], vals[3]))
    return table


def lids_for_expression(
    expression: m.ScreenExpression, table: Mapping[m.ExpressionAction, EyePair] = DEFAULT_LIDS
) -> list[m.EyeLidControl]:
    """Lid messages for an expression: one BOTH message when the eyes agree,
    else one per eye (LEFT then RIGHT). `stamp_ns` is kept."""
    pair = table[expression.action]
    stamp = expression.stamp_ns
    if pair.left == pair.right:
        return [m.EyeLidControl(stamp_ns=stamp, eye_id=m.EyeId.BOTH,
                                top_lid_position=pair.left.top,
                                bottom_lid_position=pair.left.bottom)]
    return [
        m.EyeLidControl(stamp_ns=stamp, eye_id=eye, top_lid_position=lids.top,
                        bottom_lid_position=lids.bottom)
        for eye, lids in ((m.EyeId.LEFT, pair.left), (m.EyeId.RIGHT, pair.right))
    ]
