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
from buddybot.core.limits import BoundedDict


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
        # Per frame size; bounded because the sizes come from the bus (a sender
        # changing the size every frame must not grow it without end).
        self._intrinsics: BoundedDict[tuple[int, int], Intrinsics] = BoundedDict(8)
        self._last: bf.Detection | None = None  # the followed face as last measured
        self._full_t = -np.inf  # when the whole frame was last searched
        self._search_due = False  # a deferred whole-frame pass is owed
        self.tracked = 0

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        key = (width, height)
        found = self._intrinsics.get(key)
        if found is None:
            s = self.s
            found = Intrinsics.resolve(width, height, s.fx, s.fy, s.cx, s.cy, s.hfov_deg)
            self._intrinsics[key] = found
        return found

    def _track(self, bgr: np.ndarray, t: float) -> bf.Detection | None:
        """The followed face re-found in its own crop (the refiner only)."""
        if (self.refiner is None or self._last is None or self.s.full_every_s <= 0
                or t <= self._full_t):
            return None
        found = self.refiner.refine(bgr, self._last)
        if found is None:
            return None
        same, _new = self.tracker.select([found], t)
        return same

    def process(self, bgr: np.ndarray, stamp_ns: int, *,
                defer_search: bool = False) -> FaceResult:
        """The face to follow in this frame.

        Between whole-frame passes (`full_every_s`) the followed face is tracked in
        its crop. When a pass is due it runs first, unless `defer_search`: then the
        frame is answered from the crop and `search_if_due()` does the pass after
        the caller has published, off the latency path.
        """
        t = stamp_ns * 1e-9
        due = not 0 < t - self._full_t < self.s.full_every_s
        if not due or defer_search:
            tracked = self._track(bgr, t)
            if tracked is not None:
                self.tracked += 1
                self._search_due = due
                return self._locate(bgr, [tracked], tracked, False, t, tracked)
        faces = self.net.detect(bgr)
        self._full_t = t
        self._search_due = False
        target, new_person = self.tracker.select(faces, t)
        if target is None:
            self._last = None
            return FaceResult(faces, None, None, None, None, None)
        return self._locate(bgr, faces, target, new_person, t, None)

    def search_if_due(self, bgr: np.ndarray, stamp_ns: int) -> list[bf.Detection] | None:
        """The whole-frame pass a deferred `process` put off; None when none was due.

        Target choice stays with the followed person while they are seen, so the
        pass only has to confirm them: a tracked face the whole-frame detector does
        not see is dropped, and the next frame searches the whole frame again.
        """
        if not self._search_due:
            return None
        self._search_due = False
        faces = self.net.detect(bgr)
        self._full_t = stamp_ns * 1e-9
        if not self.tracker.confirms(faces):
            self._last = None
        return faces

    def _locate(self, bgr: np.ndarray, faces: list[bf.Detection], target: bf.Detection,
                new_person: bool, t: float, measured: bf.Detection | None) -> FaceResult:
        """Distance, back-projection and smoothing of the followed face."""
        k = self.intrinsics(bgr.shape[1], bgr.shape[0])
        eye_m = self.s.eye_distance_m if self.s.eye_distance_m > 0 else None
        if measured is None:
            measured = target
            if self.refiner is not None:
                better = self.refiner.refine(bgr, target)
                if better is not None:
                    measured = better
                    self.refined += 1
        self._last = measured
        est = estimate_distance(measured, k.fx, self.s.face_width_m, eye_m)
        u, v = measured.centre
        raw = back_project(u, v, est.z_m, k)
        if not self.s.smoothing:
            return FaceResult(faces, target, est, raw, raw, measured)
        if new_person:
            self.smoother.reset()
        return FaceResult(faces, target, est, self.smoother(raw, t), raw, measured)
