"""One frame in, at most one face out: detection, target choice, geometry, smoothing.

No Zenoh here (the service wires it to keys), so the whole chain is tested
on real images in-process: `FacePipeline.process(bgr, stamp_ns)`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera.facenet import FaceNet
from buddybot.camera.geometry import DistanceEstimate, Intrinsics, back_project, estimate_distance
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.camera.tracking import PointSmoother, TargetTracker


@dataclass(frozen=True)
class FaceResult:
    """What one frame gave: every face, the followed one and its point (ROS axes, m)."""

    faces: list[bf.Detection]
    target: bf.Detection | None
    estimate: DistanceEstimate | None
    point: tuple[float, float, float] | None
    raw_point: tuple[float, float, float] | None
    measured: bf.Detection | None
    """The followed face as measured (refined when a refiner is set)."""


class FacePipeline:
    """Detector `net` on the whole frame; optional `refiner` (the short-range
    model) re-detects the followed face in a crop for a precise size and eyes."""

    def __init__(self, net: FaceNet, settings: FaceDetectorSettings,
                 refiner: FaceNet | None = None) -> None:
        self.net = net
        self.refiner = refiner
        self.refined = 0
        self.s = settings
        self.tracker = TargetTracker(switch_after_s=settings.switch_after_s)
        self.smoother = PointSmoother(settings.min_cutoff_hz, settings.beta)
        self._intrinsics: dict[tuple[int, int], Intrinsics] = {}

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        key = (width, height)
        if key not in self._intrinsics:
            s = self.s
            self._intrinsics[key] = Intrinsics.resolve(width, height, s.fx, s.fy, s.cx, s.cy,
                                                       s.hfov_deg)
        return self._intrinsics[key]

    def process(self, bgr: np.ndarray, stamp_ns: int) -> FaceResult:
        faces = self.net.detect(bgr)
        t = stamp_ns * 1e-9
        target, new_person = self.tracker.select(faces, t)
        if target is None:
            return FaceResult(faces, None, None, None, None, None)
        k = self.intrinsics(bgr.shape[1], bgr.shape[0])
        eye_m = self.s.eye_distance_m if self.s.eye_distance_m > 0 else None
        measured = target
        if self.refiner is not None:
            better = self.refiner.refine(bgr, target)
            if better is not None:
                measured = better
                self.refined += 1
        est = estimate_distance(measured, k.fx, self.s.face_width_m, eye_m)
        u, v = measured.centre
        raw = back_project(u, v, est.z_m, k)
        if not self.s.smoothing:
            return FaceResult(faces, target, est, raw, raw, measured)
        if new_person:
            self.smoother.reset()
        return FaceResult(faces, target, est, self.smoother(raw, t), raw, measured)
