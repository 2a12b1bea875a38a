"""Pinhole geometry, pure: pixels + face size -> a 3-D point in ROS axes.

Camera (optical) axes: x right, y down, z forward. ROS body axes, which
every BuddyBot message uses: x forward, y left, z up. So a point at
optical (X, Y, Z) is ROS (Z, -X, -Y).

Distance has two cues:

* face width (the seed): `Z = fx * face_width_m / box_width_px`. The box
  is BlazeFace's, so `face_width_m` is the real width that box covers on
  an average adult (0.15 m default);
* eye distance: `Z = fx * eye_distance_m / eye_px`. When the head turns by
  yaw the eyes' image distance shrinks by cos(yaw); the ear and nose
  keypoints give that yaw (cylinder head model, see `head_yaw`), so the
  cue is corrected. The two are fused with weights that favour the box
  as the head turns further (its width changes little with yaw).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from buddybot.camera import blazeface as bf


@dataclass(frozen=True)
class Intrinsics:
    """Focal lengths and principal point in pixels."""

    fx: float
    fy: float
    cx: float
    cy: float

    @staticmethod
    def resolve(width: int, height: int, fx: float | None = None, fy: float | None = None,
                cx: float | None = None, cy: float | None = None,
                hfov_deg: float | None = None) -> Intrinsics:
        """Fill what the config leaves out.

        A horizontal field of view, when given, wins over fx (it is what
        camera data sheets state); fy defaults to fx (square pixels) and the
        principal point to the image centre.
        """
        if hfov_deg is not None:
            if not 0.0 < hfov_deg < 180.0:
                raise ValueError(f"hfov_deg must be in (0, 180), got {hfov_deg}")
            fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
            fy = fy if fy is not None else fx
        if fx is None or fx <= 0:
            raise ValueError("fx (or hfov_deg) must be set and positive")
        fy = fx if fy is None else fy
        if fy <= 0:
            raise ValueError("fy must be positive")
        return Intrinsics(
            fx, fy, width / 2.0 if cx is None else cx, height / 2.0 if cy is None else cy,
        )


def distance_from_width(fx: float, real_width_m: float, width_px: float) -> float:
    """The seed's pinhole distance: Z = fx * W / w."""
    if width_px <= 0:
        raise ValueError("width in pixels must be positive")
    return fx * real_width_m / width_px


def head_yaw(keypoints: np.ndarray) -> float:
    """Head yaw (rad, 0 = facing the camera) from nose and ear keypoints.

    Cylinder model: the ears sit at +-90 degrees from the nose, so with yaw
    t the nose projects at R sin t and the ears at -+R cos t about the head
    axis, which gives tan t = 2 * r - 1 where r is the nose's fraction of
    the way from one ear to the other. Clipped to +-70 degrees, where the
    far ear is hidden and the keypoint is a guess.
    """
    right_ear = float(keypoints[bf.RIGHT_EAR][0])
    left_ear = float(keypoints[bf.LEFT_EAR][0])
    nose = float(keypoints[bf.NOSE_TIP][0])
    span = left_ear - right_ear
    if abs(span) < 1e-6:
        return 0.0
    ratio = (nose - right_ear) / span
    return float(np.clip(math.atan(2.0 * ratio - 1.0), -math.radians(70), math.radians(70)))


@dataclass(frozen=True)
class DistanceEstimate:
    """The fused distance and the cues it came from (for diagnostics and the debug image)."""

    z_m: float
    from_width_m: float
    from_eyes_m: float | None
    yaw_rad: float


def estimate_distance(det: bf.Detection, fx: float, face_width_m: float,
                      eye_distance_m: float | None) -> DistanceEstimate:
    """Fuse the face-width and the yaw-corrected eye-distance cues.

    Weight of the eye cue: cos(yaw)^2 (it is best facing the camera, where
    its correction is exact, and fades out as the head turns). With
    `eye_distance_m` None only the width cue is used (the seed's method).
    """
    z_width = distance_from_width(fx, face_width_m, det.width)
    yaw = head_yaw(det.keypoints)
    if eye_distance_m is None:
        return DistanceEstimate(z_width, z_width, None, yaw)
    eye_px = det.eye_distance() / max(math.cos(yaw), 0.3)
    if eye_px <= 1.0:
        return DistanceEstimate(z_width, z_width, None, yaw)
    z_eyes = fx * eye_distance_m / eye_px
    w_eyes = 0.5 * math.cos(yaw) ** 2
    z = (1.0 - w_eyes) * z_width + w_eyes * z_eyes
    return DistanceEstimate(z, z_width, z_eyes, yaw)


def back_project(u: float, v: float, z: float, k: Intrinsics) -> tuple[float, float, float]:
    """Pixel (u, v) at depth z (m along the optical axis) -> ROS point (x fwd, y left, z up)."""
    x_opt = (u - k.cx) * z / k.fx
    y_opt = (v - k.cy) * z / k.fy
    return z, -x_opt, -y_opt
