"""Which face track the followed face belongs to: pure, one box per frame.

The face detector marks the face the robot follows (`FaceBox.followed`)
and gives it its track id (`FaceDetections.track`): a new id whenever it
follows another person. That id is the track, so a name is decided for
the same track the people service sees on `camera/{camera}/face`. A
source without ids gets tracks of its own: a box that overlaps the last
one (IoU at least `min_iou`) continues the track, a box elsewhere starts
a new one. Either way no followed face for `lost_s` ends the track, and
ids are never reused, so a name decided for one track can never stick to
the next face.
"""

from __future__ import annotations

from dataclasses import dataclass

Box = tuple[float, float, float, float]
"""x0, y0, x1, y1 in image pixels."""


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two boxes (0 when either is empty)."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


@dataclass
class FaceTracks:
    """The followed face's track; `update` per frame returns its id (None: no track)."""

    min_iou: float = 0.3
    lost_s: float = 1.0
    track: int | None = None
    box: Box | None = None
    seen_ns: int = 0
    last_id: int = 0

    def update(self, box: Box | None, stamp_ns: int, given: int | None = None) -> int | None:
        """The track of this frame's followed `box` (None when no face is followed);
        `given`: the detector's track id of it, used as the track when present."""
        if box is None:
            if self.track is not None and stamp_ns - self.seen_ns > self.lost_s * 1e9:
                self.track, self.box = None, None
            return self.track
        if given is not None:
            self.track = given
        elif self.box is None or self.track is None or iou(self.box, box) < self.min_iou:
            self.last_id += 1
            self.track = self.last_id
        self.box, self.seen_ns = box, stamp_ns
        return self.track
