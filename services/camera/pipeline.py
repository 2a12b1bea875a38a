"""One frame in, at most one face out, and the work owed once that face is published.

    check -> track or search -> choose -> measure -> geometry -> smooth

* check: the frame becomes HxWx3 uint8 BGR or is refused with a counted
  reason (`refused`), never an exception; its only conversion;
* track or search: the followed face re-found in its crop (through
  `gate.TrackGate`), or a whole-frame search (`facenet.FaceNet`) when there
  is no track, the gate refused, or a pass is due and the caller does not defer;
* choose: which face is followed (`tracking.TargetTracker`);
* measure: the chosen face detected again in its crop with the short-range
  model for a precise size and eyes (a tracked face already is that);
* geometry: distance cues and the 3-D point (`geometry.locate`);
* smooth: One-Euro filters (`tracking.PointSmoother`).

Owed work (`process(..., defer=True)`): a due whole-frame pass
(`OwedSearch`) and the iris measurement (`OwedIris`, which updates
`fusion.IrisCalibration`) come back in `FaceResult.owed`; the caller runs
them with `run_owed` after publishing, off the gaze's latency path.
Without `defer` both run inside `process`. No Zenoh here, so the whole
chain is tested on real images in-process. Details: docs/camera.md.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import assert_never

import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera import frames
from buddybot.camera.facenet import FaceNet
from buddybot.camera.fusion import IrisCalibration
from buddybot.camera.gate import TrackGate
from buddybot.camera.geometry import (
    DistanceEstimate,
    Intrinsics,
    Location,
    eye_distance_px,
    head_yaw,
    locate,
)
from buddybot.camera.iris import IrisNet, IrisSchedule
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.camera.tracking import PointSmoother, TargetTracker
from buddybot.runtime.limits import BoundedDict

MEASURE_MAX_RATIO = 1.5
"""A crop re-detection whose width differs from the whole-frame box by more than this
factor is another (partial) face in the crop, not a better measure of this one."""


@dataclass(frozen=True, eq=False)
class OwedSearch:
    """The whole-frame pass that was due when the frame was answered from the crop."""

    bgr: np.ndarray
    t: float


@dataclass(frozen=True, eq=False)
class OwedIris:
    """The iris measurement of the followed face `measured` in this frame."""

    bgr: np.ndarray
    measured: bf.Detection
    t: float


Owed = OwedSearch | OwedIris


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
    tracked: bool = False
    """True when the face came from the crop track (no whole-frame pass this frame)."""
    refused: str | None = None
    """Why the frame was not processed ("bad_frames", "too_large"), else None."""
    track: int | None = None
    """The followed person's track: a new id whenever another person is followed."""
    owed: tuple[Owed, ...] = ()
    """Work put off until after publishing (`process(defer=True)`): for `run_owed`."""


