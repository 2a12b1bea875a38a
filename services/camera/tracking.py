"""Which face to follow, and jitter smoothing: pure, time passed in explicitly.

Target choice the way a person would expect: with nobody tracked, take the
largest face (the nearest one); then stay with that person while they
remain in view, matching them frame to frame by overlap / nearness, even
when someone else is momentarily bigger. Only when the tracked face has
been missing for `switch_after_s` is another face taken; a detector miss
of a frame or two therefore never makes the eyes jump to a bystander. The
hold is for bystanders only, faces already seen next to the followed one:
a face that appears where none was while the followed one vanishes (the
person stepped in quickly and the track could not follow, or the only
person left and another arrived) is taken at once, since holding would
publish nothing for half a second when there is nobody else to confuse.
Whether a crop-tracking result may continue the track at all is decided
before this, by `gate.TrackGate`.

Smoothing: a One-Euro filter (Casiez, Roussel, Vogel, CHI 2012) per
coordinate. Its cut-off frequency rises with speed, so a still face is
steady (low cut-off removes jitter) while a moving one is followed with
little lag (high cut-off).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from buddybot.camera import blazeface as bf


def _alpha(cutoff_hz: float, dt: float) -> float:
    tau = 1.0 / (2.0 * math.pi * cutoff_hz)
    return 1.0 / (1.0 + tau / dt)


@dataclass
class OneEuro:
    """One-Euro filter of one scalar; `min_cutoff` Hz, `beta` per unit/s of speed."""

    min_cutoff: float = 1.0
    beta: float = 0.5
    d_cutoff: float = 1.0
    _x: float | None = None
    _dx: float = 0.0
    _t: float | None = None

    def reset(self) -> None:
        self._x, self._dx, self._t = None, 0.0, None

    def __call__(self, x: float, t: float) -> float:
        if self._x is None or self._t is None or t <= self._t:
            if self._x is None or self._t is None:
                self._x, self._t = x, t
                return x
            if t <= self._t:  # same or older stamp: no time passed, keep the state
                return self._x
        dt = t - self._t
        dx = (x - self._x) / dt
        self._dx += _alpha(self.d_cutoff, dt) * (dx - self._dx)
        cutoff = self.min_cutoff + self.beta * abs(self._dx)
        self._x += _alpha(cutoff, dt) * (x - self._x)
        self._t = t
        return self._x


@dataclass
class PointSmoother:
    """One-Euro filters for x, y, z, reset after a gap (a new sighting starts fresh)."""

    min_cutoff: float = 1.0
    beta: float = 0.5
    reset_after_s: float = 0.5
    _filters: list[OneEuro] = field(default_factory=list)
    _last_t: float | None = None

    def __post_init__(self) -> None:
        self._filters = [OneEuro(self.min_cutoff, self.beta) for _ in range(3)]

    def reset(self) -> None:
        for f in self._filters:
            f.reset()
        self._last_t = None

    def __call__(self, point: tuple[float, float, float], t: float) -> tuple[float, float, float]:
        # A gap, or time going backwards, starts afresh. Backwards matters: the filters
        # hold their value for stamps older than their last one, so after one stamp from
        # the future they would otherwise freeze until real time caught up with it.
        if self._last_t is not None and not 0 <= t - self._last_t <= self.reset_after_s:
            self.reset()
        self._last_t = t
        x, y, z = (f(v, t) for f, v in zip(self._filters, point, strict=True))
        return x, y, z


def _iou(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _near(box: tuple[float, float, float, float], det: bf.Detection, min_iou: float,
          max_jump: float) -> float | None:
    """How well `det` continues `box` (higher is better), or None when it cannot."""
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    width = max(box[2] - box[0], 1.0)
    overlap = _iou(box, det.box)
    jump = math.hypot(det.centre[0] - cx, det.centre[1] - cy) / width
    size_ratio = det.width / width
    if overlap < min_iou and (jump > max_jump or not 0.5 < size_ratio < 2.0):
        return None
    return overlap - jump


@dataclass
class TargetTracker:
    """Keeps following one face across frames.

    `select(detections, t)` (a whole-frame pass) returns the face to follow
    now (or None) and whether it is a newly chosen person (so smoothing
    restarts); `follow(det, t)` continues the track with a crop result the
    gate accepted; `observe(detections, t)` is a whole-frame pass that only
    confirms (it never changes the person).
    """

    switch_after_s: float = 0.5
    min_iou: float = 0.2
    max_jump: float = 1.0
    """A face whose centre moved less than `max_jump` box widths is the same person."""
    forget_after_s: float = 3.0
    """A face unseen this long is forgotten: whoever appears next, even at the same
    place, is a new person (smoothing and what the iris learnt start afresh)."""
    bystander_jump: float = 2.0
    """A face within this many box widths of a bystander seen at the last whole-frame
    pass is that bystander (they had up to `full_every_s` to move)."""
    _box: tuple[float, float, float, float] | None = None
    _seen_t: float = -math.inf
    _others: list[tuple[float, float, float, float]] = field(default_factory=list)
    target_changes: int = 0

    def _match(self, dets: list[bf.Detection]) -> bf.Detection | None:
        if self._box is None:
            return None
        best: tuple[float, bf.Detection] | None = None
        for det in dets:
            rank = _near(self._box, det, self.min_iou, self.max_jump)
            if rank is not None and (best is None or rank > best[0]):
                best = (rank, det)
        return None if best is None else best[1]

    def _bystander(self, det: bf.Detection) -> bool:
        return any(_near(box, det, self.min_iou, self.bystander_jump) is not None
                   for box in self._others)

    def observe(self, dets: list[bf.Detection], t: float) -> bool:
        """A whole-frame pass that only confirms: refreshes the followed face and the
        bystanders; returns whether the followed face was among `dets`."""
        same = self._match(dets)
        self._others = [d.box for d in dets if d is not same]
        if same is None:
            return False
        self._box, self._seen_t = same.box, t
        return True

    def follow(self, det: bf.Detection, t: float) -> None:
        """Continue the track with `det` (a crop result the gate accepted)."""
        self._box, self._seen_t = det.box, t

    def select(self, dets: list[bf.Detection], t: float) -> tuple[bf.Detection | None, bool]:
        if self._box is not None and abs(t - self._seen_t) > self.forget_after_s:
            self._box = None  # measured both ways, like the switch hold
        same = self._match(dets)
        if same is not None:
            self._others = [d.box for d in dets if d is not same]
            self._box, self._seen_t = same.box, t
            return same, False
        if not dets:
            return None, False
        candidates = dets
        # Our person may be back next frame: do not jump to a bystander yet. Measured both
        # ways, so a sighting with a stamp from the future cannot hold the choice forever.
        if self._box is not None and abs(t - self._seen_t) < self.switch_after_s:
            candidates = [d for d in dets if not self._bystander(d)]
            if not candidates:
                self._others = [d.box for d in dets]
                return None, False
        chosen = max(candidates, key=lambda d: d.area)
        self._others = [d.box for d in dets if d is not chosen]
        self._box, self._seen_t = chosen.box, t
        self.target_changes += 1
        return chosen, True
