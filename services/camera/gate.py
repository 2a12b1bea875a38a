"""The tracking gate, pure: is a crop-tracking result plausibly the face of a frame ago?

Crop tracking re-detects the followed face only in a square around where
it was (`FaceNet.refine`). When that face leaves the square between two
frames (a quick step in, or another person arriving), the crop can still
hold *something* face-like near its middle: the edge of the new face, an
ear, a half-hidden face. Published unchecked, such a find put a face at
0.6 m at 1.67, 2.38 and 3.67 m (tests/camera/test_pipeline.py).

A head cannot change size or place in the image faster than it can move.
At distance Z a face W metres wide is w = fx W / Z pixels; moving at v m/s
for dt seconds changes its width by at most v dt / Z (relative) and moves
its centre by at most v dt / W face widths. To that the detector's own
frame-to-frame noise is added. The keypoints must also agree with the box
as they did a frame ago: the eyes in the same order, their spacing the
same share of the box width, their midpoint at the same place in the box.
A result that fails any of these is refused; the pipeline then searches
the whole frame before publishing anything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from buddybot.camera import blazeface as bf

DT_FALLBACK_S = 1 / 30
"""Interval assumed when the stamps give none (same stamp or time going back)."""
DT_MAX_S = 0.5
"""Longest interval the bounds grow with: after that the track is stale anyway."""


def _eyes(det: bf.Detection) -> tuple[float, float, float]:
    """(eye spacing / box width, eye midpoint x, y in box widths from the box centre)."""
    right, left = det.keypoints[bf.RIGHT_EYE], det.keypoints[bf.LEFT_EYE]
    width = max(det.width, 1e-6)
    spacing = float(np.hypot(*(left - right))) / width
    cx, cy = det.centre
    mid = (right + left) / 2
    return spacing, (float(mid[0]) - cx) / width, (float(mid[1]) - cy) / width


@dataclass(frozen=True)
class TrackGate:
    """Bounds on how far a followed face can change between two frames."""

    max_speed_mps: float = 2.0
    """Fastest head movement allowed for: a quick step or lean (walking is ~1.4 m/s)."""
    size_noise: float = 0.15
    """Relative box-width change the detector shows on a still face, plus margin."""
    position_noise: float = 0.25
    """Centre movement (box widths) the detector shows on a still face, plus margin."""
    spacing_noise: float = 0.3
    """Relative change of the eye spacing / box width ratio allowed (head turning)."""
    eye_shift: float = 0.25
    """Movement of the eyes' midpoint inside the box, in box widths (head turning)."""

    def check(self, prev: bf.Detection, cand: bf.Detection, dt_s: float, fx: float,
              face_width_m: float) -> str | None:
        """None when `cand` is plausibly `prev` `dt_s` later, else why not
        ("size", "position" or "keypoints")."""
        dt = dt_s if dt_s > 0 else DT_FALLBACK_S
        dt = min(dt, DT_MAX_S)
        if prev.width <= 0 or cand.width <= 0:
            return "size"
        z_prev = fx * face_width_m / prev.width
        reach_m = self.max_speed_mps * dt
        ratio = cand.width / prev.width
        if abs(math.log(ratio)) > math.log1p(self.size_noise + reach_m / z_prev):
            return "size"
        (pcx, pcy), (ccx, ccy) = prev.centre, cand.centre
        moved = math.hypot(ccx - pcx, ccy - pcy) / prev.width
        if moved > self.position_noise + reach_m / face_width_m:
            return "position"
        p_spacing, p_mx, p_my = _eyes(prev)
        c_spacing, c_mx, c_my = _eyes(cand)
        p_order = prev.keypoints[bf.LEFT_EYE][0] - prev.keypoints[bf.RIGHT_EYE][0]
        c_order = cand.keypoints[bf.LEFT_EYE][0] - cand.keypoints[bf.RIGHT_EYE][0]
        if p_order * c_order <= 0 or p_spacing <= 0 or c_spacing <= 0:
            return "keypoints"
        if abs(math.log(c_spacing / p_spacing)) > math.log1p(self.spacing_noise):
            return "keypoints"
        if math.hypot(c_mx - p_mx, c_my - p_my) > self.eye_shift:
            return "keypoints"
        return None