class FacePipeline:
    """Detector `net` on the whole frame; optional `refiner` (the short-range
    model) re-detects the followed face in a crop for a precise size and eyes,
    and tracks it there between whole-frame passes (`full_every_s`)."""

    def __init__(self, net: FaceNet, settings: FaceDetectorSettings,
                 refiner: FaceNet | None = None, gate: TrackGate | None = None,
                 irises: IrisNet | None = None, first_track: int = 1) -> None:
        self.net = net
        self.track = first_track - 1
        """The followed person's track id (the next one is this + 1); the service
        starts it from the wall clock, so ids are not reused after a restart."""
        self.refiner = refiner
        self.irises = irises
        self.iris_schedule = IrisSchedule(settings.iris_every_s, settings.iris_min_px)
        self.iris_held = IrisCalibration()
        """What the iris measurements of the followed person say (reset for a new one)."""
        self.iris_measurements = 0
        self.iris_accepted = 0
        self.s = settings
        self.gate = gate or TrackGate()
        self.tracker = TargetTracker(switch_after_s=settings.switch_after_s)
        self.smoother = PointSmoother(settings.min_cutoff_hz, settings.beta)
        # Per frame size; bounded because the sizes come from the bus (a sender
        # changing the size every frame must not grow it without end).
        self._intrinsics: BoundedDict[tuple[int, int], Intrinsics] = BoundedDict(8)
        self._last: bf.Detection | None = None  # the followed face as last measured
        self._last_t = 0.0
        self._full_t = -np.inf  # when the whole frame was last searched
        self._jumped = False  # the gate refused this frame's crop result
        self.tracked = 0
        self.refined = 0
        self.searches = 0
        self.refused: Counter[str] = Counter()
        """Frames refused by the check stage, by reason."""
        self.gate_rejections: Counter[str] = Counter()
        """Crop results the gate refused, by reason ("size", "position", "keypoints")."""

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        key = (width, height)
        found = self._intrinsics.get(key)
        if found is None:
            s = self.s
            found = Intrinsics.resolve(width, height, s.fx, s.fy, s.cx, s.cy, s.hfov_deg)
            self._intrinsics[key] = found
        return found

    def reconfigure(self, settings: FaceDetectorSettings) -> None:
        """Take changed live settings (between frames, so no frame is processed half
        with the old ones). Thresholds and timings are read from `self.s` on every
        frame; the score threshold lives in the net, the switch delay in the tracker,
        and a changed smoothing filter restarts smoothing. Model, camera, intrinsics,
        iris and threads are restart-only (settings.py marks them)."""
        self.s = settings
        self.net.min_score = (self.net.spec.min_score if settings.min_score is None
                              else settings.min_score)
        self.tracker.switch_after_s = settings.switch_after_s
        if (self.smoother.min_cutoff, self.smoother.beta) != (settings.min_cutoff_hz,
                                                              settings.beta):
            self.smoother = PointSmoother(settings.min_cutoff_hz, settings.beta)

    # -- stages ---------------------------------------------------------------

    def _check(self, frame: np.ndarray) -> np.ndarray | FaceResult:
        """Stage 1: HxWx3 uint8 BGR, or a refusal result (counted)."""
        try:
            return frames.to_bgr8(np.asarray(frame), max_side=None)
        except frames.FrameRefused as refused:
            self.refused[refused.reason] += 1
            return FaceResult([], None, None, None, None, None, refused=refused.reason)

    def _track(self, bgr: np.ndarray, t: float) -> bf.Detection | None:
        """Stage 2a: the followed face re-found in its own crop, if the gate agrees."""
        if (self.refiner is None or self._last is None or self.s.full_every_s <= 0
                or t <= self._full_t):
            return None
        found = self.refiner.refine(bgr, self._last)
        if found is None:
            return None
        k = self.intrinsics(bgr.shape[1], bgr.shape[0])
        why = self.gate.check(self._last, found, t - self._last_t, k.fx, self.s.face_width_m)
        if why is not None:
            self.gate_rejections[why] += 1
            self._jumped = True
            return None
        return found

    def _search(self, bgr: np.ndarray, t: float) -> list[bf.Detection]:
        """Stage 2b: every face in the whole frame."""
        self._full_t = t
        self.searches += 1
        return self.net.detect(bgr)

    def _measure(self, bgr: np.ndarray, target: bf.Detection) -> bf.Detection:
        """Stage 4: the chosen face re-detected in its crop, when that agrees in size."""
        if self.refiner is None:
            return target
        better = self.refiner.refine(bgr, target)
        if better is None:
            return target
        ratio = better.width / max(target.width, 1e-6)
        if not 1 / MEASURE_MAX_RATIO < ratio < MEASURE_MAX_RATIO:
            return target
        self.refined += 1
        return better

    def _geometry(self, bgr: np.ndarray, measured: bf.Detection) -> Location:
        """Stage 5: distance cues (the held iris one too) and the 3-D point."""
        k = self.intrinsics(bgr.shape[1], bgr.shape[0])
        eye_m = self.s.eye_distance_m if self.s.eye_distance_m > 0 else None
        held = self.iris_held if self.irises is not None else None
        return locate(measured, k, self.s.face_width_m, eye_m, held)

    def _iris(self, bgr: np.ndarray, measured: bf.Detection, t: float) -> None:
        """Measure the irises (owed work, or the end of an undeferred `process`);
        a plausible measurement updates the held ratio."""
        assert self.irises is not None
        self.iris_schedule.ran(t)
        self.iris_measurements += 1
        found = self.irises.measure(bgr, measured)
        if found is not None and found.plausible():
            accepted = self.iris_held.update(found.diameter_px, eye_distance_px(
                measured.keypoints), head_yaw(measured.keypoints))
            self.iris_accepted += bool(accepted)

    def _smooth(self, point: tuple[float, float, float], t: float,
                new_person: bool) -> tuple[float, float, float]:
        """Stage 6: One-Euro smoothing (restarted for a new person)."""
        if not self.s.smoothing:
            return point
        if new_person:
            self.smoother.reset()
        return self.smoother(point, t)

    # -- entry points ---------------------------------------------------------

    def process(self, frame: np.ndarray, stamp_ns: int, *, defer: bool = False) -> FaceResult:
        """The face to follow in this frame.

        Between whole-frame passes (`full_every_s`) the followed face is tracked in
        its crop. When a pass is due it runs first, unless `defer`: then the frame
        is answered from the crop and the pass is owed (`FaceResult.owed`), like a
        due iris measurement. A crop result the gate does not accept gets a
        whole-frame pass at once, before anything is published.
        """
        checked = self._check(frame)
        if isinstance(checked, FaceResult):
            return checked
        bgr = checked
        t = stamp_ns * 1e-9
        due = not 0 < t - self._full_t < self.s.full_every_s
        self._jumped = False
        owed: list[Owed] = []
        tracked = self._track(bgr, t) if not due or defer else None
        if tracked is not None:
            self.tracked += 1
            if due:
                owed.append(OwedSearch(bgr, t))
            self.tracker.follow(tracked, t)
            faces, target, measured, new_person = [tracked], tracked, tracked, False
        else:
            faces = self._search(bgr, t)
            chosen, new_person = self.tracker.select(faces, t)
            if chosen is None:
                self._last = None
                return FaceResult(faces, None, None, None, None, None)
            target = chosen
            measured = self._measure(bgr, target)
            # After a jump no head could make, smoothing across it would only publish
            # points between the old face and this one: start afresh.
            new_person = new_person or self._jumped
        self._last, self._last_t = measured, t
        if new_person:  # what the iris said was about somebody else
            self.track += 1
            self.iris_schedule.reset()
            self.iris_held.reset()
        where = self._geometry(bgr, measured)
        point = self._smooth(where.point, t, new_person)
        if self.irises is not None and self.iris_schedule.due(measured, t):
            if defer:
                owed.append(OwedIris(bgr, measured, t))
            else:
                self._iris(bgr, measured, t)
        return FaceResult(faces, target, where.estimate, point, where.point, measured,
                          tracked=tracked is not None, track=self.track, owed=tuple(owed))

    def run_owed(self, owed: Sequence[Owed]) -> list[bf.Detection] | None:
        """Run the work a deferred `process` owed, in order; the faces of the
        whole-frame pass, or None when none was owed.

        Target choice stays with the followed person while they are seen, so the
        pass only has to confirm them: a tracked face the whole-frame detector does
        not see is dropped, and the next frame searches the whole frame again.
        """
        searched = None
        for work in owed:
            match work:
                case OwedSearch(bgr=bgr, t=t):
                    searched = self._search(bgr, t)
                    if not self.tracker.observe(searched, t):
                        self._last = None
                case OwedIris(bgr=bgr, measured=measured, t=t):
                    self._iris(bgr, measured, t)
                case _:
                    assert_never(work)
        return searched
