"""Pinhole geometry, pure: pixels + face size -> a 3-D point in ROS axes.

Camera (optical) axes: x right, y down, z forward. ROS body axes, which
every BuddyBot message uses: x forward, y left, z up. So a point at
optical (X, Y, Z) is ROS (Z, -X, -Y).

Distance has two cues:

* face width (the classic pinhole cue): `Z = fx * face_width_m / box_width_px`. The box
  is BlazeFace's, so `face_width_m` is the real width that box covers on
  an average adult (0.15 m default);
* eye distance: `Z = fx * eye_distance_m / eye_px`. When the head turns by
  yaw the eyes' image distance shrinks by cos(yaw); the ear and nose
  keypoints give that yaw (cylinder head model, see `head_yaw`), so the
  cue is corrected. The two are fused with weights that favour the box
  as the head turns further (its width changes little with yaw).

This is the geometry stage of the pipeline: `locate` takes the measured
detection once per frame and returns everything derived from it (the
cues, the fused distance, the 3-D point); nothing downstream goes back to
the detection for a distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera import fusion


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
    """The pinhole distance: Z = fx * W / w."""
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


def eye_distance_px(keypoints: np.ndarray) -> float:
    """Pixel distance between the two eye keypoints."""
    d = keypoints[bf.LEFT_EYE] - keypoints[bf.RIGHT_EYE]
    return float(np.hypot(d[0], d[1]))


@dataclass(frozen=True)
class DistanceEstimate:
    """The fused distance and the cues it came from (for diagnostics and the debug image)."""

    z_m: float
    from_width_m: float
    from_eyes_m: float | None
    yaw_rad: float
    fusion: fusion.Fusion | None = None
    """Every cue with its weight, or why it was not used (`fusion.Fusion.summary()`)."""


def estimate_distance(det: bf.Detection, fx: float, face_width_m: float,
                      eye_distance_m: float | None,
                      held_iris: fusion.IrisCalibration | None = None) -> DistanceEstimate:
    """Fuse the face-width, the yaw-corrected eye-distance and the held iris cues.

    Each cue is weighted by how reliable it is at its size in pixels
    (`fusion.fuse`): the eye cue fades out as the head turns, the iris cue
    counts once this person's iris was measured close up. With
    `eye_distance_m` None only the width cue is used.
    """
    yaw = head_yaw(det.keypoints)
    width = fusion.width_cue(fx, face_width_m, det.width)
    cues = [width]
    z_eyes = None
    if eye_distance_m is not None:
        eye_px = eye_distance_px(det.keypoints)
        eyes = fusion.eye_cue(fx, eye_distance_m, eye_px, yaw)
        if eyes.usable == fusion.USED:
            z_eyes = eyes.z_m
        cues.append(eyes)
        held = held_iris.cue(fx, eye_px, yaw) if held_iris is not None else None
        if held is not None:
            cues.append(held)
    fused = fusion.fuse(cues)
    if fused is None:  # not even the width cue (a degenerate box): the width's value
        return DistanceEstimate(width.z_m, width.z_m, None, yaw)
    # One cue alone is its own distance, exactly (no log/exp round trip).
    z = width.z_m if fused.used == (fusion.WIDTH,) else fused.z_m
    return DistanceEstimate(z, width.z_m, z_eyes, yaw, fused)


def back_project(u: float, v: float, z: float, k: Intrinsics) -> tuple[float, float, float]:
    """Pixel (u, v) at depth z (m along the optical axis) -> ROS point (x fwd, y left, z up)."""
    x_opt = (u - k.cx) * z / k.fx
    y_opt = (v - k.cy) * z / k.fy
    return z, -x_opt, -y_opt


@dataclass(frozen=True)
class Location:
    """The geometry stage's output for one face: distance cues and the ROS point."""

    estimate: DistanceEstimate
    point: tuple[float, float, float]


def locate(det: bf.Detection, k: Intrinsics, face_width_m: float,
           eye_distance_m: float | None,
           held_iris: fusion.IrisCalibration | None = None) -> Location:
    """Distance (fused cues) and the back-projected box centre of one measured face."""
    est = estimate_distance(det, k.fx, face_width_m, eye_distance_m, held_iris)
    u, v = det.centre
    return Location(est, back_project(u, v, est.z_m, k))
